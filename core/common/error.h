// Errors as values at module boundaries. The server maps ErrorCode to a gRPC status in one place.
#pragma once

#include <cassert>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace stevi {

enum class ErrorCode {
  kInvalidArgument,     // bad input: a field, a file, an image
  kNotFound,            // a file or an id that does not exist
  kAlreadyExists,       // something to be created is there already (a recording)
  kFailedPrecondition,  // e.g. no calibration, no frame yet
  kUnavailable,         // a camera or source is down
  kResourceExhausted,   // too large
  kOutOfRange,          // end of a finite stream (image sequence, video)
  kCancelled,           // the caller cancelled (a capture, a wait), or the server is stopping
  kUnauthenticated,     // no credentials for a call that needs them
  kPermissionDenied,    // credentials that do not allow the call
  kInternal,            // a bug or an unexpected library failure
};

std::string_view ErrorCodeName(ErrorCode code);

// Helpers for Validate() messages ("field: problem (got 3.5)").
// " (got VALUE)", the value as FormatNumber writes it (whole numbers in full, else like %g).
std::string Got(double value);
// Appends each of `problems` to `out`, prefixed with `prefix` (a sub-struct's name and a dot).
void AppendPrefixed(std::vector<std::string>& out, std::string_view prefix,
                    const std::vector<std::string>& problems);

struct Error {
  ErrorCode code = ErrorCode::kInternal;
  std::string message;

  // The same error, its message after `prefix` ("source.aravis: ").
  Error Prefixed(std::string_view prefix) const {
    return Error{code, std::string(prefix) + message};
  }
};

// Errors are built by their code's name, one way everywhere: `return NotFound(path + ": no such
// file");`.
Error InvalidArgument(std::string message);
// The problems of a Validate() ("field: problem"), joined into one message by "; ".
Error InvalidArgument(const std::vector<std::string>& problems);
Error NotFound(std::string message);
Error AlreadyExists(std::string message);
Error FailedPrecondition(std::string message);
Error Unavailable(std::string message);
Error ResourceExhausted(std::string message);
Error OutOfRange(std::string message);
Error Cancelled(std::string message);
Error Unauthenticated(std::string message);
Error PermissionDenied(std::string message);
Error Internal(std::string message);

// Either a value or an Error. Small on purpose: C++20 has no std::expected.
template <typename T>
class [[nodiscard]] Result {
 public:
  Result(T value) : v_(std::move(value)) {}      // NOLINT: implicit by design
  Result(Error error) : v_(std::move(error)) {}  // NOLINT: implicit by design

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }

  T& value() & {
    assert(ok());
    return std::get<0>(v_);
  }
  const T& value() const& {
    assert(ok());
    return std::get<0>(v_);
  }
  T&& value() && {
    assert(ok());
    return std::get<0>(std::move(v_));
  }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }

  const Error& error() const {
    assert(!ok());
    return std::get<1>(v_);
  }

 private:
  std::variant<T, Error> v_;
};

// A Result with no value: success, or an Error.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(Error error) : error_(std::move(error)) {}  // NOLINT: implicit by design
  static Status Ok() { return {}; }

  bool ok() const { return !error_.has_value(); }
  explicit operator bool() const { return ok(); }
  const Error& error() const {
    assert(!ok());
    return *error_;
  }

 private:
  std::optional<Error> error_;
};

}  // namespace stevi
