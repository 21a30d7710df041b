#include "core/common/error.h"

namespace stevi {

std::string_view ErrorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kInvalidArgument: return "invalid argument";
    case ErrorCode::kNotFound: return "not found";
    case ErrorCode::kFailedPrecondition: return "failed precondition";
    case ErrorCode::kUnavailable: return "unavailable";
    case ErrorCode::kResourceExhausted: return "resource exhausted";
    case ErrorCode::kOutOfRange: return "out of range";
    case ErrorCode::kInternal: return "internal";
  }
  return "unknown";
}

Error Error::Invalid(const std::vector<std::string>& problems) {
  std::string message;
  for (const std::string& p : problems) {
    if (!message.empty()) message += "; ";
    message += p;
  }
  return Error{ErrorCode::kInvalidArgument, message.empty() ? "invalid input" : message};
}

}  // namespace stevi
