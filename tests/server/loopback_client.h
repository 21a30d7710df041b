// A client of an in-process server on loopback, for the server's tests that start one
// (server_test, calibration_test).
#pragma once

#include <chrono>
#include <string>

#include "client/lib/client.h"
#include "server/server.h"

namespace stevi::testing {

// Options for a client of `server` on 127.0.0.1 with the unary deadline `timeout`.
inline client::ClientOptions LoopbackOptions(const server::Server& server,
                                             std::chrono::seconds timeout) {
  client::ClientOptions options;
  options.address = "127.0.0.1:" + std::to_string(server.port());
  options.timeout = timeout;
  return options;
}

}  // namespace stevi::testing
