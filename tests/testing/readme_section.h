// A generated section of README.md (a table made from the field lists) checked against what the
// code gives: a setting added, renamed, or with a new default or range fails the test until the
// README says so. STEVI_UPDATE_README=1 rewrites the section in place instead.
#pragma once

#include <string>

namespace stevi::testing {

// Compares README.md's text between the lines `begin` and `end` (each ending in '\n') with
// `expected`: adds a test failure naming the difference, or rewrites the section (and skips) when
// STEVI_UPDATE_README=1.
void CheckReadmeSection(const std::string& begin, const std::string& end,
                        const std::string& expected);

}  // namespace stevi::testing
