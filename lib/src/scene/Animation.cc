// SPDX-License-Identifier: Apache-2.0
#include <ivdb/scene/Animation.h>

#include <ivdb/util/Params.h>

#include <algorithm>
#include <cstdlib>

namespace ivdb::scene {

std::vector<int> FrameRange::frames() const
{
    std::vector<int> out;
    for (long f = start; f <= end; f += step) out.push_back(int(f));
    return out;
}

namespace {

/// A whole frame number at the start of @a text (digits only), advancing @a pos; -1 if none.
long frameNumber(const std::string& text, std::size_t& pos)
{
    const std::size_t begin = pos;
    while (pos < text.size() && text[pos] >= '0' && text[pos] <= '9') ++pos;
    if (pos == begin || pos - begin > 9) return -1;
    return std::strtol(text.substr(begin, pos - begin).c_str(), nullptr, 10);
}

} // namespace

FrameRange parseFrameRange(const std::string& text)
{
    const auto bad = [&](const std::string& why) {
        throw ParamError(param::kFrames, "must be A-B[:STEP] or A (whole frames, 0 <= A <= B, "
                         "STEP >= 1); " + why + ", got '" + text + "'");
    };
    std::size_t pos = 0;
    const long a = frameNumber(text, pos);
    if (a < 0) bad("A is not a whole number below 10^9");
    long b = a, step = 1;
    if (pos < text.size() && text[pos] == '-') {
        ++pos;
        b = frameNumber(text, pos);
        if (b < 0) bad("B is not a whole number below 10^9");
        if (pos < text.size() && text[pos] == ':') {
            ++pos;
            step = frameNumber(text, pos);
            if (step < 1) bad("STEP is not a whole number >= 1");
        }
    }
    if (pos != text.size()) bad("unexpected '" + text.substr(pos) + "'");
    if (a > b) bad("A > B");
    return FrameRange{int(a), int(b), int(step)};
}

bool hasFrameField(const std::string& pattern)
{
    return pattern.find('#') != std::string::npos;
}

std::string frameFileName(const std::string& pattern, int frame)
{
    std::string out;
    for (std::size_t i = 0; i < pattern.size();) {
        if (pattern[i] != '#') {
            out += pattern[i++];
            continue;
        }
        std::size_t width = 0;
        while (i < pattern.size() && pattern[i] == '#') ++i, ++width;
        std::string digits = std::to_string(frame);
        if (digits.size() < width) digits.insert(0, width - digits.size(), '0');
        out += digits;
    }
    return out;
}

std::vector<double> Keys::at(double frame) const
{
    // The segment [frames[i], frames[i + 1]) that holds the frame, so a key frame is never
    // reached at t = 1 (where a + 1 * (b - a) need not be b in floating point).
    const auto next = std::upper_bound(frames.begin(), frames.end(), frame);
    if (next == frames.begin()) return values.front();
    if (next == frames.end()) return values.back();
    const std::size_t i = std::size_t(next - frames.begin()) - 1;
    if (interpolation == Interpolation::Step || frame == frames[i]) return values[i];
    double t = (frame - frames[i]) / (frames[i + 1] - frames[i]);
    if (interpolation == Interpolation::Smooth) t = t * t * (3.0 - 2.0 * t);
    std::vector<double> v(values[i].size());
    for (std::size_t c = 0; c < v.size(); ++c) {
        v[c] = values[i][c] + t * (values[i + 1][c] - values[i][c]);
    }
    return v;
}

} // namespace ivdb::scene
