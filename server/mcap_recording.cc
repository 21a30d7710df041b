#include "server/mcap_recording.h"

#include <chrono>
#include <utility>

#include "core/common/thread_name.h"
#include "server/convert.h"
#include "server/runtime/log.h"
#include "server/service.h"

namespace stevi::server {
namespace {

constexpr int64_t kStatusPeriodNs = 1'000'000'000;

}  // namespace

McapRecording::McapRecording(McapRecordingOptions options, const Engine& engine,
                             FrameBroadcaster& broadcaster, PreviewHub& previews,
                             const RecordingManager* recording)
    : options_(std::move(options)),
      engine_(engine),
      broadcaster_(broadcaster),
      previews_(previews),
      recording_(recording) {}

Result<std::unique_ptr<McapRecording>> McapRecording::Start(McapRecordingOptions options,
                                                            const Engine& engine,
                                                            FrameBroadcaster& broadcaster,
                                                            PreviewHub& previews,
                                                            const RecordingManager* recording) {
  std::map<std::string, std::string> metadata = {{"source", engine.Status().source},
                                                 {"writer", "stevi-server --record-mcap"}};
  Result<std::unique_ptr<drivers::FlightLog>> log =
      drivers::FlightLog::Create(options.file, options.log, metadata);
  if (!log.ok()) return log.error().Prefixed("record_mcap: ");
  std::unique_ptr<McapRecording> r(
      new McapRecording(std::move(options), engine, broadcaster, previews, recording));
  r->log_ = std::move(log).value();
  r->status_.file = r->options_.file;
  r->status_.active = true;
  r->frames_ = broadcaster.Subscribe("mcap " + r->options_.file);
  if (r->frames_ == nullptr) {
    return ResourceExhausted("record_mcap: no room for another track subscriber (max_streams)");
  }
  if (r->options_.log.image_hz > 0) {
    PreviewRequest request;
    request.kinds = {PreviewKind::kLeft, PreviewKind::kDisparity};
    request.rate_hz = r->options_.log.image_hz;
    request.max_width_px = r->options_.image_max_width_px;
    request.jpeg_quality = r->options_.image_jpeg_quality;
    if (std::vector<std::string> problems = request.Validate(); !problems.empty()) {
      broadcaster.Unsubscribe(r->frames_->id());
      return InvalidArgument(problems).Prefixed("record_mcap: images: ");
    }
    r->images_ = previews.Subscribe("mcap " + r->options_.file, request);
    if (r->images_ == nullptr) {
      broadcaster.Unsubscribe(r->frames_->id());
      return ResourceExhausted("record_mcap: no room for another preview subscriber");
    }
  }
  McapRecording* raw = r.get();
  const auto wake = [raw] {
    {
      std::lock_guard lock(raw->mu_);
      raw->wake_ = true;
    }
    raw->cv_.notify_one();
  };
  r->frames_->SetNotify(wake);
  if (r->images_) r->images_->SetNotify(wake);
  r->thread_ = std::thread([raw] {
    NameThisThread("stevi-mcap");
    raw->Run();
  });
  return r;
}

McapRecording::~McapRecording() { Stop(); }

// The writer's errors are sticky (a full disk fails every later write alike): the first is logged
// and kept for status; the rest are the same.
void McapRecording::Fail(const Error& error) {
  {
    std::lock_guard lock(mu_);
    if (!status_.error.empty()) return;
    status_.error = error.message;
  }
  Log(LogLevel::kError, "mcap_recording", {{"file", options_.file}, {"error", error.message}});
}

void McapRecording::WriteStatus(int64_t unix_time_ns) {
  v1::GetStatusResponse status;
  // The status as GetStatus gives it, minus what only a live client needs.
  (void)GetStatusImpl(engine_, broadcaster_, recording_, &previews_, &status);
  if (stevi::Status s = log_->AddStatus(status, unix_time_ns); !s.ok()) Fail(s.error());
}

bool McapRecording::Drain() {
  bool ended = false;
  for (;;) {
    bool any = false;
    if (images_) {
      PreviewSubscription::Popped image = images_->Pop();
      if (image.state == PreviewSubscription::PopState::kItem) {
        any = true;
        // The hub paces them at the image rate, on capture time.
        if (stevi::Status s = log_->AddImage(ToProto(**image.item)); !s.ok()) Fail(s.error());
      }
    }
    FrameSubscription::Popped frame = frames_->Pop();
    if (frame.state == FrameSubscription::PopState::kItem) {
      any = true;
      const v1::TrackFrame& f = **frame.item;
      if (stevi::Status s = log_->AddFrame(f); !s.ok()) Fail(s.error());
      const int64_t t = f.capture_unix_time_ns();
      if (t >= next_status_ns_) {
        WriteStatus(t);
        next_status_ns_ = t + kStatusPeriodNs;
      }
    } else if (frame.state == FrameSubscription::PopState::kEnded) {
      ended = true;
    }
    {
      std::lock_guard lock(mu_);
      status_.frames_dropped = frame.dropped;
      status_.counts = log_->counts();
    }
    if (!any) return !ended;
  }
}

void McapRecording::Run() {
  std::unique_lock lock(mu_);
  for (;;) {
    lock.unlock();
    const bool open = Drain();
    lock.lock();
    if (!open || stop_) break;
    cv_.wait(lock, [this] { return wake_ || stop_; });
    wake_ = false;
  }
}

McapRecordingStatus McapRecording::Stop() {
  {
    std::lock_guard lock(mu_);
    if (!status_.active) return status_;
    stop_ = true;
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
  frames_->Detach();
  broadcaster_.Unsubscribe(frames_->id());
  if (images_) {
    images_->Detach();
    previews_.Unsubscribe(images_->id());
  }
  Drain();  // what came between the thread's last pass and the unsubscription
  const stevi::Status closed = log_->Close();
  if (!closed.ok()) Fail(closed.error());
  std::lock_guard lock(mu_);
  status_.counts = log_->counts();
  status_.active = false;
  return status_;
}

McapRecordingStatus McapRecording::Status() const {
  std::lock_guard lock(mu_);
  return status_;
}

}  // namespace stevi::server
