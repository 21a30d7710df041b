#include "server/server.h"

#include <chrono>

#include "server/app_config.h"
#include "server/convert.h"
#include "drivers/recording/replay_source.h"

namespace stevi::server {

Result<std::unique_ptr<Server>> Server::Start(const v1::ServerConfig& config) {
  std::vector<std::string> problems = ValidateServerConfig(config);
  Result<pipeline::PipelineConfig> pipeline_config = BuildPipelineConfig(config.pipeline());
  if (!pipeline_config.ok()) problems.push_back(pipeline_config.error().message);
  if (!problems.empty()) return Error::Invalid(problems);

  // The synthetic airfield rig hovers at Pisa unless the config gives a pose.
  std::optional<geo::VehicleState> synthetic_pose;
  const v1::SourceKind kind = config.source().kind();
  if ((kind == v1::SOURCE_KIND_SYNTHETIC || kind == v1::SOURCE_KIND_UNSPECIFIED) &&
      config.source().synthetic().scene() != "chessboard") {
    const std::optional<drivers::Scenario> scenario = FindScenario(config.source().synthetic().scene());
    synthetic_pose = SyntheticRigPose(scenario ? scenario->options.scene.camera_height_m
                                               : drivers::DefaultScene().camera_height_m);
  }
  Result<std::unique_ptr<PoseSource>> poses = PoseSource::Create(config.geo(), synthetic_pose);
  if (!poses.ok()) return poses.error();

  Result<std::unique_ptr<drivers::StereoSource>> source =
      OpenSource(config.source(), /*loop_images=*/true);
  if (!source.ok()) return source.error();

  if (auto* replay = dynamic_cast<drivers::ReplaySource*>(source->get())) {
    (*poses)->SetRecordedStates(replay->vehicle_states());
  }

  std::unique_ptr<Server> server(new Server());
  server->poses_ = std::move(poses).value();
  server->listen_ = config.has_listen() ? config.listen() : kDefaultListen;
  const uint32_t queue =
      config.has_subscriber_queue_frames() ? config.subscriber_queue_frames() : kDefaultQueueFrames;
  const uint32_t max_streams = config.has_max_streams() ? config.max_streams() : kDefaultMaxStreams;
  server->broadcaster_ = std::make_unique<FrameBroadcaster>(queue, max_streams);

  FrameBroadcaster* broadcaster = server->broadcaster_.get();
  Result<std::unique_ptr<Engine>> engine = Engine::Create(
      std::move(source).value(), std::move(pipeline_config).value(),
      [broadcaster](const std::shared_ptr<const pipeline::FrameResult>& result) {
        // Converted once per frame, shared by every subscriber.
        broadcaster->Publish(std::make_shared<const v1::TrackFrame>(ToTrackFrame(*result)));
      });
  if (!engine.ok()) return engine.error();
  server->engine_ = std::move(engine).value();
  PoseSource* pose_source = server->poses_.get();
  if (synthetic_pose) {
    const std::optional<drivers::Scenario> scenario = FindScenario(config.source().synthetic().scene());
    if (scenario && scenario->options.scene.rig_velocity_mps != cv::Vec3d(0, 0, 0)) {
      const drivers::Scene scene = scenario->options.scene;
      const geo::VehicleState start = *synthetic_pose;
      pose_source->SetSyntheticPath([scene, start](int64_t t_ns) {
        return MovedRigPose(start, scene.RigOffsetAt(static_cast<double>(t_ns) * 1e-9),
                            scene.rig_velocity_mps);
      });
    }
  }
  server->engine_->SetPoseSource(
      [pose_source](int64_t t, int64_t unix_t) { return pose_source->At(t, unix_t); });
  Result<std::unique_ptr<CalibrationManager>> calibration = CalibrationManager::Open(
      config.has_data_dir() ? config.data_dir() : kDefaultDataDir, *server->engine_);
  // (The recorder comes after the calibration store, so that it records the calibration the
  // store restored.)
  if (!calibration.ok()) return calibration.error();
  server->calibration_ = std::move(calibration).value();
  const std::string data_dir = config.has_data_dir() ? config.data_dir() : kDefaultDataDir;
  server->recording_ =
      std::make_unique<RecordingManager>(data_dir, *server->engine_, *server->poses_);
  if (config.record().has_dir()) {
    // From the first frame on: the tap is in place before the engine starts.
    const uint64_t max_bytes = config.record().has_max_bytes() ? config.record().max_bytes()
                                                               : kDefaultRecordingMaxBytes;
    Result<v1::RecordingStatus> recording = server->recording_->StartIn(config.record().dir(), max_bytes);
    if (!recording.ok()) {
      Error error = recording.error();
      error.message = "record: " + error.message;
      return error;
    }
  }
  server->service_ = std::make_unique<ObstacleServiceImpl>(*server->engine_, *broadcaster,
                                                           *server->poses_, *server->recording_);
  server->calibration_service_ = std::make_unique<CalibrationServiceImpl>(*server->calibration_);

  const int max_message =
      static_cast<int>(config.has_max_message_bytes() ? config.max_message_bytes()
                                                      : kDefaultMaxMessageBytes);
  grpc::ServerBuilder builder;
  builder.AddListeningPort(server->listen_, grpc::InsecureServerCredentials(), &server->port_);
  builder.RegisterService(server->service_.get());
  builder.RegisterService(server->calibration_service_.get());
  builder.SetMaxReceiveMessageSize(max_message);
  builder.SetMaxSendMessageSize(max_message);
  server->grpc_server_ = builder.BuildAndStart();
  if (server->grpc_server_ == nullptr || server->port_ == 0) {
    return Error{ErrorCode::kUnavailable,
                 "cannot listen on " + server->listen_ + " (address in use or not local?)"};
  }
  server->engine_->Start();
  return server;
}

Server::~Server() { Shutdown(); }

void Server::Shutdown() {
  if (shut_down_) return;
  shut_down_ = true;
  // End the streams first so that Shutdown() does not wait on them, then stop accepting.
  if (broadcaster_) broadcaster_->Close();
  if (grpc_server_) {
    grpc_server_->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
    grpc_server_->Wait();
  }
  if (calibration_) calibration_->Stop();
  if (engine_) engine_->Stop();
  // After the source stopped: every captured frame is in the recording, which is then closed.
  if (recording_) recording_->Stop("the server stopped");
}

}  // namespace stevi::server
