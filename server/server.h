// stevi-server's body: source, engine, broadcaster, preview hub and the gRPC server, started and
// stopped in order. main() only parses flags and waits for a signal.
#pragma once

#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>
#include <string>

#include "core/common/error.h"
#include "server/auth.h"
#include "server/calibration_manager.h"
#include "server/calibration_service.h"
#include "server/server_options.h"
#include "server/runtime/engine.h"
#include "server/mcap_recording.h"
#include "server/recording_manager.h"
#include "server/service.h"
#include "stevi/v1/config.pb.h"

namespace stevi::server {

class Server {
 public:
  // Validates the whole config (every problem named) before opening the source or the socket,
  // then opens the source, starts the engine and listens.
  static Result<std::unique_ptr<Server>> Start(const v1::ServerConfig& config);
  ~Server();

  // The port actually bound (useful with "127.0.0.1:0").
  int port() const { return port_; }
  const std::string& listen_address() const { return listen_; }
  Engine& engine() { return *engine_; }
  CalibrationManager& calibration() { return *calibration_; }
  RecordingManager& recording() { return *recording_; }
  // The MCAP flight log (--record-mcap), or null.
  McapRecording* mcap_recording() { return mcap_recording_.get(); }
  PreviewHub& previews() { return *previews_; }

  // Graceful shutdown: stop accepting, end every stream with a final status, stop the source and
  // the pipeline. Idempotent.
  void Shutdown();

 private:
  Server() = default;
  // Start()'s steps: the broadcaster, preview hub, engine, calibration store, recorder and
  // services; then the gRPC server listening with them.
  Status BuildRuntime(const v1::ServerConfig& config, std::unique_ptr<drivers::StereoSource> source,
                      pipeline::PipelineConfig pipeline_config);
  Status BuildGrpcServer(const std::shared_ptr<grpc::ServerCredentials>& credentials);
  // Keeps the gRPC health service (grpc.health.v1) in step with the source and the pipeline:
  // SERVING while frames are processed, NOT_SERVING while the source is starting, down or ended.
  void HealthLoop();

  ServerOptions options_;
  std::string listen_;
  int port_ = 0;
  std::unique_ptr<FrameBroadcaster> broadcaster_;
  std::unique_ptr<PreviewHub> previews_;  // before the engine, whose sink offers it frames
  std::unique_ptr<PoseSource> poses_;
  std::unique_ptr<Engine> engine_;
  std::unique_ptr<CalibrationManager> calibration_;
  std::unique_ptr<RecordingManager> recording_;
  std::unique_ptr<McapRecording> mcap_recording_;
  Authorizer auth_;
  std::unique_ptr<ObstacleServiceImpl> service_;
  std::unique_ptr<CalibrationServiceImpl> calibration_service_;
  std::unique_ptr<grpc::Server> grpc_server_;
  bool shut_down_ = false;
  std::mutex health_mu_;
  std::condition_variable health_cv_;
  bool health_stop_ = false;
  std::thread health_thread_;
};

}  // namespace stevi::server
