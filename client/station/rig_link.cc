#include "client/station/rig_link.h"

#include <algorithm>
#include <utility>

#include "client/advisory/track_points.h"
#include "client/lib/thread_name.h"

namespace stevi::station {
namespace {

using Clock = std::chrono::steady_clock;

// The window over which rates are reported.
constexpr auto kRateWindow = std::chrono::seconds(2);
// How often the server's status is asked for (and the rig's status published).
constexpr auto kStatusPeriod = std::chrono::milliseconds(500);
// After a refusal that reconnecting cannot change (a wrong token, say), the stream is tried again
// this much later: the server may be restarted with another configuration.
constexpr auto kRefusedRetry = std::chrono::seconds(2);
// A frame this recent says the server is up, whatever a status call says.
constexpr auto kFramesFlowing = std::chrono::seconds(1);

int64_t UnixNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

void Note(std::deque<Clock::time_point>& times, Clock::time_point now) {
  times.push_back(now);
  while (!times.empty() && now - times.front() > kRateWindow) times.pop_front();
}

double Rate(const std::deque<Clock::time_point>& times, Clock::time_point now) {
  size_t n = 0;
  for (const Clock::time_point t : times) n += now - t <= kRateWindow ? 1 : 0;
  return static_cast<double>(n) / std::chrono::duration<double>(kRateWindow).count();
}

std::string Describe(const grpc::Status& status) {
  return client::StatusCodeName(status.error_code()) + ": " + status.error_message();
}

client::ClientOptions WithToken(client::ClientOptions options, const std::string& token) {
  options.bearer_token = token;
  return options;
}

// An operator token gRPC can carry: a metadata value is printable ASCII, and gRPC aborts the
// process on any other byte ("API misuse"), so the token (typed into the page) is checked first.
grpc::Status CheckOperatorToken(const std::string& token) {
  if (client::IsPrintableAscii(token)) return grpc::Status::OK;
  return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                      "operator_token: must be printable ASCII");
}

// `call` on a client of its own that carries the operator's token (checked first) instead of the
// station's.
template <class Call>
grpc::Status AsOperator(const client::ClientOptions& options, const std::string& operator_token,
                        Call call) {
  if (grpc::Status bad = CheckOperatorToken(operator_token); !bad.ok()) return bad;
  client::Client c(WithToken(options, operator_token));
  return call(c);
}

}  // namespace

RigLink::RigLink(std::string name, client::ClientOptions options, PreviewSettings previews,
                 RigCallbacks callbacks, size_t max_track_points)
    : name_(std::move(name)),
      options_(std::move(options)),
      previews_(previews),
      callbacks_(std::move(callbacks)),
      max_track_points_(max_track_points),
      tracks_client_(options_),
      control_client_(options_) {
  status_.set_rig(name_);
  status_.set_address(options_.address);
  status_.set_connection(v1::StationRigStatus::CONNECTION_CONNECTING);
}

RigLink::~RigLink() { Stop(); }

void RigLink::Start() {
  std::lock_guard lock(mu_);
  if (started_ || stopping_) return;
  started_ = true;
  tracks_thread_ = std::thread([this] {
    client::NameThisThread("stevi-tracks");
    TracksLoop();
  });
  status_thread_ = std::thread([this] {
    client::NameThisThread("stevi-status");
    StatusLoop();
  });
}

void RigLink::Stop() {
  {
    std::lock_guard lock(mu_);
    if (stopping_) return;
    stopping_ = true;
    for (auto& [kind, stream] : preview_streams_) {
      stream.stop->store(true);
      retired_.push_back(std::move(stream));
    }
    preview_streams_.clear();
  }
  cv_.notify_all();
  tracks_client_.Cancel();
  if (tracks_thread_.joinable()) tracks_thread_.join();
  if (status_thread_.joinable()) status_thread_.join();
  ReapPreviews(/*all=*/true);
}

bool RigLink::Wait(Clock::duration d) {
  std::unique_lock lock(mu_);
  cv_.wait_for(lock, d, [this] { return stopping_; });
  return !stopping_;
}

