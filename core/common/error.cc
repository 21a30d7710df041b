#include "core/common/error.h"

#include <cstdio>

namespace stevi {

std::string_view ErrorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kInvalidArgument: return "invalid argument";
    case ErrorCode::kNotFound: return "not found";
    case ErrorCode::kAlreadyExists: return "already exists";
    case ErrorCode::kFailedPrecondition: return "failed precondition";
    case ErrorCode::kUnavailable: return "unavailable";
    case ErrorCode::kResourceExhausted: return "resource exhausted";
    case ErrorCode::kOutOfRange: return "out of range";
    case ErrorCode::kCancelled: return "cancelled";
    case ErrorCode::kUnauthenticated: return "unauthenticated";
    case ErrorCode::kPermissionDenied: return "permission denied";
    case ErrorCode::kInternal: return "internal";
  }
  return "unknown";
}

std::string Got(double value) {
  char buf[64];
  std::snprintf(buf, sizeof buf, " (got %g)", value);
  return buf;
}

void AppendPrefixed(std::vector<std::string>& out, std::string_view prefix,
                    const std::vector<std::string>& problems) {
  for (const std::string& p : problems) out.push_back(std::string(prefix) + p);
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
