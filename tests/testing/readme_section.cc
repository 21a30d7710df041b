#include "tests/testing/readme_section.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <sstream>

namespace stevi::testing {

void CheckReadmeSection(const std::string& begin, const std::string& end,
                        const std::string& expected) {
  const std::string path = std::string(STEVI_SOURCE_DIR) + "/README.md";
  std::ifstream in(path);
  ASSERT_TRUE(in) << "cannot read " << path;
  std::stringstream buffer;
  buffer << in.rdbuf();
  std::string readme = buffer.str();
  const std::size_t first_line = readme.find(begin);
  const std::size_t last_line = readme.find(end);
  ASSERT_NE(first_line, std::string::npos) << "README.md lacks the line " << begin;
  ASSERT_NE(last_line, std::string::npos) << "README.md lacks the line " << end;
  ASSERT_LT(first_line, last_line);
  const std::size_t first = first_line + begin.size();
  if (readme.substr(first, last_line - first) == expected) return;
  if (const char* update = std::getenv("STEVI_UPDATE_README");
      update && std::string(update) == "1") {
    readme.replace(first, last_line - first, expected);
    std::ofstream(path) << readme;
    GTEST_SKIP() << "README.md's section after " << begin << " rewritten";
  }
  ADD_FAILURE() << "README.md's section after " << begin
                << "differs from the field lists; run this test with STEVI_UPDATE_README=1 to "
                   "rewrite it. It should be:\n"
                << expected;
}

}  // namespace stevi::testing
