// SPDX-License-Identifier: Apache-2.0
#include <ivdb/util/Params.h>

#include <ivdb/util/System.h>

#include <cmath>

namespace ivdb {

namespace {
std::string prefix(const std::string& context)
{
    return context.empty() ? std::string() : context + ": ";
}
} // namespace

ParamError::ParamError(const Param& param, std::string reason, std::string context, Kind kind)
    : openvdb::ValueError(prefix(context) +
                          (kind == Kind::Missing ? reason : param.label + (" " + reason)))
    , mParam(param.id)
    , mLabel(param.label)
    , mReason(std::move(reason))
    , mContext(std::move(context))
    , mKind(kind)
{
}

std::string ParamError::describe(const std::string& name) const
{
    if (mKind == Kind::Missing) return prefix(mContext) + mReason + " (" + name + ")";
    return prefix(mContext) + name + " " + mReason;
}

bool Limit::contains(double v) const
{
    if (!std::isfinite(v)) return false;
    const bool aboveLo = loOpen ? v > lo : v >= lo;
    const bool belowHi = hiOpen ? v < hi : v <= hi;
    return aboveLo && belowHi;
}

std::string Limit::reason(double v) const
{
    const std::string u = *unit ? std::string(" ") + unit : std::string();
    const std::string h = *hint ? std::string(" ") + hint : std::string();
    std::string range;
    if (std::isinf(hi)) {
        range = std::string(loOpen ? "> " : ">= ") + util::formatNumber(lo) + u + " and finite";
    } else {
        range = std::string("in ") + (loOpen ? "(" : "[") + util::formatNumber(lo) + ", " +
                util::formatNumber(hi) + (hiOpen ? ")" : "]") + u;
    }
    return "must be " + range + h + ", got " + util::formatNumber(v);
}

void check(const Limit& limit, double v, const std::string& context)
{
    if (!limit.contains(v)) throw ParamError(limit.param, limit.reason(v), context);
}

} // namespace ivdb
