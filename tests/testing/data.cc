#include "tests/testing/data.h"

#include <cstdlib>
#include <filesystem>
#include <random>
#include <stdexcept>

namespace stevi::testing {

std::string DataDirWanted() {
  if (const char* env = std::getenv("STEVI_DATA_DIR"); env != nullptr && *env != '\0') return env;
  return std::string(STEVI_SOURCE_DIR) + "/../shared/data";
}

std::optional<std::string> DataDir() {
  const std::string dir = DataDirWanted();
  std::error_code ec;
  if (std::filesystem::is_directory(dir, ec)) return dir;
  return std::nullopt;
}

std::string MakeTempDir(const std::string& prefix) {
  std::random_device rd;
  for (int attempt = 0; attempt < 100; ++attempt) {
    const auto path = std::filesystem::temp_directory_path() /
                      (prefix + "-" + std::to_string(rd()) + std::to_string(attempt));
    std::error_code ec;
    if (std::filesystem::create_directory(path, ec)) return path.string();
  }
  throw std::runtime_error("cannot create a temporary directory");
}

}  // namespace stevi::testing
