#include "server/service.h"

#include <algorithm>
#include <functional>
#include <string>
#include <utility>

#include "server/convert.h"
#include "server/grpc_status.h"
#include "server/tsan_handover.h"

namespace stevi::server {
namespace {

v1::SourceState ToProto(SourceState state) {
  switch (state) {
    case SourceState::kStarting: return v1::SOURCE_STATE_STARTING;
    case SourceState::kRunning: return v1::SOURCE_STATE_RUNNING;
    case SourceState::kDown: return v1::SOURCE_STATE_DOWN;
    case SourceState::kEnded: return v1::SOURCE_STATE_ENDED;
  }
  return v1::SOURCE_STATE_UNSPECIFIED;
}

// One streaming call over a subscriber's queue (StreamTracks, StreamPreview): writes the queue,
// one write in flight at a time. Lifetime: deleted in OnDone(), after detaching from the
// subscription and calling `on_done` (the unsubscribe).
template <typename Item, typename Message>
class QueueStreamReactor final : public grpc::ServerWriteReactor<Message> {
 public:
  // Fills the message to write from a queued item and the subscriber's drops so far.
  using ToMessage = std::function<void(const Item& item, uint64_t dropped, Message& out)>;

  // A refusal: finishes at once with `status`.
  explicit QueueStreamReactor(const grpc::Status& status) {
    finished_ = true;
    HandOver(this);
    this->Finish(status);
  }

  QueueStreamReactor(std::shared_ptr<Subscription<Item>> sub, ToMessage to_message,
                     std::function<void()> on_done)
      : sub_(std::move(sub)), to_message_(std::move(to_message)), on_done_(std::move(on_done)) {
    HandOver(this);
    sub_->SetNotify([this] { WriteNext(); });
    WriteNext();
  }

  void OnWriteDone(bool ok) override {
    const CallbackScope scope(this);
    {
      std::lock_guard lock(mu_);
      writing_ = false;
      if (!ok) {
        FinishLocked(ToGrpcStatus(Unavailable("stream write failed")));
        return;
      }
    }
    WriteNext();
  }

  void OnCancel() override {
    const CallbackScope scope(this);
    std::lock_guard lock(mu_);
    cancelled_ = true;
    if (!writing_) FinishLocked(ToGrpcStatus(Cancelled("the client cancelled the stream")));
  }

  void OnDone() override {
    TakeOver(this);
    if (sub_ != nullptr) sub_->Detach();
    if (on_done_) on_done_();
    CallEnded();
    delete this;
  }

 private:
  // Starts the next write when idle: from the constructor, from OnWriteDone and from the
  // subscription's notify (on the producer's thread). Never two at once (see Subscription).
  void WriteNext() {
    std::lock_guard lock(mu_);
    if (finished_ || writing_) return;
    if (cancelled_) {
      FinishLocked(ToGrpcStatus(Cancelled("the client cancelled the stream")));
      return;
    }
    typename Subscription<Item>::Popped popped = sub_->Pop();
    switch (popped.state) {
      case Subscription<Item>::PopState::kEmpty: return;  // notified at the next item
      case Subscription<Item>::PopState::kEnded:
        FinishLocked(ToGrpcStatus(Unavailable("server shutting down")));
        return;
      case Subscription<Item>::PopState::kItem:
        current_.Clear();
        to_message_(*popped.item, popped.dropped, current_);
        writing_ = true;
        HandOver(this);
        this->StartWrite(&current_);
        return;
    }
  }

  void FinishLocked(const grpc::Status& status) {
    if (finished_) return;
    finished_ = true;
    HandOver(this);
    this->Finish(status);
  }

