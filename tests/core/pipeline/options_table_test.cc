// The README's table of pipeline options is the one the field lists give (core/common/fields.h):
// a parameter added, renamed, or with a new default or range fails here until the README says so.
// STEVI_UPDATE_README=1 rewrites the table in place.
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "core/common/fields.h"
#include "core/pipeline/config.h"

namespace stevi {
namespace {

constexpr char kBegin[] = "<!-- options table: generated from the field lists -->\n";
constexpr char kEnd[] = "<!-- end of the options table -->\n";

TEST(OptionsTable, ReadmeMatchesTheFieldLists) {
  const std::string path = std::string(STEVI_SOURCE_DIR) + "/README.md";
  std::ifstream in(path);
  ASSERT_TRUE(in) << "cannot read " << path;
  std::stringstream buffer;
  buffer << in.rdbuf();
  std::string readme = buffer.str();
  const std::size_t begin = readme.find(kBegin);
  const std::size_t end = readme.find(kEnd);
  ASSERT_NE(begin, std::string::npos) << "README.md lacks the line " << kBegin;
  ASSERT_NE(end, std::string::npos) << "README.md lacks the line " << kEnd;
  ASSERT_LT(begin, end);
  const std::size_t first = begin + std::string(kBegin).size();
  const std::string table = fields::MarkdownTable(fields::Table(pipeline::PipelineConfig{}));
  if (readme.substr(first, end - first) == table) return;
  if (const char* update = std::getenv("STEVI_UPDATE_README");
      update && std::string(update) == "1") {
    readme.replace(first, end - first, table);
    std::ofstream(path) << readme;
    GTEST_SKIP() << "README.md's options table rewritten";
  }
  ADD_FAILURE() << "README.md's options table differs from the field lists; run this test with "
                   "STEVI_UPDATE_README=1 to rewrite it. The table should be:\n"
                << table;
}

}  // namespace
}  // namespace stevi
