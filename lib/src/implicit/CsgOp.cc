// SPDX-License-Identifier: Apache-2.0
#include <ivdb/implicit/CsgOp.h>

namespace ivdb::implicit {

const std::vector<std::string>& csgOpNames()
{
    static const std::vector<std::string> names{"union", "intersection", "difference"};
    return names;
}

const char* toString(CsgOp op)
{
    return csgOpNames()[static_cast<std::size_t>(op)].c_str();
}

std::optional<CsgOp> csgOpFromString(const std::string& word)
{
    const auto& names = csgOpNames();
    for (std::size_t i = 0; i < names.size(); ++i) {
        if (names[i] == word) return static_cast<CsgOp>(i);
    }
    return std::nullopt;
}

} // namespace ivdb::implicit