  std::shared_ptr<Subscription<Item>> sub_;
  const ToMessage to_message_;
  const std::function<void()> on_done_;
  std::mutex mu_;
  bool writing_ = false;
  bool finished_ = false;
  bool cancelled_ = false;
  Message current_;
};

using TrackStreamReactor = QueueStreamReactor<FramePtr, v1::TrackFrame>;
using PreviewStreamReactor = QueueStreamReactor<PreviewPtr, v1::Preview>;

// A subscription refused: UNAVAILABLE while shutting down, else RESOURCE_EXHAUSTED naming the
// limit.
grpc::Status Refusal(bool closed, const std::string& limit) {
  return closed ? ToGrpcStatus(Unavailable("server shutting down"))
                : ToGrpcStatus(ResourceExhausted(limit));
}

}  // namespace

// PublishVehicleState: each state into the pose source; refusals are counted, the stream goes on.
// A client stream waits for its client's next state, so a shutdown ends it (End) rather than
// leave the server's stop to gRPC's grace. Lifetime: deleted in OnDone(), after `on_done`
// removes it from the service's set.
class VehicleStateReactor final : public grpc::ServerReadReactor<v1::VehicleState> {
 public:
  VehicleStateReactor(PoseSource& poses, v1::PublishVehicleStateResponse* response,
                      std::function<void()> on_done)
      : poses_(poses), response_(response), on_done_(std::move(on_done)) {
    HandOver(this);
    StartRead(&state_);
  }

  void OnReadDone(bool ok) override {
    const CallbackScope scope(this);
    std::lock_guard lock(mu_);
    if (finished_) return;
    if (!ok) {
      FinishLocked(grpc::Status::OK);
      return;
    }
    if (Status added = poses_.Publish(FromProto(state_)); added.ok()) {
      response_->set_accepted(response_->accepted() + 1);
    } else {
      response_->set_refused(response_->refused() + 1);
      response_->set_last_error(added.error().message);
    }
    HandOver(this);
    StartRead(&state_);
  }

  // From any thread; the first status given is the call's.
  void End(const grpc::Status& status) {
    std::lock_guard lock(mu_);
    FinishLocked(status);
  }

  void OnDone() override {
    TakeOver(this);
    on_done_();
    CallEnded();
    delete this;
  }

 private:
  void FinishLocked(const grpc::Status& status) {
    if (finished_) return;
    finished_ = true;
    HandOver(this);
    Finish(status);
  }

