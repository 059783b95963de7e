// The table of the glTF bad-input corpus (tests/data/bad/README.md and
// tests/data/hostile/README.md, written by tests/data/make_bad_gltf.py), read by
// test_gltf.cpp (in-process loading) and test_cli.cpp (through build/smallvcm).
#pragma once

#include <catch2/catch.hpp>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace corpus {

struct Row {
    std::string mFile, mWhat, mFragment;  // mFragment empty for files that must load
    int mSkipped = -1, mKept = -1;        // for files that must load
};

inline bool StartsWith(const std::string& aText, const std::string& aPrefix) {
    return aText.compare(0, aPrefix.size(), aPrefix) == 0;
}

inline std::string Trim(const std::string& aText) {
    const size_t begin = aText.find_first_not_of(' ');
    const size_t end = aText.find_last_not_of(' ');
    return begin == std::string::npos ? std::string() : aText.substr(begin, end - begin + 1);
}

// The text between the first and the last backtick, or "" when there is none.
inline std::string InBackticks(const std::string& aCell) {
    const size_t first = aCell.find('`'), last = aCell.rfind('`');
    return first == std::string::npos || last == first ? std::string() : aCell.substr(first + 1, last - first - 1);
}

// Rows "| `file` | what | `fragment` |" or "| `file` | what | loads: skipped N, kept M |".
inline std::vector<Row> ReadTable(const std::string& aReadme) {
    std::ifstream file(aReadme);
    INFO(aReadme);
    REQUIRE(file);
    std::vector<Row> rows;
    std::string line;
    while (std::getline(file, line)) {
        if (!StartsWith(line, "| `")) continue;
        std::vector<std::string> cells;
        std::stringstream stream(line.substr(1));
        for (std::string cell; std::getline(stream, cell, '|');) cells.push_back(Trim(cell));
        INFO(line);
        REQUIRE(cells.size() == 3);
        Row row;
        row.mFile = InBackticks(cells[0]);
        row.mWhat = cells[1];
        if (StartsWith(cells[2], "loads:")) {
            REQUIRE(std::sscanf(cells[2].c_str(), "loads: skipped %d, kept %d", &row.mSkipped, &row.mKept) == 2);
        } else {
            row.mFragment = InBackticks(cells[2]);
            REQUIRE_FALSE(row.mFragment.empty());
        }
        rows.push_back(row);
    }
    return rows;
}

} // namespace corpus
