// One-line structured logs: logfmt that a log shipper can split without guessing.
#include "server/runtime/log.h"

#include <gtest/gtest.h>

namespace stevi::server {
namespace {

TEST(FormatLogFields, PlainValuesBareOthersQuotedAndEscaped) {
  EXPECT_EQ(FormatLogFields(LogLevel::kInfo, "serving", {{"listen", "127.0.0.1:50051"}}),
            "level=info event=serving listen=127.0.0.1:50051");
  EXPECT_EQ(FormatLogFields(LogLevel::kWarning, "source_state",
                            {{"source", "aravis A + B"}, {"error", ""}}),
            "level=warning event=source_state source=\"aravis A + B\" error=\"\"");
  EXPECT_EQ(FormatLogFields(LogLevel::kError, "start_failed", {{"error", "a=\"b\"\\c\nnext line"}}),
            "level=error event=start_failed error=\"a=\\\"b\\\"\\\\c\\nnext line\"");
  // Whatever a value holds, the line stays one line.
  const std::string line =
      FormatLogFields(LogLevel::kDebug, "x", {{"k", std::string("a\nb\nc\td")}});
  EXPECT_EQ(line.find('\n'), std::string::npos) << line;
}

}  // namespace
}  // namespace stevi::server
