// The `stevi` commands, one file each, and the options before them. Each command takes the
// arguments after its name and returns the exit status: 0 on success, 1 when the server fails or
// cannot be reached, 2 on bad usage.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

#include "client/lib/client.h"
#include "client/cli/command_io.h"
#include "client/cli/stop_signals.h"

namespace stevi::client::commands {

// A command: its name, a one-line summary for `stevi --help`, its whole usage for `stevi help
// NAME` and `stevi NAME --help`, and what runs it with the arguments after its name.
struct CommandSpec {
  std::string_view name;
  std::string_view summary;
  std::string_view usage;
  int (*run)(Client& client, const Args& args);
};

int Watch(Client& client, const Args& args);        // watch.cc
int Status(Client& client, const Args& args);       // status.cc
int Record(Client& client, const Args& args);       // record.cc
int Config(Client& client, const Args& args);       // config.cc
int Snapshot(Client& client, const Args& args);     // snapshot.cc
int Calibrate(Client& client, const Args& args);    // calibrate.cc
int Avoid(Client& client, const Args& args);        // avoid.cc
int Export(Client& client, const Args& args);       // export.cc
int Calibration(Client& client, const Args& args);  // calibration.cc
int Mavlink(Client& client, const Args& args);      // mavlink.cc
int Station(Client& client, const Args& args);      // station.cc
int Mcap(Client& client, const Args& args);         // mcap.cc

// Each defined beside its command.
extern const CommandSpec kWatchCommand;
extern const CommandSpec kStatusCommand;
extern const CommandSpec kRecordCommand;
extern const CommandSpec kConfigCommand;
extern const CommandSpec kSnapshotCommand;
extern const CommandSpec kCalibrateCommand;
extern const CommandSpec kAvoidCommand;
extern const CommandSpec kExportCommand;
extern const CommandSpec kCalibrationCommand;
extern const CommandSpec kMavlinkCommand;
extern const CommandSpec kStationCommand;
extern const CommandSpec kMcapCommand;

// The options before the command (global_options.cc).
struct GlobalOptions {
  ClientOptions client;
  bool help = false;        // --help: print the usage, and nothing else
  std::size_t command = 0;  // the index of the command in the arguments
};

// Reads --server, --timeout, --tls-ca, --tls-cert, --tls-key, --token-file and --help from the
// start of `args`. Returns "" or the usage problem.
std::string ParseGlobalOptions(const Args& args, GlobalOptions& out);

}  // namespace stevi::client::commands
