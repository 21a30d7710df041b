// stevi record start [--name NAME] [--max-mb MB] [--json] | stop [--json]: recording on the
// server.
#include <cstdint>
#include <iostream>
#include <string>

#include "client/cli/commands.h"
#include "core/common/flags.h"

namespace stevi::client::commands {
namespace {

constexpr flags::RealRange kMaxMb{.lo = 1, .hi = 16e6, .unit = "MiB"};

// The flags of `record start` into `request`; "" or the usage problem.
std::string ParseStart(const Args& args, v1::StartRecordingRequest& request, bool& json) {
  return flags::FlagSet("record start")
      .Switch("--json", &json)
      .Value("--name",
             [&request](const std::string& name) {
               request.set_name(name);
               return std::string();
             })
      .Value("--max-mb",
             [&request](const std::string& text) {
               const flags::Parsed<double> mb = flags::ParseNumber(text, kMaxMb);
               if (!mb.ok()) {
                 return "record start: --max-mb must be a size in MiB, " +
                        flags::FormatNumber(kMaxMb.lo) + ".." + flags::FormatNumber(kMaxMb.hi) +
                        " (got '" + text + "')";
               }
               request.set_max_bytes(static_cast<uint64_t>(mb.value * 1048576.0));
               return std::string();
             })
      .Parse(args, 1);
}

}  // namespace

int Record(Client& client, const Args& args) {
  if (args.empty()) return Usage("record: expected 'start' or 'stop'");
  bool json = false;
  v1::RecordingStatus status;
  if (args[0] == "stop") {
    const std::string problem = ParseJsonFlag("record stop", args, 1, json);
    if (!problem.empty()) return Usage(problem);
    if (grpc::Status s = client.StopRecording(&status); !s.ok()) {
      return RpcFailed(client, "record stop", s);
    }
  } else if (args[0] == "start") {
    v1::StartRecordingRequest request;
    if (std::string problem = ParseStart(args, request, json); !problem.empty())
      return Usage(problem);
    if (grpc::Status s = client.StartRecording(request, &status); !s.ok()) {
      return RpcFailed(client, "record start", s);
    }
  } else {
    return Usage("record: expected 'start' or 'stop' (got '" + args[0] + "')");
  }
  if (json) {
    std::cout << Json(status) << "\n";
  } else {
    std::cout << RecordingLine(status) << "\n";
  }
  return 0;
}

const CommandSpec kRecordCommand = {
    "record", "record the raw stereo pairs on the server, or stop",
    R"(usage: stevi record start [--name NAME] [--max-mb MB] [--json]
       stevi record stop [--json]

start: record the raw stereo pairs, timestamps, vehicle states and calibration id on the server,
in DATA_DIR/recordings/NAME (default name from the time; default limit 4096 MiB), for
stevi-server --source replay and stevi-process --replay.
stop: stop it and print what was written.
)",
    &Record};

}  // namespace stevi::client::commands
