// stevi: the command-line client of stevi-server. This file holds the table of commands and the
// global usage; each command, with its own usage, lives in a file of its own beside it
// (client/cli/), over the flags of core/common/flags.h.
#include <malloc.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <string_view>

#include "client/lib/client.h"
#include "client/cli/commands.h"

namespace {

namespace commands = stevi::client::commands;

constexpr char kGlobalUsage[] =
    R"(usage: stevi [--server HOST:PORT] [--timeout SECONDS] [--tls-ca PEM]
             [--tls-cert PEM --tls-key PEM] [--token-file FILE] COMMAND [ARGS]
       stevi help COMMAND     (or stevi COMMAND --help): the command's own usage

  --server HOST:PORT the server (default 127.0.0.1:50051)
  --timeout SECONDS  bounds each call (default 5)
  --tls-ca PEM       connect with TLS, trusting this CA (the server's certificate must name the
                     host given in --server)
  --tls-cert, --tls-key PEM
                     this client's certificate and key, for a server with mutual TLS
  --token-file FILE  send the bearer token on its first line (the server's control calls need
                     it when it has auth.token_file)

Commands:
)";

constexpr char kExitStatus[] =
    "\nExit status: 0 on success, 1 when the server fails or cannot be reached, 2 on bad usage.\n";

// Every command, in the order `stevi --help` lists them.
constexpr const commands::CommandSpec* kCommands[] = {
    &commands::kWatchCommand,       &commands::kStatusCommand,  &commands::kConfigCommand,
    &commands::kSnapshotCommand,    &commands::kRecordCommand,  &commands::kCalibrateCommand,
    &commands::kCalibrationCommand, &commands::kAvoidCommand,   &commands::kExportCommand,
    &commands::kMcapCommand,        &commands::kMavlinkCommand, &commands::kStationCommand,
};

const commands::CommandSpec* FindCommand(std::string_view name) {
  for (const commands::CommandSpec* command : kCommands) {
    if (command->name == name) return command;
  }
  return nullptr;
}

void PrintUsage() {
  std::cout << kGlobalUsage;
  for (const commands::CommandSpec* command : kCommands) {
    std::printf("  %-13s %s\n", std::string(command->name).c_str(),
                std::string(command->summary).c_str());
  }
  std::cout << kExitStatus;
}

std::string CommandNames() {
  std::string names;
  for (const commands::CommandSpec* command : kCommands) {
    names += (names.empty() ? "" : ", ") + std::string(command->name);
  }
  return names;
}

// `stevi station`, `mavlink` and `avoid` run for hours. glibc's malloc gives each thread that
// allocates an arena of its own (up to 8 per core: a station has two dozen civetweb workers and
// gRPC's threads), and raises its mmap threshold to the largest block freed, so that a track
// export of some megabytes is later carved from whichever arena its worker has; each arena then
// keeps its own peak. Measured in a station serving an export every 3 s: 20 MB growing to about
// 46 MB with glibc's defaults, flat at 23 MB with these. Called before any thread starts;
// MALLOC_ARENA_MAX or MALLOC_MMAP_THRESHOLD_ in the environment wins.
void TuneAllocatorForLongRuns() {
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 2);
  // A fixed threshold also stops the dynamic one: blocks above it are mapped and, when freed,
  // returned to the system at once.
  if (std::getenv("MALLOC_MMAP_THRESHOLD_") == nullptr) mallopt(M_MMAP_THRESHOLD, 256 << 10);
}

}  // namespace

int main(int argc, char** argv) {
  TuneAllocatorForLongRuns();
  commands::HandleStopSignals();
  const commands::Args args(argv + 1, argv + argc);
  commands::GlobalOptions global;
  if (std::string problem = commands::ParseGlobalOptions(args, global); !problem.empty()) {
    return commands::Usage(problem);
  }
  if (global.help) {
    PrintUsage();
    return 0;
  }
  if (global.command >= args.size()) {
    return commands::Usage("expected a command: " + CommandNames());
  }
  const std::string& name = args[global.command];
  const commands::Args rest(args.begin() + static_cast<long>(global.command) + 1, args.end());
  if (name == "help") {
    if (rest.empty()) {
      PrintUsage();
      return 0;
    }
    const commands::CommandSpec* command = FindCommand(rest[0]);
    if (command == nullptr) return commands::Usage("help: unknown command '" + rest[0] + "'");
    std::cout << command->usage;
    return 0;
  }
  const commands::CommandSpec* command = FindCommand(name);
  if (command == nullptr) {
    return commands::Usage("unknown command '" + name + "' (the commands: " + CommandNames() + ")");
  }
  if (std::find(rest.begin(), rest.end(), "--help") != rest.end()) {
    std::cout << command->usage;
    return 0;
  }
  stevi::client::Client client(global.client);
  const int code = command->run(client, rest);
  commands::OnStopSignal(nullptr);  // a stop handler refers to `client`: done with it first
  return code;
}