void RigLink::TracksLoop() {
  client::StreamOptions options;
  options.reconnect = true;
  options.persist_once_streaming = true;
  options.max_reconnect_attempts = 0;  // never give up: the server may come up later
  options.on_event = [this](const client::StreamEvent& event) {
    if (event.kind == client::StreamEvent::Kind::kLost) {
      SetConnection(false, "track stream lost: " + Describe(event.status));
    } else {
      {
        std::lock_guard lock(mu_);
        status_.set_reconnects(event.reconnects);
      }
      SetConnection(true, "");
    }
  };
  while (true) {
    {
      std::lock_guard lock(mu_);
      if (stopping_) return;
    }
    const grpc::Status status = tracks_client_.StreamTracks(
        [this](const v1::TrackFrame& frame) {
          const Clock::time_point now = Clock::now();
          {
            std::lock_guard lock(mu_);
            if (stopping_) return false;
            Note(frame_times_, now);
            status_.set_track_frames(status_.track_frames() + 1);
            std::vector<client::TrackPoint> points;
            client::CollectTrackPoints(frame, points);
            for (client::TrackPoint& p : points) points_.push_back(p);
            while (points_.size() > max_track_points_) points_.pop_front();
          }
          if (callbacks_.on_frame) callbacks_.on_frame(frame);
          return true;
        },
        options);
    if (!Wait(std::chrono::milliseconds(0))) return;
    // Only a refusal ends a stream that never gives up: say why and try again later.
    SetConnection(false, "track stream refused: " + Describe(status));
    if (!Wait(kRefusedRetry)) return;
  }
}

void RigLink::StatusLoop() {
  client::ClientOptions poll_options = options_;
  poll_options.timeout = std::min(options_.timeout, std::chrono::milliseconds(2000));
  client::Client poll(poll_options);
  while (true) {
    v1::GetStatusResponse response;
    const grpc::Status status = poll.GetStatus(&response);
    if (status.ok()) {
      {
        std::lock_guard lock(mu_);
        *status_.mutable_server() = response;
      }
      SetConnection(true, "");
    } else if (!FramesFlowing()) {
      // A status call can fail while frames flow (its connection still backing off after an
      // outage): the stream is the better witness.
      SetConnection(false, Describe(status));
    }
    PublishStatus();
    ReapPreviews(/*all=*/false);
    if (!Wait(kStatusPeriod)) return;
  }
}

bool RigLink::FramesFlowing() const {
  std::lock_guard lock(mu_);
  return !frame_times_.empty() && Clock::now() - frame_times_.back() < kFramesFlowing;
}

void RigLink::SetConnection(bool up, const std::string& error) {
  bool changed = false;
  {
    std::lock_guard lock(mu_);
    const auto before = status_.connection();
    if (up) {
      status_.set_connection(v1::StationRigStatus::CONNECTION_UP);
      status_.clear_error();
    } else {
      // Never reached: still connecting. Reached once: down.
      if (before == v1::StationRigStatus::CONNECTION_UP) {
        status_.set_connection(v1::StationRigStatus::CONNECTION_DOWN);
        down_since_ = Clock::now();
      }
      status_.set_error(error);
    }
    changed = before != status_.connection();
  }
  if (changed) PublishStatus();
}

v1::StationRigStatus RigLink::Status() const {
  const Clock::time_point now = Clock::now();
  std::lock_guard lock(mu_);
  v1::StationRigStatus s = status_;
  s.set_track_frames_per_s(Rate(frame_times_, now));
  s.set_previews_per_s(Rate(preview_times_, now));
  s.set_unix_time_ns(UnixNowNs());
  s.set_down_for_s(s.connection() == v1::StationRigStatus::CONNECTION_DOWN
                       ? std::chrono::duration<double>(now - down_since_).count()
                       : 0.0);
  return s;
}

void RigLink::PublishStatus() {
  if (callbacks_.on_status) callbacks_.on_status(Status());
}

