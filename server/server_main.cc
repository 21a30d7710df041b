// stevi-server: serves obstacle tracks from a stereo rig over gRPC.
#include <signal.h>

#include <cstdio>
#include <iostream>
#include <string>

#include "core/common/allocator.h"
#include "server/app_config.h"
#include "server/server_flags.h"
#include "server/runtime/log.h"
#include "server/server.h"

namespace {

constexpr char kAbout[] =
    R"(Serves obstacle tracks from a stereo rig over gRPC (services stevi.v1.ObstacleService and
stevi.v1.CalibrationService). With no flags: the built-in synthetic rig, the canonical algorithm,
listening on 127.0.0.1:50051. Each flag sets the config field named after it.)";

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  using namespace stevi;
  server::ServerCommandLine command_line("stevi-server",
                                         [](const server::SettingFlag&) { return true; });
  if (std::optional<int> exit_code = command_line.ParseOrExit(argc, argv, kAbout)) {
    return *exit_code;
  }
  Result<v1::ServerConfig> configured = command_line.Config();
  if (!configured.ok()) {
    std::cerr << "stevi-server: " << configured.error().message << "\n";
    return 2;
  }
  const v1::ServerConfig& config = *configured;

  // Block the stop signals in every thread; the main thread waits for them below.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  using server::Log;
  using server::LogLevel;
  Result<std::unique_ptr<server::Server>> server = server::Server::Start(config);
  if (!server.ok()) {
    Log(LogLevel::kError, "start_failed", {{"error", server.error().message}});
    return 1;
  }
  for (const std::string& problem : (*server)->calibration().problems()) {
    Log(LogLevel::kWarning, "calibration_store", {{"problem", problem}});
  }
  const server::EngineStatus status = (*server)->engine().Status();
  const std::string& listen = (*server)->listen_address();
  Log(LogLevel::kInfo, "serving",
      {{"source", status.source},
       {"algorithm", std::string(pipeline::AlgorithmName(status.algorithm))},
       {"listen", listen.substr(0, listen.rfind(':')) + ":" + std::to_string((*server)->port())},
       {"tls", config.tls().has_cert_file() ? "on" : "off"},
       {"auth",
        config.auth().has_token_file() || config.tls().has_client_ca_file() ? "on" : "off"}});

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  Log(LogLevel::kInfo, "shutting_down",
      {{"signal", signal_number == SIGINT ? "SIGINT" : "SIGTERM"}});
  (*server)->Shutdown();
  Log(LogLevel::kInfo, "stopped");
  return 0;
}
