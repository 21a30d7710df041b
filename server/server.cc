#include "server/server.h"

#include <algorithm>
#include <chrono>
#include <optional>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/thread_name.h"
#include "drivers/synthetic/scenarios.h"
#include "server/app_config.h"
#include "server/convert.h"
#include "server/runtime/log.h"
#include "server/tsan_handover.h"

namespace stevi::server {

namespace {

// The synthetic rig hovers at Pisa unless the config gives a pose: its pose for the configured
// scene, or nullopt for another source (or the chessboard, which has no vehicle).
std::optional<geo::VehicleState> SyntheticPose(const v1::SourceConfig& source) {
  const v1::SourceKind kind = source.kind();
  if (kind != v1::SOURCE_KIND_SYNTHETIC && kind != v1::SOURCE_KIND_UNSPECIFIED) return std::nullopt;
  return drivers::SceneRigPose(source.synthetic().scene());
}

// A scenario whose rig moves flies its path: the pose source follows it.
void FollowSyntheticFlight(const v1::SourceConfig& source, const geo::VehicleState& start,
                           PoseSource& poses) {
  if (auto path = drivers::SceneRigPath(source.synthetic().scene(), start)) {
    poses.SetSyntheticPath(std::move(path));
  }
}

// ServerConfig.record: recording from the first frame on (the tap is in place before the engine
// starts). Errors are prefixed "record: ".
Status StartConfiguredRecording(const v1::RecordConfig& record, RecordingManager& recording) {
  if (!record.has_dir()) return Status::Ok();
  const drivers::RecorderOptions defaults;
  const uint64_t max_bytes = record.has_max_bytes() ? record.max_bytes() : defaults.max_bytes;
  const int queue =
      record.has_queue_frames() ? static_cast<int>(record.queue_frames()) : defaults.queue_frames;
  Result<v1::RecordingStatus> started = recording.StartIn(record.dir(), max_bytes, queue);
  if (started.ok()) return Status::Ok();
  Error error = started.error();
  error.message = "record: " + error.message;
  return error;
}

// The gRPC server's transport settings: message sizes and keepalive (idle connections are pinged
// and dead, half-open ones of vanished clients closed).
void ConfigureTransport(const ServerOptions& options, grpc::ServerBuilder& builder) {
  const auto ms = [](double seconds) { return static_cast<int>(seconds * 1000.0); };
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, ms(options.keepalive_time_s));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, ms(options.keepalive_timeout_s));
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS,
                             ms(options.min_client_ping_interval_s));
  const int max_message = static_cast<int>(options.max_message_bytes);
  builder.SetMaxReceiveMessageSize(max_message);
  builder.SetMaxSendMessageSize(max_message);
}

// OpenCV builds its table of image codecs on first use, behind a function-local static whose
// fast path ThreadSanitizer cannot see inside the uninstrumented library: a calibration worker
// decoding an uploaded image read what the thread that first encoded an image had written while
// building the table (one report, in server/calibration_test). Building it here, before any of
// the server's threads exist, orders it before them all, and takes the one-time cost (GDAL's
// loading among it) off the first calibration or preview.
void LoadImageCodecs() { (void)cv::haveImageWriter(".png"); }

}  // namespace

Result<std::unique_ptr<Server>> Server::Start(const v1::ServerConfig& config) {
  LoadImageCodecs();
  std::vector<std::string> problems = ValidateServerConfig(config);
  Result<pipeline::PipelineConfig> pipeline_config = BuildPipelineConfig(config.pipeline());
  if (!pipeline_config.ok()) problems.push_back(pipeline_config.error().message);
  if (!problems.empty()) return InvalidArgument(problems);
  Result<ServerOptions> options = ServerOptionsFrom(config);  // checked above
  if (!options.ok()) return options.error();

  const std::optional<geo::VehicleState> synthetic_pose = SyntheticPose(config.source());
  Result<std::unique_ptr<PoseSource>> poses = MakePoseSource(config.geo(), synthetic_pose);
  if (!poses.ok()) return poses.error();

  // Credentials before the source: a bad certificate or token file is found without touching a
  // camera.
  Result<std::shared_ptr<grpc::ServerCredentials>> credentials =
      MakeServerCredentials(config.tls());
  if (!credentials.ok()) return credentials.error();
  Result<Authorizer> auth = Authorizer::Create(config.auth());
  if (!auth.ok()) return auth.error();

  Result<std::unique_ptr<drivers::StereoSource>> source =
      OpenSource(config.source(), /*loop_images=*/true);
  if (!source.ok()) return source.error();
  (*poses)->SetRecordedStates((*source)->RecordedVehicleStates());
  if (synthetic_pose) FollowSyntheticFlight(config.source(), *synthetic_pose, **poses);

  std::unique_ptr<Server> server(new Server());
  server->auth_ = std::move(auth).value();
  server->poses_ = std::move(poses).value();
  server->options_ = std::move(options).value();
  server->listen_ = server->options_.listen;
  Status built =
      server->BuildRuntime(config, std::move(source).value(), std::move(pipeline_config).value());
  if (!built.ok()) return built.error();
  built = server->BuildGrpcServer(*credentials);
  if (!built.ok()) return built.error();
  // The flight log last, once nothing else can fail: a server that did not start leaves no file.
  // Before the engine starts, so that it has every frame.
  if (config.has_record_mcap()) {
    std::vector<std::string> mcap_problems;
    McapRecordingOptions mcap_options =
        McapRecordingOptionsFrom(config.record_mcap(), mcap_problems);
    if (!mcap_problems.empty()) return InvalidArgument(mcap_problems);
    Result<std::unique_ptr<McapRecording>> mcap =
        McapRecording::Start(std::move(mcap_options), *server->engine_, *server->broadcaster_,
                             *server->previews_, server->recording_.get());
    if (!mcap.ok()) return mcap.error();
    server->mcap_recording_ = std::move(mcap).value();
  }
  server->engine_->Start(server->options_.pipeline_workers.value_or(0),
                         server->options_.opencv_threads.value_or(0));
  server->health_thread_ = std::thread([raw = server.get()] {
    NameThisThread("stevi-health");
    raw->HealthLoop();
  });
  return server;
}

