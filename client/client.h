// stevi_client: a small C++ client for stevi-server (connect, stream tracks, control calls).
// Depends on the proto library only.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "stevi/v1/calibration_service.grpc.pb.h"
#include "stevi/v1/obstacle_service.grpc.pb.h"

namespace stevi::client {

// The HTTP/2 receive window of StreamTracks (BDP probing off): how far a slow reader may fall
// behind before the server starts dropping frames for it. 16 KiB holds about 7 TrackFrames of ten
// tracks. Other clients of the API should do the same (see README, "Slow readers").
inline constexpr int kStreamLookaheadBytes = 16 << 10;

struct ClientOptions {
  std::string address = "127.0.0.1:50051";
  // Deadline of each unary call, and of connecting a stream.
  std::chrono::milliseconds timeout{5000};
  int max_message_bytes = 64 << 20;
  // Channel credentials: insecure (loopback) when null; grpc::SslCredentials(...) for TLS.
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  // Sent as "authorization: Bearer TOKEN" with every call when not empty: the server's control
  // RPCs need it when it has an AuthConfig.token_file. Send it over TLS only.
  std::string bearer_token;
};

struct StreamOptions {
  // Stop after this many frames (0 = until cancelled or the server ends the stream).
  uint64_t max_frames = 0;
  // Reconnect with exponential backoff (0.2 s doubling to 5 s) when the stream breaks.
  bool reconnect = false;
  // Give up reconnecting after this many failed attempts in a row (0 = never give up).
  int max_reconnect_attempts = 10;
  // Server-side filters: no TENTATIVE tracks; only tracks scoring at least min_score (0..1).
  bool confirmed_only = false;
  double min_score = 0.0;
};

// Thread-safe, except that one StreamTracks() runs at a time per Client.
class Client {
 public:
  explicit Client(ClientOptions options);

  grpc::Status GetStatus(v1::GetStatusResponse* response);
  grpc::Status GetPipelineConfig(v1::PipelineConfig* response);
  // Sends only the fields that are set; the server merges them and returns the active config.
  grpc::Status SetPipelineConfig(const v1::PipelineConfig& update, v1::PipelineConfig* active);
  // With `annotated`, the snapshot also carries the left image with the obstacles drawn on it.
  grpc::Status GetDisparitySnapshot(v1::DisparitySnapshot* response, bool annotated = false);

  // Calls on_frame for every frame until it returns false, max_frames arrived, Cancel() is called,
  // or the stream fails (and reconnecting, if asked, gives up). Returns OK in the first three
  // cases.
  grpc::Status StreamTracks(const std::function<bool(const v1::TrackFrame&)>& on_frame,
                            const StreamOptions& options = {});
  // Calibration (CalibrationService). Calibrate() streams `settings` then every pair; the
  // deadline is `calibrate_timeout` (calibrating 25 pairs takes seconds).
  grpc::Status Calibrate(const v1::CalibrationSettings& settings,
                         const std::vector<v1::ImagePair>& pairs, v1::CalibrationReport* report,
                         std::chrono::milliseconds calibrate_timeout = std::chrono::minutes(5));
  // Streams the server's capture progress to on_progress (the last message holds the report).
  grpc::Status CaptureCalibration(
      const v1::CaptureCalibrationRequest& request,
      const std::function<void(const v1::CaptureProgress&)>& on_progress,
      std::chrono::milliseconds capture_timeout = std::chrono::minutes(10));
  grpc::Status ListCalibrations(v1::ListCalibrationsResponse* response);
  // Streams vehicle states to the server (an autopilot's feed) and returns its counts.
  grpc::Status PublishVehicleStates(const std::vector<v1::VehicleState>& states,
                                    v1::PublishVehicleStateResponse* response);
  // Recording on the server (DATA_DIR/recordings/NAME).
  grpc::Status StartRecording(const v1::StartRecordingRequest& request,
                              v1::RecordingStatus* status);
  grpc::Status StopRecording(v1::RecordingStatus* status);
  grpc::Status GetCalibration(const std::string& id, v1::CalibrationRecord* record);
  grpc::Status ActivateCalibration(const std::string& id, v1::CalibrationRecord* record);

  // Ends a running StreamTracks() from another thread.
  void Cancel();

  const ClientOptions& options() const { return options_; }

 private:
  // The unary deadline and the credentials metadata.
  void Prepare(grpc::ClientContext& context) const;
  // The credentials metadata alone (streams set their own deadlines).
  void AddCredentials(grpc::ClientContext& context) const;

  ClientOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::ObstacleService::Stub> stub_;
  std::unique_ptr<v1::CalibrationService::Stub> calibration_stub_;
  std::shared_ptr<grpc::Channel> stream_channel_;  // StreamTracks only: a small receive window
  std::unique_ptr<v1::ObstacleService::Stub> stream_stub_;
  std::mutex stream_mu_;
  grpc::ClientContext* stream_context_ = nullptr;
  std::atomic<bool> cancelled_{false};
};

// "UNAVAILABLE", "INVALID_ARGUMENT", ...
std::string StatusCodeName(grpc::StatusCode code);

}  // namespace stevi::client
