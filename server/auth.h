// Who may call what: TLS credentials for the listening port, and the check of the control RPCs
// (a bearer token compared in constant time, or an allowed client-certificate name).
#pragma once

#include <grpcpp/grpcpp.h>

#include <memory>
#include <set>
#include <string>
#include <string_view>

#include "core/common/error.h"
#include "server/tsan_handover.h"
#include "stevi/v1/config.pb.h"

namespace stevi::server {

// True for 127.0.0.0/8, ::1 and "localhost" (the host part of HOST:PORT).
bool IsLoopbackListen(const std::string& listen);

// The server's credentials: TLS (mutual with client_ca_file) when the config has a certificate,
// else insecure. Errors name the unreadable file.
Result<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const v1::TlsConfig& tls);

// Reads a whole (small) file, for certificates, keys and tokens: kNotFound / kInvalidArgument
// naming it.
Result<std::string> ReadSecretFile(const std::string& path, size_t max_bytes = 1 << 20);

// Equal strings, in a time that depends only on their lengths (not on where they differ).
bool ConstantTimeEquals(std::string_view a, std::string_view b);

// Thread-safe after creation (immutable).
class Authorizer {
 public:
  // No authentication: every call is allowed (the server is then on loopback only).
  Authorizer() = default;
  // From the config: reads the token file (kInvalidArgument when empty or shorter than 16
  // characters, naming the file).
  static Result<Authorizer> Create(const v1::AuthConfig& auth);

  // True when a token or client names are configured.
  bool enabled() const { return !token_.empty() || !allowed_names_.empty(); }

  // OK when the call may use control RPC `method`: no authentication configured, a client
  // certificate with an allowed name, or the right bearer token. UNAUTHENTICATED without any
  // credentials, PERMISSION_DENIED with wrong ones; both logged on stderr with the peer.
  grpc::Status CheckControl(const grpc::ServerContextBase& context, std::string_view method) const;

 private:
  std::string token_;
  std::set<std::string> allowed_names_;
};

// A client stream refused before it starts: finishes with `status` and deletes itself.
template <typename Request>
class RefusedReadReactor final : public grpc::ServerReadReactor<Request> {
 public:
  // Not bound to its call until the handler returns it: no callback runs before HandOver.
  explicit RefusedReadReactor(grpc::Status status) {
    this->Finish(std::move(status));
    HandOver(this);
  }
  void OnDone() override {
    TakeOver(this);
    CallEnded();
    delete this;
  }
};

}  // namespace stevi::server
