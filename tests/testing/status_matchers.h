// gMock matchers for stevi's Result<T> and Status, with the error's code and message in the
// failure message:
//   EXPECT_THAT(config, IsOk());
//   EXPECT_THAT(source, IsError(ErrorCode::kNotFound));
//   EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument, HasSubstr("source.fps")));
#pragma once

#include <gmock/gmock.h>

#include <string>

#include "core/common/error.h"

namespace stevi::testing {

MATCHER(IsOk, negation ? "is an error" : "is OK") {
  if (arg.ok()) return true;
  *result_listener << "is an error: " << ErrorCodeName(arg.error().code) << ": "
                   << arg.error().message;
  return false;
}

MATCHER_P(IsError, code,
          std::string(negation ? "is not an error of code " : "is an error of code ") +
              std::string(ErrorCodeName(code))) {
  if (arg.ok()) {
    *result_listener << "is OK";
    return false;
  }
  *result_listener << "is " << ErrorCodeName(arg.error().code) << ": " << arg.error().message;
  return arg.error().code == code;
}

MATCHER_P2(IsError, code, message_matcher,
           std::string(negation ? "is not an error of code " : "is an error of code ") +
               std::string(ErrorCodeName(code)) + " whose message " +
               ::testing::DescribeMatcher<std::string>(message_matcher, negation)) {
  if (arg.ok()) {
    *result_listener << "is OK";
    return false;
  }
  *result_listener << "is " << ErrorCodeName(arg.error().code) << ": " << arg.error().message;
  return arg.error().code == code &&
         ::testing::Matches(::testing::SafeMatcherCast<const std::string&>(message_matcher))(
             arg.error().message);
}

}  // namespace stevi::testing