Status Server::BuildRuntime(const v1::ServerConfig& config,
                            std::unique_ptr<drivers::StereoSource> source,
                            pipeline::PipelineConfig pipeline_config) {
  const auto queue = static_cast<uint32_t>(options_.subscriber_queue_frames);
  const auto max_streams = static_cast<uint32_t>(options_.max_streams);
  broadcaster_ = std::make_unique<FrameBroadcaster>(queue, max_streams);
  FrameBroadcaster* broadcaster = broadcaster_.get();
  PreviewHubOptions preview_options;
  preview_options.max_subscribers = std::min<size_t>(max_streams, kMaxPreviewStreams);
  previews_ = std::make_unique<PreviewHub>(preview_options);
  PreviewHub* previews = previews_.get();
  Result<std::unique_ptr<Engine>> engine = Engine::Create(
      std::move(source), std::move(pipeline_config),
      [broadcaster, previews](const std::shared_ptr<const pipeline::FrameResult>& result) {
        // Converted once per frame, shared by every subscriber.
        broadcaster->Publish(std::make_shared<const v1::TrackFrame>(ToTrackFrame(*result)));
        // A pointer handed over (nothing at all without preview subscribers): the JPEGs are
        // made on the hub's thread.
        previews->Offer(result);
      });
  if (!engine.ok()) return engine.error();
  engine_ = std::move(engine).value();
  PoseSource* pose_source = poses_.get();
  engine_->SetPoseSource(
      [pose_source](int64_t t, int64_t unix_t) { return pose_source->At(t, unix_t); });
  const std::string& data_dir = options_.data_dir;
  Result<std::unique_ptr<CalibrationManager>> calibration =
      CalibrationManager::Open(data_dir, *engine_);
  if (!calibration.ok()) return calibration.error();
  calibration_ = std::move(calibration).value();
  // The recorder comes after the calibration store, so that it records the calibration the store
  // restored.
  recording_ = std::make_unique<RecordingManager>(data_dir, *engine_, *poses_);
  const Status recording = StartConfiguredRecording(config.record(), *recording_);
  if (!recording.ok()) return recording;
  service_ = std::make_unique<ObstacleServiceImpl>(*engine_, *broadcaster, *previews_, *poses_,
                                                   *recording_, auth_);
  calibration_service_ = std::make_unique<CalibrationServiceImpl>(*calibration_, auth_);
  return Status::Ok();
}

Status Server::BuildGrpcServer(const std::shared_ptr<grpc::ServerCredentials>& credentials) {
  // grpc.health.v1 (gRPC's own implementation) and server reflection (grpcurl, grpc_cli).
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(listen_, credentials, &port_);
  builder.RegisterService(service_.get());
  builder.RegisterService(calibration_service_.get());
  ConfigureTransport(options_, builder);
  grpc_server_ = builder.BuildAndStart();
  if (grpc_server_ == nullptr || port_ == 0) {
    return Unavailable("cannot listen on " + listen_ + " (address in use or not local?)");
  }
  if (grpc::HealthCheckServiceInterface* health = grpc_server_->GetHealthCheckService()) {
    // NOT_SERVING until the first frame comes through (the default is SERVING); naming the
    // services lets a client ask for each.
    health->SetServingStatus("stevi.v1.ObstacleService", false);
    health->SetServingStatus("stevi.v1.CalibrationService", false);
    health->SetServingStatus(false);
  }
  return Status::Ok();
}

