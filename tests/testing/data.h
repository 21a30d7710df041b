// Where the shared reference data lives, for tests that use it.
#pragma once

#include <optional>
#include <string>

namespace stevi::testing {

// The reference data folder: $STEVI_DATA_DIR, else ../shared/data beside the repository.
// nullopt when it does not exist; tests then GTEST_SKIP() with a message naming the folder.
std::optional<std::string> DataDir();

// The folder DataDir() looked for (for skip messages).
std::string DataDirWanted();

// A fresh temporary directory for one test (removed by the OS, not by the test).
std::string MakeTempDir(const std::string& prefix);

}  // namespace stevi::testing
