// SPDX-License-Identifier: Apache-2.0
// Reading the CSV files ivdb writes (bench.csv) back, by column name.
#pragma once

#include "CliRun.h"

#include <gtest/gtest.h>

#include <cstddef>
#include <filesystem>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace ivdb::test {

using CsvRow = std::map<std::string, std::string>;

/// The fields of one CSV line (RFC 4180 quoting: "" inside quotes is a quote).
inline std::vector<std::string> splitCsvLine(const std::string& line)
{
    std::vector<std::string> out(1);
    bool quoted = false;
    for (std::size_t i = 0; i < line.size(); ++i) {
        const char c = line[i];
        if (quoted && c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
            out.back() += '"';
            ++i;
        } else if (c == '"') {
            quoted = !quoted;
        } else if (c == ',' && !quoted) {
            out.emplace_back();
        } else {
            out.back() += c;
        }
    }
    return out;
}

/// The rows of the CSV file @a p by column name; a row with another field count than the header
/// fails the test.
inline std::vector<CsvRow> readCsv(const std::filesystem::path& p)
{
    std::istringstream in(slurpFile(p));
    std::string line;
    std::vector<CsvRow> rows;
    if (!std::getline(in, line)) return rows;
    const auto header = splitCsvLine(line);
    while (std::getline(in, line)) {
        const auto fields = splitCsvLine(line);
        EXPECT_EQ(fields.size(), header.size()) << line;
        CsvRow row;
        for (std::size_t i = 0; i < header.size() && i < fields.size(); ++i) row[header[i]] = fields[i];
        rows.push_back(row);
    }
    return rows;
}

} // namespace ivdb::test
