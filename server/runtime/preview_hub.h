// Live JPEG previews of the processed frames for people watching: each frame is encoded once for
// every subscriber that asked for the same kind, width and quality, on a thread of the hub's own
// (never on the engine's), and only when some subscriber is due one. No gRPC here.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "core/pipeline/pipeline.h"
#include "server/runtime/broadcaster.h"

namespace stevi::server {

enum class PreviewKind {
  kAnnotatedLeft,  // the rectified left image with the tracks drawn (pipeline::AnnotateTracks)
  kDisparity,      // the colour-mapped disparity (stereo::ToColour)
  kLeft,           // the rectified left image as processed (grey)
};

// What one subscriber asks for. The field names are those of stevi.v1.StreamPreviewRequest.
struct PreviewRequest {
  std::vector<PreviewKind> kinds;  // at least one, no duplicates; previews come in this order
  double rate_hz = 5;              // previews per second of each kind, (0, 30], on capture time
  int max_width_px = 640;          // 64..4096: downscaled to at most this, aspect kept, never up
  int jpeg_quality = 80;           // 10..100

  // Every problem, each naming its field ("rate_hz: must be in (0, 30], got 40").
  std::vector<std::string> Validate() const;
};

// One encoded preview, shared (read-only) by every subscriber that asked for it.
struct Preview {
  uint64_t frame_id = 0;  // FrameResult::frame_id
  int64_t capture_time_ns = 0;
  int64_t capture_unix_time_ns = 0;
  PreviewKind kind = PreviewKind::kAnnotatedLeft;
  std::string jpeg;
  int width = 0;  // of the JPEG
  int height = 0;
  // JPEG pixels per pixel of the image the tracks' boxes are in (the frame's rig image size).
  double scale = 1;
  std::string calibration_id;
};
using PreviewPtr = std::shared_ptr<const Preview>;
using PreviewSubscription = Subscription<PreviewPtr>;

struct PreviewHubOptions {
  // Previews queued per subscriber and per kind it asked for; beyond, the oldest is dropped and
  // counted (Subscription::dropped).
  size_t queue_per_kind = 2;
  size_t max_subscribers = 16;
  // The hub thread's nice value (Linux: per thread): it yields to the pipeline when the cores are
  // busy, so that encoding takes the pipeline's spare time. 0 leaves it as created.
  int thread_nice = 10;
};

// The image of `kind` for `frame` at full size (BGR, or grey for kLeft); empty when the frame has
// none. What the hub encodes, before downscaling.
cv::Mat RenderPreview(const pipeline::FrameResult& frame, PreviewKind kind);
// `image` downscaled (cv::INTER_AREA) to at most `max_width_px` wide, keeping its aspect ratio
// (height rounded); unchanged (shared, not copied) when it is not wider.
cv::Mat FitWidth(const cv::Mat& image, int max_width_px);
// `fitted` (RenderPreview's image, FitWidth'ed) as a JPEG preview of `frame`; nullopt when there
// is no image or it does not encode.
std::optional<Preview> EncodePreview(const pipeline::FrameResult& frame, PreviewKind kind,
                                     const cv::Mat& fitted, int jpeg_quality);
// Renders, fits and encodes in one go (one preview alone, as stevi-process writes them).
std::optional<Preview> EncodePreview(const pipeline::FrameResult& frame, PreviewKind kind,
                                     int max_width_px, int jpeg_quality);

// Thread-safe. Its thread starts in the constructor; Close() (or the destructor) joins it.
class PreviewHub {
 public:
  explicit PreviewHub(PreviewHubOptions options = {});
  ~PreviewHub();
  PreviewHub(const PreviewHub&) = delete;
  PreviewHub& operator=(const PreviewHub&) = delete;

  // From the engine's sink: the latest processed frame. Returns at once (a pointer swap); a frame
  // the hub has not taken yet is replaced (latest wins). Without subscribers it does nothing.
  void Offer(std::shared_ptr<const pipeline::FrameResult> frame);

  // `request` must be valid (PreviewRequest::Validate). nullptr when max_subscribers are already
  // subscribed or the hub was closed. The first preview of each kind comes with the next frame.
  std::shared_ptr<PreviewSubscription> Subscribe(std::string peer, PreviewRequest request);
  void Unsubscribe(uint64_t id);

  // Ends every subscription, refuses new ones and joins the thread (shutdown). Idempotent.
  // Returns how many subscriptions it ended.
  size_t Close();
  bool closed() const;
  size_t size() const;

  // Waits until every frame offered so far was handled or replaced; false after `timeout`.
  bool WaitIdle(std::chrono::milliseconds timeout);

  struct Stats {
    uint64_t frames_offered = 0;   // Offer()s taken (with subscribers, not closed)
    uint64_t frames_handled = 0;   // frames the thread looked at
    uint64_t frames_replaced = 0;  // offered frames replaced before the thread took them
    uint64_t encodes = 0;          // JPEG encodings (one per frame per distinct request due)
    uint64_t previews_queued = 0;  // previews given to subscribers' queues
    // CPU time the hub's thread spent on frames (rendering, scaling, encoding), nanoseconds:
    // what previews cost the machine.
    uint64_t cpu_ns = 0;
  };
  Stats stats() const;

 private:
  struct Subscriber;
  void Loop();
  void Handle(const pipeline::FrameResult& frame);

  const PreviewHubOptions options_;
  std::atomic<size_t> subscriber_count_{0};  // Offer()'s quick check, without the lock

  mutable std::mutex subs_mu_;  // guards the three below
  std::map<uint64_t, std::shared_ptr<Subscriber>> subs_;
  uint64_t next_id_ = 1;
  bool closed_ = false;

  mutable std::mutex mu_;            // guards the frame hand-off and the counters below
  std::condition_variable cv_;       // the thread waits for a frame or stop_
  std::condition_variable idle_cv_;  // WaitIdle() waits for the thread
  std::shared_ptr<const pipeline::FrameResult> pending_;
  bool busy_ = false;
  bool stop_ = false;
  Stats stats_;
  std::thread thread_;
};

}  // namespace stevi::server