void RigLink::SetPreviewWanted(v1::PreviewKind kind, bool wanted) {
  std::lock_guard lock(mu_);
  if (stopping_) return;
  const auto it = preview_streams_.find(kind);
  if (wanted == (it != preview_streams_.end())) return;
  if (!wanted) {
    it->second.stop->store(true);
    it->second.client->Cancel();
    retired_.push_back(std::move(it->second));
    preview_streams_.erase(it);
    return;
  }
  PreviewStream stream;
  stream.client = std::make_unique<client::Client>(options_);
  client::Client* c = stream.client.get();
  const std::atomic<bool>* stop = stream.stop.get();
  std::shared_ptr<std::atomic<bool>> done = stream.done;
  stream.thread = std::thread([this, kind, c, stop, done] {
    client::NameThisThread("stevi-preview");
    PreviewLoop(kind, c, stop);
    done->store(true);
  });
  preview_streams_.emplace(kind, std::move(stream));
}

void RigLink::PreviewLoop(v1::PreviewKind kind, client::Client* c, const std::atomic<bool>* stop) {
  v1::StreamPreviewRequest request;
  request.add_kinds(kind);
  request.set_rate_hz(previews_.rate_hz);
  request.set_max_width_px(previews_.max_width_px);
  request.set_jpeg_quality(previews_.jpeg_quality);
  client::StreamOptions options;
  options.reconnect = true;
  options.persist_once_streaming = true;
  options.max_reconnect_attempts = 0;
  while (!stop->load()) {
    (void)c->StreamPreview(
        request,
        [this, stop](const v1::Preview& preview) {
          if (stop->load()) return false;
          {
            std::lock_guard lock(mu_);
            Note(preview_times_, Clock::now());
            status_.set_previews(status_.previews() + 1);
          }
          if (callbacks_.on_preview) callbacks_.on_preview(preview);
          return true;
        },
        options);
    // Refused (an old server without previews answers UNIMPLEMENTED): try again later.
    std::unique_lock lock(mu_);
    cv_.wait_for(lock, kRefusedRetry, [this, stop] { return stopping_ || stop->load(); });
  }
}

void RigLink::ReapPreviews(bool all) {
  std::vector<PreviewStream> ended;
  {
    std::lock_guard lock(mu_);
    for (auto it = retired_.begin(); it != retired_.end();) {
      if (all || it->done->load()) {
        ended.push_back(std::move(*it));
        it = retired_.erase(it);
      } else {
        it->client->Cancel();  // again: a Cancel() before the call started is forgotten
        ++it;
      }
    }
  }
  cv_.notify_all();
  for (PreviewStream& s : ended) {
    // A stream that has not ended yet is cancelled until it does (Stop() reaps them all).
    while (!s.done->load()) {
      s.client->Cancel();
      if (s.thread.joinable() && s.done->load()) break;
      std::unique_lock lock(mu_);
      cv_.wait_for(lock, std::chrono::milliseconds(20));
    }
    if (s.thread.joinable()) s.thread.join();
  }
}

grpc::Status RigLink::GetConfig(v1::PipelineConfig* config) {
  return control_client_.GetPipelineConfig(config);
}

grpc::Status RigLink::SetConfig(const v1::PipelineConfig& update, const std::string& operator_token,
                                v1::PipelineConfig* active) {
  return AsOperator(options_, operator_token,
                    [&](client::Client& c) { return c.SetPipelineConfig(update, active); });
}

grpc::Status RigLink::Snapshot(bool annotated, v1::DisparitySnapshot* snapshot) {
  return control_client_.GetDisparitySnapshot(snapshot, annotated);
}

grpc::Status RigLink::ListCalibrations(v1::ListCalibrationsResponse* response) {
  return control_client_.ListCalibrations(response);
}

grpc::Status RigLink::ActivateCalibration(const std::string& id, const std::string& operator_token,
                                          v1::CalibrationRecord* record) {
  return AsOperator(options_, operator_token,
                    [&](client::Client& c) { return c.ActivateCalibration(id, record); });
}

std::vector<client::TrackPoint> RigLink::TrackPoints() const {
  std::lock_guard lock(mu_);
  return {points_.begin(), points_.end()};
}

}  // namespace stevi::station