Server::~Server() { Shutdown(); }

void Server::HealthLoop() {
  grpc::HealthCheckServiceInterface* health = grpc_server_->GetHealthCheckService();
  if (health == nullptr) return;
  std::optional<bool> published;
  std::unique_lock lock(health_mu_);
  while (!health_stop_) {
    lock.unlock();
    const EngineStatus status = engine_->Status();
    // Serving: the source delivers and the pipeline turns its frames into tracks.
    const bool serving =
        status.source_state == SourceState::kRunning && status.frames_processed > 0;
    if (published != serving) {
      health->SetServingStatus(serving);  // the overall status ("") and every service
      published = serving;
    }
    lock.lock();
    // A quarter of a second: a load balancer or watchdog sees a camera loss about as soon as
    // the engine does.
    health_cv_.wait_for(lock, std::chrono::milliseconds(250), [this] { return health_stop_; });
  }
}

void Server::Shutdown() {
  if (shut_down_) return;
  shut_down_ = true;
  {
    std::lock_guard lock(health_mu_);
    health_stop_ = true;
  }
  health_cv_.notify_all();
  if (health_thread_.joinable()) health_thread_.join();
  // The order of a graceful stop, each step logged (a SIGTERM must end within 5 s):
  // 1. Stop accepting: gRPC refuses new connections and calls from the moment its Shutdown()
  //    begins, and then waits for the calls in progress (cancelling them after shutdown_grace_s).
  const auto started = std::chrono::steady_clock::now();
  const auto elapsed_ms = [&] {
    return std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(
                              std::chrono::steady_clock::now() - started)
                              .count());
  };
  Log(LogLevel::kInfo, "shutdown", {{"step", "stop_accepting"}});
  std::thread stop_accepting;
  if (grpc_server_) {
    stop_accepting = std::thread([this] {
      NameThisThread("stevi-shutdown");
      grpc_server_->Shutdown(std::chrono::system_clock::now() +
                             std::chrono::duration_cast<std::chrono::system_clock::duration>(
                                 std::chrono::duration<double>(options_.shutdown_grace_s)));
    });
  }
  // 2. End the streams, each with a final status (UNAVAILABLE "server shutting down": a client
  //    reconnects to the next server), so that the calls in progress finish without waiting.
  //    The preview streams likewise; the hub's thread is joined. And the vehicle state streams,
  //    which would otherwise wait for their clients' next state.
  const size_t streams = broadcaster_ ? broadcaster_->Close() : 0;
  const size_t preview_streams = previews_ ? previews_->Close() : 0;
  const size_t vehicle_streams = service_ ? service_->EndVehicleStreams() : 0;
  if (stop_accepting.joinable()) stop_accepting.join();
  if (grpc_server_) grpc_server_->Wait();
  AllCallsEnded();
  Log(LogLevel::kInfo, "shutdown",
      {{"step", "streams_ended"},
       {"streams", std::to_string(streams)},
       {"preview_streams", std::to_string(preview_streams)},
       {"vehicle_streams", std::to_string(vehicle_streams)},
       {"ms", elapsed_ms()}});
  // 3. Stop the cameras (the source and the pipeline) and the calibration worker.
  if (calibration_) calibration_->Stop();
  if (engine_) engine_->Stop();
  Log(LogLevel::kInfo, "shutdown", {{"step", "source_stopped"}, {"ms", elapsed_ms()}});
  // 4. After the source stopped, every captured frame is in the recording: flush and close it.
  if (recording_) {
    const bool was_recording = recording_->Status().active();
    recording_->Stop("the server stopped");
    if (was_recording) {
      const v1::RecordingStatus status = recording_->Status();
      Log(LogLevel::kInfo, "shutdown",
          {{"step", "recording_flushed"},
           {"dir", status.dir()},
           {"frames", std::to_string(status.frames_written())},
           {"ms", elapsed_ms()}});
    }
  }
  // 5. The MCAP flight log: its subscriptions ended with the streams; write what is queued and
  //    the summary.
  if (mcap_recording_) {
    const McapRecordingStatus mcap = mcap_recording_->Stop();
    Log(mcap.error.empty() ? LogLevel::kInfo : LogLevel::kError, "shutdown",
        {{"step", "mcap_closed"},
         {"file", mcap.file},
         {"track_frames", std::to_string(mcap.counts.track_frames)},
         {"images", std::to_string(mcap.counts.images)},
         {"bytes", std::to_string(mcap.counts.bytes)},
         {"dropped", std::to_string(mcap.frames_dropped)},
         {"error", mcap.error},
         {"ms", elapsed_ms()}});
  }
}

}  // namespace stevi::server
