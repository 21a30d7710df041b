#include "core/common/error.h"

#include <cstdio>

#include "core/common/format.h"

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

std::string Got(double value) { return " (got " + FormatNumber(value) + ")"; }

void AppendPrefixed(std::vector<std::string>& out, std::string_view prefix,
                    const std::vector<std::string>& problems) {
  for (const std::string& p : problems) out.push_back(std::string(prefix) + p);
}

Error InvalidArgument(std::string message) {
  return Error{ErrorCode::kInvalidArgument, std::move(message)};
}

Error InvalidArgument(const std::vector<std::string>& problems) {
  std::string message;
  for (const std::string& p : problems) {
    if (!message.empty()) message += "; ";
    message += p;
  }
  return InvalidArgument(message.empty() ? "invalid input" : std::move(message));
}

Error NotFound(std::string message) { return Error{ErrorCode::kNotFound, std::move(message)}; }
Error AlreadyExists(std::string message) {
  return Error{ErrorCode::kAlreadyExists, std::move(message)};
}
Error FailedPrecondition(std::string message) {
  return Error{ErrorCode::kFailedPrecondition, std::move(message)};
}
Error Unavailable(std::string message) {
  return Error{ErrorCode::kUnavailable, std::move(message)};
}
Error ResourceExhausted(std::string message) {
  return Error{ErrorCode::kResourceExhausted, std::move(message)};
}
Error OutOfRange(std::string message) { return Error{ErrorCode::kOutOfRange, std::move(message)}; }
Error Cancelled(std::string message) { return Error{ErrorCode::kCancelled, std::move(message)}; }
Error Unauthenticated(std::string message) {
  return Error{ErrorCode::kUnauthenticated, std::move(message)};
}
Error PermissionDenied(std::string message) {
  return Error{ErrorCode::kPermissionDenied, std::move(message)};
}
Error Internal(std::string message) { return Error{ErrorCode::kInternal, std::move(message)}; }

}  // namespace stevi
