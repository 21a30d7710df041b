// The one mapping from core errors to gRPC statuses (server/grpc_status.h).
#include "server/grpc_status.h"

#include <algorithm>
#include <cctype>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace stevi::server {
namespace {

// Every ErrorCode with the gRPC code of the same name, spelt as grpc/status.h spells it.
const std::vector<std::pair<ErrorCode, std::pair<grpc::StatusCode, std::string>>>& AllCodes() {
  static const std::vector<std::pair<ErrorCode, std::pair<grpc::StatusCode, std::string>>> codes = {
      {ErrorCode::kInvalidArgument, {grpc::StatusCode::INVALID_ARGUMENT, "INVALID_ARGUMENT"}},
      {ErrorCode::kNotFound, {grpc::StatusCode::NOT_FOUND, "NOT_FOUND"}},
      {ErrorCode::kAlreadyExists, {grpc::StatusCode::ALREADY_EXISTS, "ALREADY_EXISTS"}},
      {ErrorCode::kFailedPrecondition,
       {grpc::StatusCode::FAILED_PRECONDITION, "FAILED_PRECONDITION"}},
      {ErrorCode::kUnavailable, {grpc::StatusCode::UNAVAILABLE, "UNAVAILABLE"}},
      {ErrorCode::kResourceExhausted, {grpc::StatusCode::RESOURCE_EXHAUSTED, "RESOURCE_EXHAUSTED"}},
      {ErrorCode::kOutOfRange, {grpc::StatusCode::OUT_OF_RANGE, "OUT_OF_RANGE"}},
      {ErrorCode::kCancelled, {grpc::StatusCode::CANCELLED, "CANCELLED"}},
      {ErrorCode::kUnauthenticated, {grpc::StatusCode::UNAUTHENTICATED, "UNAUTHENTICATED"}},
      {ErrorCode::kPermissionDenied, {grpc::StatusCode::PERMISSION_DENIED, "PERMISSION_DENIED"}},
      {ErrorCode::kInternal, {grpc::StatusCode::INTERNAL, "INTERNAL"}},
  };
  return codes;
}

TEST(ToGrpcStatus, EveryCodeMapsToTheGrpcCodeOfItsName) {
  // The table holds every enumerator: kInternal is the last, and they count from 0.
  ASSERT_EQ(static_cast<size_t>(ErrorCode::kInternal) + 1, AllCodes().size());
  for (size_t i = 0; i < AllCodes().size(); ++i) {
    const auto& [code, want] = AllCodes()[i];
    EXPECT_EQ(static_cast<size_t>(code), i) << "the table is in the enum's order";
    const grpc::Status status = ToGrpcStatus(Error{code, "what went wrong"});
    EXPECT_EQ(status.error_code(), want.first) << want.second;
    EXPECT_EQ(status.error_message(), "what went wrong");
    // The code's own name, as logs print it, is the gRPC name in lower case with spaces.
    std::string name(ErrorCodeName(code));
    std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) {
      return c == ' ' ? '_' : static_cast<char>(std::toupper(c));
    });
    EXPECT_EQ(name, want.second);
  }
}

TEST(ToGrpcStatus, CodeAndMessageFormIsTheSame) {
  const grpc::Status a = ToGrpcStatus(PermissionDenied("no"));
  const grpc::Status b = ToGrpcStatus(PermissionDenied("no"));
  EXPECT_EQ(a.error_code(), b.error_code());
  EXPECT_EQ(a.error_message(), b.error_message());
}

TEST(ToGrpcStatus, OkStatusIsOk) {
  EXPECT_TRUE(ToGrpcStatus(Status::Ok()).ok());
  const grpc::Status failed = ToGrpcStatus(Status(NotFound("cal-000001")));
  EXPECT_EQ(failed.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(failed.error_message(), "cal-000001");
}

TEST(ToGrpcStatus, LongMessagesAreTruncatedAndSaySo) {
  const std::string exact(2048, 'x');
  EXPECT_EQ(ToGrpcStatus(InvalidArgument(exact)).error_message(), exact);
  const grpc::Status long_one = ToGrpcStatus(InvalidArgument(std::string(100000, 'y')));
  EXPECT_EQ(long_one.error_message(), std::string(2048, 'y') + "... (truncated)");
}

}  // namespace
}  // namespace stevi::server
