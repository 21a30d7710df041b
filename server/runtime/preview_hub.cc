#include "server/runtime/preview_hub.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <tuple>
#include <utility>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/thread_name.h"
#include "core/pipeline/annotate.h"
#include "core/stereo/disparity.h"

namespace stevi::server {

namespace {

// This thread's CPU time, nanoseconds.
int64_t ThreadCpuNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace

std::vector<std::string> PreviewRequest::Validate() const {
  std::vector<std::string> problems;
  if (kinds.empty()) problems.push_back("kinds: at least one kind is needed");
  std::set<PreviewKind> seen;
  for (size_t i = 0; i < kinds.size(); ++i) {
    if (!seen.insert(kinds[i]).second) {
      problems.push_back("kinds[" + std::to_string(i) + "]: listed twice");
    }
  }
  if (!(rate_hz > 0 && rate_hz <= 30))
    problems.push_back("rate_hz: must be in (0, 30]" + Got(rate_hz));
  if (max_width_px < 64 || max_width_px > 4096) {
    problems.push_back("max_width_px: must be in 64..4096" + Got(max_width_px));
  }
  if (jpeg_quality < 10 || jpeg_quality > 100) {
    problems.push_back("jpeg_quality: must be in 10..100" + Got(jpeg_quality));
  }
  return problems;
}

cv::Mat RenderPreview(const pipeline::FrameResult& frame, PreviewKind kind) {
  switch (kind) {
    case PreviewKind::kAnnotatedLeft: return pipeline::AnnotateTracks(frame);
    case PreviewKind::kDisparity:
      if (frame.disparity.fixed.empty()) return {};
      return stereo::ToColour(frame.disparity);
    case PreviewKind::kLeft: return frame.rectified_left;
  }
  return {};
}

cv::Mat FitWidth(const cv::Mat& image, int max_width_px) {
  if (image.empty() || image.cols <= max_width_px) return image;
  const int height = std::max(1, static_cast<int>(std::lround(static_cast<double>(image.rows) *
                                                              max_width_px / image.cols)));
  cv::Mat out;
  cv::resize(image, out, cv::Size(max_width_px, height), 0, 0, cv::INTER_AREA);
  return out;
}

// The hub's view of one subscriber. The schedule is the hub thread's alone.
struct PreviewHub::Subscriber {
  std::shared_ptr<PreviewSubscription> queue;
  PreviewRequest request;
  int64_t period_ns = 0;
  bool scheduled = false;
  int64_t next_due_ns = 0;  // the capture time from which the next preview is due
  int64_t last_t_ns = 0;

