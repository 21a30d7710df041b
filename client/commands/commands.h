// The `stevi` commands, one file each, and the options before them. Each command takes the
// arguments after its name and returns the exit status: 0 on success, 1 when the server fails or
// cannot be reached, 2 on bad usage.
#pragma once

#include <cstddef>
#include <string>

#include "client/client.h"
#include "client/commands/common.h"

namespace stevi::client::commands {

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