  PoseSource& poses_;
  v1::PublishVehicleStateResponse* response_;
  const std::function<void()> on_done_;
  std::mutex mu_;
  bool finished_ = false;
  v1::VehicleState state_;
};

grpc::Status ValidateStreamTracksRequest(const v1::StreamTracksRequest& request) {
  const double s = request.min_score();
  if (!(s >= 0.0 && s <= 1.0)) {
    return ToGrpcStatus(InvalidArgument("min_score: must be in [0, 1]" + Got(s)));
  }
  return grpc::Status::OK;
}

void FilterTracks(const v1::StreamTracksRequest& request, v1::TrackFrame& frame) {
  if (!request.confirmed_only() && request.min_score() <= 0) return;
  google::protobuf::RepeatedPtrField<v1::Track>* tracks = frame.mutable_tracks();
  int kept = 0;
  for (int i = 0; i < tracks->size(); ++i) {
    const v1::Track& t = tracks->Get(i);
    if (request.confirmed_only() && t.state() == v1::TRACK_STATE_TENTATIVE) continue;
    if (t.score() < request.min_score()) continue;
    if (kept != i) tracks->SwapElements(kept, i);
    ++kept;
  }
  tracks->DeleteSubrange(kept, tracks->size() - kept);
}

grpc::Status GetStatusImpl(const Engine& engine, const FrameBroadcaster& broadcaster,
                           const RecordingManager* recording, const PreviewHub* previews,
                           v1::GetStatusResponse* response) {
  const EngineStatus s = engine.Status();
  response->set_source_state(ToProto(s.source_state));
  response->set_source(s.source);
  response->set_source_error(s.source_error);
  response->set_fps_in(s.fps_in);
  response->set_fps_out(s.fps_out);
  response->set_frames_captured(s.frames_captured);
  response->set_frames_processed(s.frames_processed);
  response->set_frames_failed(s.frames_failed);
  response->set_frames_dropped_capture(s.frames_dropped_capture);
  ToProto(s.mean_timings, response->mutable_timings());
  response->set_algorithm(ToProto(s.algorithm));
  response->set_calibration_id(s.calibration_id);
  response->set_uptime_s(s.uptime_s);
  response->set_pipeline_workers(static_cast<uint32_t>(s.workers));
  response->set_opencv_threads(static_cast<uint32_t>(std::max(0, s.opencv_threads)));
  response->set_image_width(s.image_size.width);
  response->set_image_height(s.image_size.height);
  response->set_processed_width(s.processed_size.width);
  response->set_processed_height(s.processed_size.height);
  response->set_binning(s.binning);
  v1::PairingStatus* pairing = response->mutable_pairing();
  pairing->set_pairs(s.pairing.pairs);
  pairing->set_unpaired_dropped(s.pairing.unpaired_dropped);
  pairing->set_incomplete_dropped(s.pairing.incomplete_dropped);
  pairing->set_reconnects(s.pairing.reconnects);
  pairing->set_last_skew_ns(s.pairing.last_skew_ns);
  pairing->set_max_abs_skew_ns(s.pairing.max_abs_skew_ns);
  pairing->set_mean_abs_skew_ns(s.pairing.mean_abs_skew_ns);
  if (recording != nullptr) *response->mutable_recording() = recording->Status();
  if (previews != nullptr) {
    response->set_preview_streams(static_cast<uint32_t>(previews->size()));
    response->set_preview_encodes(previews->stats().encodes);
  }
  for (const auto& sub : broadcaster.Stats()) {
    v1::SubscriberStatus* out = response->add_subscribers();
    out->set_subscriber_id(sub.id);
    out->set_peer(sub.peer);
    out->set_frames_sent(sub.sent);
    out->set_frames_dropped(sub.dropped);
  }
  return grpc::Status::OK;
}

grpc::Status GetPipelineConfigImpl(Engine& engine, v1::PipelineConfig* response) {
  *response = ToProto(*engine.config().Get());
  return grpc::Status::OK;
}

grpc::Status SetPipelineConfigImpl(Engine& engine, std::mutex& mu,
                                   const v1::SetPipelineConfigRequest& request,
                                   v1::PipelineConfig* response) {
  std::lock_guard lock(mu);
  pipeline::PipelineConfig updated = *engine.config().Get();
  if (std::vector<std::string> problems = MergeFromProto(request.config(), updated);
      !problems.empty()) {
    return ToGrpcStatus(InvalidArgument(problems));
  }
  Result<std::shared_ptr<const pipeline::PipelineConfig>> active =
      engine.config().Set(std::move(updated));
  if (!active.ok()) return ToGrpcStatus(active.error());
  *response = ToProto(**active);
  return grpc::Status::OK;
}

grpc::Status GetDisparitySnapshotImpl(const Engine& engine,
                                      const v1::GetDisparitySnapshotRequest& request,
                                      v1::DisparitySnapshot* response) {
  const EngineStatus status = engine.Status();
  if (status.source_state == SourceState::kDown) {
    return ToGrpcStatus(Unavailable("source is down: " + status.source_error));
  }
  std::shared_ptr<const pipeline::FrameResult> latest = engine.Latest();
  if (latest == nullptr) {
    return ToGrpcStatus(FailedPrecondition("no frame has been processed yet"));
  }
  Result<v1::DisparitySnapshot> snapshot = ToSnapshot(*latest, request.annotated());
  if (!snapshot.ok()) return ToGrpcStatus(snapshot.error());
  *response = std::move(snapshot).value();
  return grpc::Status::OK;
}

grpc::ServerWriteReactor<v1::TrackFrame>* ObstacleServiceImpl::StreamTracks(
    grpc::CallbackServerContext* context, const v1::StreamTracksRequest* request) {
  if (grpc::Status status = ValidateStreamTracksRequest(*request); !status.ok()) {
    return new TrackStreamReactor(status);
  }
  std::shared_ptr<Subscription<FramePtr>> sub = broadcaster_.Subscribe(context->peer());
  if (sub == nullptr) {
    return new TrackStreamReactor(
        Refusal(broadcaster_.closed(), "too many StreamTracks subscribers (see max_streams)"));
  }
  const uint64_t id = sub->id();
  return new TrackStreamReactor(
      std::move(sub),
      [filter = *request](const FramePtr& frame, uint64_t dropped, v1::TrackFrame& out) {
        out = *frame;
        FilterTracks(filter, out);
        out.set_dropped_frames(dropped);
      },
      [this, id] { broadcaster_.Unsubscribe(id); });
}

grpc::ServerWriteReactor<v1::Preview>* ObstacleServiceImpl::StreamPreview(
    grpc::CallbackServerContext* context, const v1::StreamPreviewRequest* request) {
  Result<PreviewRequest> valid = ToPreviewRequest(*request);
  if (!valid.ok()) return new PreviewStreamReactor(ToGrpcStatus(valid.error()));
  std::shared_ptr<PreviewSubscription> sub =
      previews_.Subscribe(context->peer(), std::move(valid).value());
  if (sub == nullptr) {
    return new PreviewStreamReactor(Refusal(
        previews_.closed(), "too many StreamPreview subscribers (see max_streams; at most " +
                                std::to_string(kMaxPreviewStreams) + ")"));
  }
  const uint64_t id = sub->id();
  return new PreviewStreamReactor(
      std::move(sub),
      [](const PreviewPtr& preview, uint64_t dropped, v1::Preview& out) {
        out = ToProto(*preview);
        out.set_dropped_previews(dropped);
      },
      [this, id] { previews_.Unsubscribe(id); });
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::GetStatus(grpc::CallbackServerContext* context,
                                                         const v1::GetStatusRequest* /*request*/,
                                                         v1::GetStatusResponse* response) {
  return Reply(context, GetStatusImpl(engine_, broadcaster_, &recording_, &previews_, response));
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::GetPipelineConfig(
    grpc::CallbackServerContext* context, const v1::GetPipelineConfigRequest* /*request*/,
    v1::PipelineConfig* response) {
  return Reply(context, GetPipelineConfigImpl(engine_, response));
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::SetPipelineConfig(
    grpc::CallbackServerContext* context, const v1::SetPipelineConfigRequest* request,
    v1::PipelineConfig* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "SetPipelineConfig"); !allowed.ok()) {
    return Reply(context, allowed);
  }
  return Reply(context, SetPipelineConfigImpl(engine_, config_mu_, *request, response));
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::GetDisparitySnapshot(
    grpc::CallbackServerContext* context, const v1::GetDisparitySnapshotRequest* request,
    v1::DisparitySnapshot* response) {
  return Reply(context, GetDisparitySnapshotImpl(engine_, *request, response));
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::StartRecording(
    grpc::CallbackServerContext* context, const v1::StartRecordingRequest* request,
    v1::RecordingStatus* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "StartRecording"); !allowed.ok()) {
    return Reply(context, allowed);
  }
  // Creating the directory and the files is quick; the frames are written by the recorder's own
  // thread.
  Result<v1::RecordingStatus> started = recording_.Start(*request);
  if (started.ok()) *response = std::move(started).value();
  return Reply(context, started.ok() ? grpc::Status::OK : ToGrpcStatus(started.error()));
}

grpc::ServerUnaryReactor* ObstacleServiceImpl::StopRecording(
    grpc::CallbackServerContext* context, const v1::StopRecordingRequest* /*request*/,
    v1::RecordingStatus* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "StopRecording"); !allowed.ok()) {
    return Reply(context, allowed);
  }
  // Waits for the queued frames (at most RecorderOptions::queue_frames) to be written.
  *response = recording_.Stop();
  return Reply(context, grpc::Status::OK);
}

