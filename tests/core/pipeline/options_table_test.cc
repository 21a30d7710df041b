// The README's table of pipeline options is the one the field lists give (core/common/fields.h):
// a parameter added, renamed, or with a new default or range fails here until the README says so.
// STEVI_UPDATE_README=1 rewrites the table in place.
#include <gtest/gtest.h>

#include "core/common/fields.h"
#include "core/pipeline/config.h"
#include "tests/testing/readme_section.h"

namespace stevi {
namespace {

TEST(OptionsTable, ReadmeMatchesTheFieldLists) {
  testing::CheckReadmeSection("<!-- options table: generated from the field lists -->\n",
                              "<!-- end of the options table -->\n",
                              fields::MarkdownTable(fields::Table(pipeline::PipelineConfig{})));
}

}  // namespace
}  // namespace stevi
