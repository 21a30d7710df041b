// stevi config get [--json] | set KEY=VALUE...: the active pipeline configuration.
#include <google/protobuf/text_format.h>

#include <iostream>
#include <string>

#include "client/cli/commands.h"
#include "client/lib/config_edit.h"

namespace stevi::client::commands {
namespace {

void PrintConfigText(const v1::PipelineConfig& config) {
  std::string text;
  google::protobuf::TextFormat::PrintToString(config, &text);
  std::cout << text;
}

int Set(Client& client, const Args& args) {
  if (args.size() < 2) return Usage("config set: expected KEY=VALUE...");
  v1::PipelineConfig update;
  for (size_t i = 1; i < args.size(); ++i) {
    const size_t eq = args[i].find('=');
    if (eq == std::string::npos || eq == 0) {
      return Usage("config set: expected KEY=VALUE, got '" + args[i] + "'");
    }
    const std::string problem =
        SetFieldByPath(update, args[i].substr(0, eq), args[i].substr(eq + 1));
    if (!problem.empty()) return Usage("config set: " + problem);
  }
  v1::PipelineConfig active;
  if (grpc::Status status = client.SetPipelineConfig(update, &active); !status.ok()) {
    return RpcFailed(client, "config set", status);
  }
  std::cout << "applied; algorithm "
            << ShortEnum(v1::Algorithm_Name(active.algorithm()), "ALGORITHM_") << ", matcher "
            << ShortEnum(v1::MatcherKind_Name(active.matcher().kind()), "MATCHER_KIND_") << "\n";
  return 0;
}

}  // namespace

int Config(Client& client, const Args& args) {
  if (args.empty()) return Usage("config: expected 'get' or 'set'");
  if (args[0] == "get") {
    return ShowResponse(client, "config get", args, 1, &Client::GetPipelineConfig, PrintConfigText);
  }
  if (args[0] == "set") return Set(client, args);
  return Usage("config: unknown subcommand '" + args[0] + "' (get or set)");
}

const CommandSpec kConfigCommand = {
    "config", "the active pipeline configuration: get it, or change it while running",
    R"(usage: stevi config get [--json]
       stevi config set KEY=VALUE...

get: the active pipeline configuration.
set: change it while running, e.g. algorithm=canonical, matcher.kind=semi_global,
canonical.threshold_range_m=60.
)",
    &Config};

}  // namespace stevi::client::commands
