// One stevi-server as the ground station sees it: its track stream, the previews somebody watches,
// its status, and the control calls the page makes. Reconnects on its own, for ever.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "client/lib/client.h"
#include "client/advisory/export.h"
#include "stevi/v1/station.pb.h"

namespace stevi::station {

struct PreviewSettings {
  double rate_hz = 5;
  int max_width_px = 640;
  int jpeg_quality = 80;
};

struct RigCallbacks {
  // On the rig's streaming threads; they must not block for long.
  std::function<void(const v1::TrackFrame&)> on_frame;
  std::function<void(const v1::Preview&)> on_preview;
  std::function<void(const v1::StationRigStatus&)> on_status;
};

class RigLink {
 public:
  // `name` is "rig1", ...; `options` the address, TLS and token of the reading calls.
  // `max_track_points` bounds the export history (TrackPoints()).
  RigLink(std::string name, client::ClientOptions options, PreviewSettings previews,
          RigCallbacks callbacks, size_t max_track_points = kMaxTrackPoints);
  ~RigLink();
  RigLink(const RigLink&) = delete;
  RigLink& operator=(const RigLink&) = delete;

  void Start();
  void Stop();  // ends every stream and joins every thread

  const std::string& name() const { return name_; }
  const std::string& address() const { return options_.address; }

  // Streams previews of `kind` from the server while wanted (somebody watches its channel).
  void SetPreviewWanted(v1::PreviewKind kind, bool wanted);

  v1::StationRigStatus Status() const;

  // The page's calls. The control calls carry `operator_token` (and only they do); a token that
  // is not printable ASCII gets INVALID_ARGUMENT without a call.
  grpc::Status GetConfig(v1::PipelineConfig* config);
  grpc::Status SetConfig(const v1::PipelineConfig& update, const std::string& operator_token,
                         v1::PipelineConfig* active);
  grpc::Status Snapshot(bool annotated, v1::DisparitySnapshot* snapshot);
  grpc::Status ListCalibrations(v1::ListCalibrationsResponse* response);
  grpc::Status ActivateCalibration(const std::string& id, const std::string& operator_token,
                                   v1::CalibrationRecord* record);

  // The georeferenced track points received so far (the newest max_track_points).
  std::vector<client::TrackPoint> TrackPoints() const;
  // The default bound (`stevi station --export-points`).
  static constexpr size_t kMaxTrackPoints = 200'000;

 private:
  using Clock = std::chrono::steady_clock;
  struct PreviewStream {
    std::unique_ptr<client::Client> client;
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> stop = std::make_shared<std::atomic<bool>>(false);
    std::shared_ptr<std::atomic<bool>> done = std::make_shared<std::atomic<bool>>(false);
  };

  void TracksLoop();
  void StatusLoop();
  void PreviewLoop(v1::PreviewKind kind, client::Client* client, const std::atomic<bool>* stop);
  // Cancels the retired preview streams again and joins those that have ended.
  void ReapPreviews(bool all);
  // Marks the rig UP or DOWN/CONNECTING with `error`, and publishes the status on a change.
  void SetConnection(bool up, const std::string& error);
  void PublishStatus();
  // True when a track frame arrived within the last second.
  bool FramesFlowing() const;
  // Waits `d` or until Stop(); false when stopping.
  bool Wait(Clock::duration d);

  const std::string name_;
  const client::ClientOptions options_;
  const PreviewSettings previews_;
  const RigCallbacks callbacks_;
  const size_t max_track_points_;

  client::Client tracks_client_;
  client::Client control_client_;

  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  bool started_ = false;
  v1::StationRigStatus status_;
  Clock::time_point down_since_{};
  std::deque<Clock::time_point> frame_times_, preview_times_;
  std::deque<client::TrackPoint> points_;
  std::map<int, PreviewStream> preview_streams_;  // by PreviewKind
  std::vector<PreviewStream> retired_;            // no longer wanted; ending

  std::thread tracks_thread_, status_thread_;
};

}  // namespace stevi::station
