#include "server/auth.h"

#include <arpa/inet.h>

#include "server/grpc_status.h"
#include "server/runtime/log.h"

#include <fstream>
#include <sstream>

namespace stevi::server {
namespace {

constexpr size_t kMinTokenLength = 16;
constexpr char kBearer[] = "Bearer ";

// The host of "HOST:PORT" or "[V6]:PORT".
std::string HostOf(const std::string& listen) {
  const size_t colon = listen.rfind(':');
  std::string host = colon == std::string::npos ? listen : listen.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  return host;
}

void LogRefusal(const grpc::ServerContextBase& context, std::string_view method,
                std::string_view why) {
  Log(LogLevel::kWarning, "refused",
      {{"method", std::string(method)}, {"peer", context.peer()}, {"reason", std::string(why)}});
}

}  // namespace

bool IsLoopbackListen(const std::string& listen) {
  const std::string host = HostOf(listen);
  if (host == "localhost") return true;
  in_addr v4{};
  if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  if (inet_pton(AF_INET6, host.c_str(), &v6) == 1) return IN6_IS_ADDR_LOOPBACK(&v6);
  return false;
}

Result<std::string> ReadSecretFile(const std::string& path, size_t max_bytes) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return NotFound(path + ": cannot be read");
  std::string text(max_bytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<size_t>(in.gcount()));
  if (text.size() > max_bytes) {
    return InvalidArgument(path + ": larger than " + std::to_string(max_bytes) + " bytes");
  }
  return text;
}

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  // Every byte of the longer string is looked at whatever the contents.
  const size_t n = std::max(a.size(), b.size());
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff = static_cast<unsigned char>(diff | (x ^ y));
  }
  return diff == 0;
}

Result<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const v1::TlsConfig& tls) {
  if (!tls.has_cert_file() && !tls.has_key_file()) {
    if (tls.has_client_ca_file()) {
      return InvalidArgument(
          "tls.client_ca_file: needs tls.cert_file and tls.key_file (mutual TLS is TLS)");
    }
    return grpc::InsecureServerCredentials();
  }
  if (!tls.has_cert_file() || !tls.has_key_file()) {
    return InvalidArgument("tls: cert_file and key_file go together");
  }
  Result<std::string> cert = ReadSecretFile(tls.cert_file());
  if (!cert.ok()) return Error{cert.error().code, "tls.cert_file: " + cert.error().message};
  Result<std::string> key = ReadSecretFile(tls.key_file());
  if (!key.ok()) return Error{key.error().code, "tls.key_file: " + key.error().message};
  grpc::SslServerCredentialsOptions options;
  options.pem_key_cert_pairs.push_back({*key, *cert});
  if (tls.has_client_ca_file()) {
    Result<std::string> ca = ReadSecretFile(tls.client_ca_file());
    if (!ca.ok()) return Error{ca.error().code, "tls.client_ca_file: " + ca.error().message};
    options.pem_root_certs = *ca;
    options.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(options);
}

Result<Authorizer> Authorizer::Create(const v1::AuthConfig& auth) {
  Authorizer a;
  if (auth.has_token_file()) {
    Result<std::string> text = ReadSecretFile(auth.token_file(), 4096);
    if (!text.ok()) return Error{text.error().code, "auth.token_file: " + text.error().message};
    std::istringstream lines(*text);
    std::string token;
    std::getline(lines, token);
    while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
    if (token.size() < kMinTokenLength) {
      return InvalidArgument("auth.token_file: " + auth.token_file() +
                             ": the token (first line) must have at least " +
                             std::to_string(kMinTokenLength) + " characters (got " +
                             std::to_string(token.size()) + ")");
    }
    a.token_ = token;
  }
  for (const std::string& name : auth.allowed_client_names()) {
    if (name.empty()) {
      return InvalidArgument("auth.allowed_client_names: an empty name");
    }
    a.allowed_names_.insert(name);
  }
  return a;
}

grpc::Status Authorizer::CheckControl(const grpc::ServerContextBase& context,
                                      std::string_view method) const {
  if (!enabled()) return grpc::Status::OK;
  // A client certificate the server verified (mutual TLS), with an allowed name.
  std::string certificate_name;
  if (!allowed_names_.empty()) {
    const std::shared_ptr<const grpc::AuthContext> auth = context.auth_context();
    if (auth != nullptr && auth->IsPeerAuthenticated()) {
      for (const char* property : {"x509_common_name", "x509_subject_alternative_name"}) {
        for (const grpc::string_ref& value : auth->FindPropertyValues(property)) {
          const std::string name(value.data(), value.size());
          if (allowed_names_.count(name) > 0) return grpc::Status::OK;
          if (certificate_name.empty()) certificate_name = name;
        }
      }
    }
  }
  const auto& metadata = context.client_metadata();
  const auto it = metadata.find("authorization");
  if (it == metadata.end() && !certificate_name.empty()) {
    LogRefusal(context, method, "client certificate '" + certificate_name + "' not allowed");
    return ToGrpcStatus(PermissionDenied(std::string(method) + ": the client certificate '" +
                                         certificate_name +
                                         "' is not allowed to make control calls"));
  }
  if (it == metadata.end()) {
    LogRefusal(context, method, "no credentials");
    return ToGrpcStatus(
        Unauthenticated(std::string(method) +
                        " is a control call: it needs a bearer token "
                        "(authorization: Bearer TOKEN) or an allowed client certificate"));
  }
  const std::string_view value(it->second.data(), it->second.size());
  const std::string_view prefix(kBearer);
  if (token_.empty() || value.substr(0, prefix.size()) != prefix ||
      !ConstantTimeEquals(value.substr(prefix.size()), token_)) {
    LogRefusal(context, method, "wrong credentials");
    return ToGrpcStatus(PermissionDenied(std::string(method) +
                                         ": the credentials given do not allow control calls"));
  }
  return grpc::Status::OK;
}

}  // namespace stevi::server
