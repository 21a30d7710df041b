// The one place where core errors become gRPC statuses.
#pragma once

#include <grpcpp/support/status.h>

#include "core/common/error.h"

namespace stevi::server {

// Maps the code (DESIGN.md: bad input -> INVALID_ARGUMENT, no calibration -> FAILED_PRECONDITION,
// camera down -> UNAVAILABLE, too large -> RESOURCE_EXHAUSTED) and truncates long messages.
grpc::Status ToGrpcStatus(const Error& error);
grpc::Status ToGrpcStatus(const Status& status);

}  // namespace stevi::server
