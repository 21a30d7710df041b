// stevi-server: serves obstacle tracks from a stereo rig over gRPC.
#include <signal.h>

#include <cstdio>
#include <iostream>
#include <set>
#include <string>

#include "server/app_config.h"
#include "server/server.h"

namespace {

constexpr char kUsage[] = R"(usage: stevi-server [flags]

Serves obstacle tracks from a stereo rig over gRPC (services stevi.v1.ObstacleService and
stevi.v1.CalibrationService).
With no flags: the built-in synthetic rig, the canonical algorithm, listening on 127.0.0.1:50051.

  --listen HOST:PORT     address to listen on (default 127.0.0.1:50051)
  --config FILE          stevi.v1.ServerConfig in protobuf text format or JSON; flags override it
  --source KIND          synthetic (default) or images
  --left PATTERN|VIDEO   images: left images as a printf pattern ("left_%04d.png") or a video file
  --right PATTERN|VIDEO  images: right images, likewise
  --calibration FILE     images: calibration YAML (OpenCV FileStorage)
  --fps N                frames per second to run the source at (default 10)
  --scene NAME           synthetic: airfield (default) or chessboard (a moving calibration board,
                         9x6 inner corners of 100 mm squares, for `stevi calibrate --capture`)
  --data-dir DIR         where calibrations are stored (default ./stevi-data); its active
                         calibration is applied at start when it fits the source
  --algorithm NAME       canonical (default), stevie (stereo + edges) or stevis (stereo + saliency)
  --help                 this text
)";

}  // namespace

int main(int argc, char** argv) {
  using namespace stevi;
  const std::set<std::string> known = {"listen", "config", "source", "left", "right",
                                       "calibration", "fps", "algorithm", "data-dir", "scene"};
  Result<server::Flags> flags = server::ParseFlags(argc, argv, known, {"help"});
  if (!flags.ok()) {
    std::cerr << "stevi-server: " << flags.error().message << "\n";
    return 2;
  }
  if (flags->values.count("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!flags->positional.empty()) {
    std::cerr << "stevi-server: unexpected argument '" << flags->positional.front() << "'\n";
    return 2;
  }

  v1::ServerConfig config;
  if (auto it = flags->values.find("config"); it != flags->values.end()) {
    Result<v1::ServerConfig> loaded = server::LoadServerConfig(it->second);
    if (!loaded.ok()) {
      std::cerr << "stevi-server: " << loaded.error().message << "\n";
      return 2;
    }
    config = std::move(loaded).value();
  }
  if (Status applied = server::ApplyFlags(*flags, config); !applied.ok()) {
    std::cerr << "stevi-server: " << applied.error().message << "\n";
    return 2;
  }

  // Block the stop signals in every thread; the main thread waits for them below.
  sigset_t stop_signals;
  sigemptyset(&stop_signals);
  sigaddset(&stop_signals, SIGINT);
  sigaddset(&stop_signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &stop_signals, nullptr);

  Result<std::unique_ptr<server::Server>> server = server::Server::Start(config);
  if (!server.ok()) {
    std::cerr << "stevi-server: " << server.error().message << "\n";
    return 1;
  }
  for (const std::string& problem : (*server)->calibration().problems()) {
    std::cerr << "stevi-server: calibration store: " << problem << "\n";
  }
  const server::EngineStatus status = (*server)->engine().Status();
  std::cerr << "stevi-server: serving " << status.source << ", algorithm "
            << pipeline::AlgorithmName(status.algorithm) << ", on "
            << (*server)->listen_address().substr(0, (*server)->listen_address().rfind(':')) << ":"
            << (*server)->port() << std::endl;

  int signal_number = 0;
  sigwait(&stop_signals, &signal_number);
  std::cerr << "stevi-server: " << (signal_number == SIGINT ? "SIGINT" : "SIGTERM")
            << ", shutting down" << std::endl;
  (*server)->Shutdown();
  std::cerr << "stevi-server: stopped" << std::endl;
  return 0;
}
