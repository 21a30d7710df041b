// The one place where core errors become gRPC statuses.
#pragma once

#include <grpcpp/support/server_callback.h>
#include <grpcpp/support/status.h>

#include "core/common/error.h"

namespace stevi::server {

// Maps the code (bad input -> INVALID_ARGUMENT, no calibration -> FAILED_PRECONDITION,
// camera down -> UNAVAILABLE, too large -> RESOURCE_EXHAUSTED; each ErrorCode to the gRPC code of
// the same name) and truncates long messages. Every status the server sends that is not OK is made
// here.
grpc::Status ToGrpcStatus(const Error& error);
grpc::Status ToGrpcStatus(const Status& status);

// A unary RPC's answer: the call's default reactor, finished with `status` (the response message
// filled in before).
grpc::ServerUnaryReactor* Reply(grpc::CallbackServerContext* context, const grpc::Status& status);

}  // namespace stevi::server
