#include "server/server_options.h"

#include <charconv>

#include "server/auth.h"

namespace stevi::server {
namespace {

// "listen: expected HOST:PORT" or a bad port; nothing when `listen` is well formed.
void CheckListen(const std::string& listen, std::vector<std::string>& problems) {
  const size_t colon = listen.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == listen.size()) {
    problems.push_back("listen: expected HOST:PORT (got '" + listen + "')");
    return;
  }
  const std::string port = listen.substr(colon + 1);
  int value = -1;
  auto [ptr, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
  if (ec != std::errc() || ptr != port.data() + port.size() || value < 0 || value > 65535) {
    problems.push_back("listen: port must be 0..65535 (got '" + port + "')");
  }
}

}  // namespace

std::vector<std::string> ServerOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  CheckListen(listen, problems);
  if (data_dir.empty()) problems.push_back("data_dir: must not be empty");
  // Who can reach the server: without authentication only this machine, unless asked explicitly.
  const bool authenticated = !auth.token_file.empty() || !tls.client_ca_file.empty();
  if (!authenticated && !allow_insecure && !IsLoopbackListen(listen)) {
    problems.push_back("listen: '" + listen +
                       "' is not a loopback address, and no authentication "
                       "is configured (auth.token_file, or tls.client_ca_file for mutual TLS): "
                       "anyone on the network could change the pipeline; configure one, or give "
                       "--allow-insecure (allow_insecure: true) to accept that");
  }
  if (!auth.token_file.empty() && tls.cert_file.empty() && !allow_insecure) {
    problems.push_back(
        "auth.token_file: a bearer token needs TLS (tls.cert_file and tls.key_file), "
        "else it crosses the network in clear text; or give --allow-insecure");
  }
  return problems;
}

}  // namespace stevi::server
