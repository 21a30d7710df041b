// What the `stevi` commands read and write, shared between them: the usage and RPC error lines
// and exit statuses, the stream-loss lines of live streams, the --json flag, JSON and enum text,
// files, and the text that more than one command prints. The stop signals: stop_signals.h.
#pragma once

#include <google/protobuf/message.h>

#include <cstddef>
#include <iostream>
#include <string>
#include <type_traits>
#include <vector>

#include "client/lib/client.h"

namespace stevi::client::commands {

namespace v1 = stevi::v1;
using Args = std::vector<std::string>;

// "stevi: PROBLEM (see stevi --help)" on stderr; returns the exit status of bad usage, 2.
int Usage(const std::string& problem);

// "stevi: WHAT: CODE: MESSAGE" on stderr (saying that the server cannot be reached when it is
// unavailable or the deadline passed); returns the exit status of a failed call, 1.
int RpcFailed(const Client& client, const std::string& what, const grpc::Status& status);

// The stream options of a live consumer (`watch`, `avoid`, `export`, `mavlink`): it survives a
// server restart or an outage of any length once frames have flowed, and says so on stderr
// ("stevi: WHAT: stream lost (CODE: MESSAGE), reconnecting" and "stevi: WHAT: stream back after
// 1.4 s"). Before the first frame it tries `attempts_before_first_frame` times (0 = for ever).
StreamOptions LiveStreamOptions(const std::string& what, int attempts_before_first_frame);

// The message as one line of JSON, with the proto field names and every primitive field.
std::string Json(const google::protobuf::Message& message);

// An enum value's name without its prefix, in lower case: ("SOURCE_STATE_RUNNING",
// "SOURCE_STATE_") gives "running".
std::string ShortEnum(const std::string& name, const std::string& prefix);

// A whole file as bytes; false when it cannot be opened or read.
bool ReadFile(const std::string& path, std::string& bytes);
// Writes (or replaces) a file; false when it cannot be written.
bool WriteFile(const std::string& path, const std::string& bytes);

// "RECORDING dir: N frames, X MiB of Y MiB, D dropped (reason)", for `status` and `record`.
std::string RecordingLine(const v1::RecordingStatus& recording);

// The flags of a command that takes [--json] alone, from args[first] on: "" or the usage problem.
std::string ParseJsonFlag(const std::string& what, const Args& args, std::size_t first, bool& json);

// A command that takes [--json] alone and makes one call (`status`, `config get`,
// `calibration list`): prints the response as JSON, or as `print` writes it. `what` names the
// command in messages.
template <typename Response>
int ShowResponse(Client& client, const std::string& what, const Args& args, std::size_t first,
                 grpc::Status (Client::*call)(Response*),
                 std::type_identity_t<void (*)(const Response&)> print) {
  bool json = false;
  if (std::string problem = ParseJsonFlag(what, args, first, json); !problem.empty()) {
    return Usage(problem);
  }
  Response response;
  if (grpc::Status status = (client.*call)(&response); !status.ok()) {
    return RpcFailed(client, what, status);
  }
  if (json) {
    std::cout << Json(response) << "\n";
  } else {
    print(response);
  }
  return 0;
}

// A calibration's quality report and verdict (or its JSON), for `calibrate` and `calibration get`.
void PrintReport(const v1::CalibrationReport& report, bool json);

}  // namespace stevi::client::commands