grpc::ServerReadReactor<v1::VehicleState>* ObstacleServiceImpl::PublishVehicleState(
    grpc::CallbackServerContext* context, v1::PublishVehicleStateResponse* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "PublishVehicleState"); !allowed.ok()) {
    return new RefusedReadReactor<v1::VehicleState>(std::move(allowed));
  }
  std::lock_guard lock(vehicle_mu_);
  if (vehicle_closed_) {
    return new RefusedReadReactor<v1::VehicleState>(
        ToGrpcStatus(Unavailable("server shutting down")));
  }
  auto* reactor = new VehicleStateReactor(poses_, response, [this, context] {
    std::lock_guard done_lock(vehicle_mu_);
    vehicle_streams_.erase(context);
  });
  vehicle_streams_.emplace(context, reactor);
  return reactor;
}

size_t ObstacleServiceImpl::EndVehicleStreams() {
  // Under the lock: a reactor's OnDone runs on a gRPC thread, never inside End(), and removes
  // it under this lock before deleting it, so every reactor in the set is alive here.
  std::lock_guard lock(vehicle_mu_);
  vehicle_closed_ = true;
  for (const auto& [context, reactor] : vehicle_streams_) {
    reactor->End(ToGrpcStatus(Unavailable("server shutting down")));
  }
  return vehicle_streams_.size();
}

}  // namespace stevi::server
