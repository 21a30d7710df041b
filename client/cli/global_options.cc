// --server, --timeout, TLS and the bearer token: the options before the command.
#include <chrono>
#include <cstdint>
#include <string>

#include "client/cli/commands.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

// The file that `flag` names, as text: "" when it was read, else the problem.
std::string ReadFlagFile(const std::string& flag, const std::string& path, std::string& text) {
  if (!ReadFile(path, text) || text.empty()) return flag + ": cannot read '" + path + "'";
  return "";
}

// The token on the first line of a token file, without the line's end or trailing spaces.
std::string FirstLine(const std::string& text) {
  std::string token = text.substr(0, text.find('\n'));
  while (!token.empty() && (token.back() == '\r' || token.back() == ' ')) token.pop_back();
  return token;
}

}  // namespace

std::string ParseGlobalOptions(const Args& args, GlobalOptions& out) {
  grpc::SslCredentialsOptions tls;
  bool use_tls = false;
  // A TLS flag's PEM file into `pem`.
  const auto pem_file = [&use_tls](const std::string& flag, std::string* pem) {
    return [flag, pem, &use_tls](const std::string& path) {
      std::string problem = ReadFlagFile(flag, path, *pem);
      use_tls |= problem.empty();
      return problem;
    };
  };
  flags::FlagSet set("");
  set.Stop("--help", &out.help)
      .Text("--server", &out.client.address)
      .Real("--timeout", {.lo = 0, .hi = 3600, .unit = "seconds", .lo_open = true},
            [&out](double seconds) {
              out.client.timeout = std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
            })
      .Value("--tls-ca", pem_file("--tls-ca", &tls.pem_root_certs))
      .Value("--tls-cert", pem_file("--tls-cert", &tls.pem_cert_chain))
      .Value("--tls-key", pem_file("--tls-key", &tls.pem_private_key))
      .Value("--token-file", [&out](const std::string& path) {
        std::string text;
        std::string problem = ReadFlagFile("--token-file", path, text);
        if (!problem.empty()) return problem;
        out.client.bearer_token = FirstLine(text);
        if (!IsPrintableAscii(out.client.bearer_token)) {
          return "--token-file " + path + ": the token must be printable ASCII";
        }
        return problem;
      });
  out.command = 0;
  if (std::string problem = set.ParseLeading(args, out.command); !problem.empty()) return problem;
  if (out.help) return "";
  if (tls.pem_cert_chain.empty() != tls.pem_private_key.empty()) {
    return "--tls-cert and --tls-key go together";
  }
  if (use_tls) out.client.credentials = grpc::SslCredentials(tls);
  return "";
}

}  // namespace stevi::client::commands