  // Paced on the frames' capture times: the first preview at once, then one with the first frame
  // at or past each slot of a grid of multiples of the period. Every subscriber at one rate (or
  // at a multiple of it) shares the grid, so they are due on the same frames and share their
  // encodings; the mean rate is the one asked for whatever the frame rate; a slot that passes
  // without a frame the hub handles (frames slower than the rate, frames it skipped) is not made
  // up for. A capture time going back (a new source) starts again.
  bool Due(int64_t t_ns) {
    if (!scheduled || t_ns < last_t_ns) {
      scheduled = true;
      next_due_ns = t_ns;
    }
    last_t_ns = t_ns;
    if (t_ns < next_due_ns) return false;
    int64_t slot = t_ns / period_ns;
    if (t_ns % period_ns < 0) --slot;  // floor, also before the epoch
    next_due_ns = (slot + 1) * period_ns;
    return true;
  }
};

PreviewHub::PreviewHub(PreviewHubOptions options) : options_(options) {
  thread_ = std::thread([this] {
    NameThisThread("stevi-preview");
    Loop();
  });
}

PreviewHub::~PreviewHub() { Close(); }

void PreviewHub::Offer(std::shared_ptr<const pipeline::FrameResult> frame) {
  if (frame == nullptr || subscriber_count_.load(std::memory_order_relaxed) == 0) return;
  {
    std::lock_guard lock(mu_);
    if (stop_) return;
    if (pending_ != nullptr) ++stats_.frames_replaced;
    pending_ = std::move(frame);
    ++stats_.frames_offered;
  }
  cv_.notify_one();
}

std::shared_ptr<PreviewSubscription> PreviewHub::Subscribe(std::string peer,
                                                           PreviewRequest request) {
  std::lock_guard lock(subs_mu_);
  if (closed_ || subs_.size() >= options_.max_subscribers) return nullptr;
  auto sub = std::make_shared<Subscriber>();
  const size_t capacity = std::max<size_t>(1, options_.queue_per_kind) * request.kinds.size();
  sub->queue = std::make_shared<PreviewSubscription>(next_id_++, std::move(peer), capacity);
  sub->period_ns = static_cast<int64_t>(std::llround(1e9 / request.rate_hz));
  sub->request = std::move(request);
  subs_.emplace(sub->queue->id(), sub);
  subscriber_count_.store(subs_.size());
  return sub->queue;
}

void PreviewHub::Unsubscribe(uint64_t id) {
  std::lock_guard lock(subs_mu_);
  subs_.erase(id);
  subscriber_count_.store(subs_.size());
}

size_t PreviewHub::Close() {
  std::vector<std::shared_ptr<Subscriber>> ended;
  {
    std::lock_guard lock(subs_mu_);
    closed_ = true;
    for (auto& [id, sub] : subs_) ended.push_back(sub);
  }
  for (const auto& sub : ended) sub->queue->End();
  {
    std::lock_guard lock(mu_);
    stop_ = true;
    pending_.reset();
  }
  cv_.notify_all();
  idle_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  return ended.size();
}

bool PreviewHub::closed() const {
  std::lock_guard lock(subs_mu_);
  return closed_;
}

size_t PreviewHub::size() const {
  std::lock_guard lock(subs_mu_);
  return subs_.size();
}

bool PreviewHub::WaitIdle(std::chrono::milliseconds timeout) {
  std::unique_lock lock(mu_);
  return idle_cv_.wait_for(lock, timeout, [this] { return stop_ || (!pending_ && !busy_); });
}

PreviewHub::Stats PreviewHub::stats() const {
  std::lock_guard lock(mu_);
  return stats_;
}

void PreviewHub::Loop() {
  if (options_.thread_nice != 0) {
    // Linux gives each thread its own nice value (setpriority on its thread id).
    setpriority(PRIO_PROCESS, static_cast<id_t>(::syscall(SYS_gettid)), options_.thread_nice);
  }
  std::unique_lock lock(mu_);
  while (true) {
    cv_.wait(lock, [this] { return stop_ || pending_ != nullptr; });
    if (stop_) return;
    std::shared_ptr<const pipeline::FrameResult> frame = std::move(pending_);
    pending_.reset();
    busy_ = true;
    lock.unlock();
    const int64_t cpu_start = ThreadCpuNs();
    Handle(*frame);
    frame.reset();
    const int64_t cpu_ns = ThreadCpuNs() - cpu_start;
    lock.lock();
    busy_ = false;
    ++stats_.frames_handled;
    stats_.cpu_ns += static_cast<uint64_t>(std::max<int64_t>(0, cpu_ns));
    idle_cv_.notify_all();
  }
}

std::optional<Preview> EncodePreview(const pipeline::FrameResult& frame, PreviewKind kind,
                                     const cv::Mat& fitted, int jpeg_quality) {
  std::vector<uchar> jpeg;
  if (fitted.empty() ||
      !cv::imencode(".jpg", fitted, jpeg, {cv::IMWRITE_JPEG_QUALITY, jpeg_quality})) {
    return std::nullopt;
  }
  const int image_width =
      frame.rig ? frame.rig->image_size().width : std::max(1, frame.rectified_left.cols);
  Preview p;
  p.frame_id = frame.frame_id;
  p.capture_time_ns = frame.capture_time_ns;
  p.capture_unix_time_ns = frame.capture_unix_time_ns;
  p.kind = kind;
  p.jpeg.assign(jpeg.begin(), jpeg.end());
  p.width = fitted.cols;
  p.height = fitted.rows;
  p.scale = static_cast<double>(fitted.cols) / image_width;
  p.calibration_id = frame.rig ? frame.rig->calibration_id() : std::string();
  return p;
}

std::optional<Preview> EncodePreview(const pipeline::FrameResult& frame, PreviewKind kind,
                                     int max_width_px, int jpeg_quality) {
  return EncodePreview(frame, kind, FitWidth(RenderPreview(frame, kind), max_width_px),
                       jpeg_quality);
}

void PreviewHub::Handle(const pipeline::FrameResult& frame) {
  std::vector<std::shared_ptr<Subscriber>> due;
  {
    std::lock_guard lock(subs_mu_);
    for (auto& [id, sub] : subs_) {
      if (sub->Due(frame.capture_time_ns)) due.push_back(sub);
    }
  }
  if (due.empty()) return;
  // Within this frame: each kind rendered once, each (kind, width) downscaled once, each
  // (kind, width, quality) encoded once.
  std::map<PreviewKind, cv::Mat> rendered;
  std::map<std::pair<PreviewKind, int>, cv::Mat> fitted;
  std::map<std::tuple<PreviewKind, int, int>, PreviewPtr> encoded;
  const auto preview_for = [&](PreviewKind kind, int max_width, int quality) -> PreviewPtr {
    const auto key = std::make_tuple(kind, max_width, quality);
    if (auto it = encoded.find(key); it != encoded.end()) return it->second;
    auto r = rendered.find(kind);
    if (r == rendered.end()) r = rendered.emplace(kind, RenderPreview(frame, kind)).first;
    auto f = fitted.find({kind, max_width});
    if (f == fitted.end())
      f = fitted.emplace(std::pair(kind, max_width), FitWidth(r->second, max_width)).first;
    PreviewPtr out;
    if (std::optional<Preview> p = EncodePreview(frame, kind, f->second, quality)) {
      out = std::make_shared<const Preview>(std::move(*p));
      std::lock_guard lock(mu_);
      ++stats_.encodes;
    }
    encoded.emplace(key, out);  // a failure (no image) is not tried again for this frame
    return out;
  };
  uint64_t queued = 0;
  for (const auto& sub : due) {
    const PreviewRequest& r = sub->request;
    for (const PreviewKind kind : r.kinds) {
      if (PreviewPtr p = preview_for(kind, r.max_width_px, r.jpeg_quality)) {
        sub->queue->Push(std::move(p));
        ++queued;
      }
    }
  }
  std::lock_guard lock(mu_);
  stats_.previews_queued += queued;
}

}  // namespace stevi::server
