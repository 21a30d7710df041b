// Runs a source through the pipeline live: a capture thread, a one-slot latest-wins mailbox and a
// pipeline thread that hands every result to a sink. No gRPC here.
#pragma once

#include <atomic>
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

#include "core/common/error.h"
#include "core/common/mailbox.h"
#include "core/pipeline/config.h"
#include "core/pipeline/pipeline.h"
#include "drivers/stereo_source.h"

namespace stevi::server {

enum class SourceState { kStarting, kRunning, kDown, kEnded };

struct EngineStatus {
  SourceState source_state = SourceState::kStarting;
  std::string source;        // the source's description
  std::string source_error;  // the last error while DOWN (or why it ENDED)
  double fps_in = 0;         // recent capture rate
  double fps_out = 0;        // recent processing rate
  uint64_t frames_captured = 0;
  uint64_t frames_processed = 0;
  uint64_t frames_failed = 0;
  uint64_t frames_dropped_capture = 0;  // replaced in the mailbox before the pipeline took them
  std::vector<pipeline::StageTiming> mean_timings;  // over the last frames
  pipeline::Algorithm algorithm = pipeline::Algorithm::kCanonical;
  std::string calibration_id;
  double uptime_s = 0;
  drivers::SourceCounters pairing;  // the source's pairing and reconnection counters
  size_t workers = 0;               // pipeline workers (frames processed at once); 0 before Start
  int opencv_threads = 0;           // threads an OpenCV call may use
  cv::Size image_size;              // the camera's images (the active rig's); empty without one
  // The images the last frame was processed at, and their binning (PipelineConfig::max_width_px);
  // empty and 0 before the first frame.
  cv::Size processed_size;
  int binning = 0;
};

// Thread-safe. Start() launches the threads; Stop() (also run by the destructor) joins them.
class Engine {
 public:
  using Sink = std::function<void(const std::shared_ptr<const pipeline::FrameResult>&)>;

  // Validates `config` (kInvalidArgument naming every bad field). `sink` runs on the pipeline
  // thread for every processed frame, in order.
  static Result<std::unique_ptr<Engine>> Create(std::unique_ptr<drivers::StereoSource> source,
                                                pipeline::PipelineConfig config, Sink sink);
  ~Engine();
  Engine(const Engine&) = delete;
  Engine& operator=(const Engine&) = delete;

  // `workers`: frames processed at once, each on a thread of its own; 0: one per core, at most
  // kDefaultWorkers. `opencv_threads`: threads one OpenCV call may use; 0: 1 with two or more
  // workers (the cores are already busy with a frame each, and OpenCV's thread pool only adds
  // synchronisation: stevi-bench measures it), OpenCV's own setting (one per core) with one.
  // OpenCV's thread count belongs to the process: only one engine at a time should set it.
  static constexpr size_t kDefaultWorkers = 4;
  void Start(size_t workers = 0, int opencv_threads = 0);
  // Stops capture, lets the frame in progress finish, joins the threads. Idempotent.
  void Stop();

  pipeline::ConfigStore& config() { return config_; }

  // The rig frames are processed with. SetRig() swaps it between two frames: the next frame taken
  // by the pipeline uses it (build it, with its rectification maps, before calling: this only
  // swaps a pointer). With `swap_left_right`, the source's left image is the rig's right camera
  // (a calibration found the cameras named the wrong way round) and the engine swaps each pair.
  void SetRig(std::shared_ptr<const geometry::StereoRig> rig, bool swap_left_right = false);
  std::shared_ptr<const geometry::StereoRig> rig() const;
  // Where the pipeline gets the vehicle pose at a frame's capture (source t_ns, unix ns), for the
  // georeferenced tracks. Set before Start(); empty (the default): no georeferencing.
  void SetPoseSource(std::function<geo::PoseLookup(int64_t, int64_t)> pose_at);

  // Called on the capture thread with every frame the source delivers, before the pipeline may
  // drop it (the recorder). Must return quickly. Empty: none. Safe to change while running.
  using CaptureTap = std::function<void(const StereoFrame&)>;
  void SetCaptureTap(CaptureTap tap);

  // The source's image size (of the rig it was created with).
  cv::Size source_image_size() const { return source_image_size_; }

  // Waits for a frame captured after the call (raw, as the source delivered it, not swapped), for
  // at most `timeout`. kUnavailable when none came (source down or ended), kCancelled when the
  // engine is stopping.
  Result<StereoFrame> WaitForCapture(std::chrono::steady_clock::duration timeout);
  // The latest processed frame, or nullptr before the first.
  std::shared_ptr<const pipeline::FrameResult> Latest() const;
  EngineStatus Status() const;

 private:
  Engine(std::unique_ptr<drivers::StereoSource> source, pipeline::PipelineConfig config, Sink sink);
  void CaptureLoop();
  // The pipeline on several threads: each WorkerLoop() takes the newest frame from the mailbox
  // and runs it through a FrontEnd of its own (rectify, disparity, extract), so that consecutive
  // frames are worked on at once, one per core; FinishLoop() tracks, georeferences and publishes
  // them in the order they were taken.
  void WorkerLoop(size_t index);
  void FinishLoop();
  void CountFailure(const Error& error);
  // Waits until `deadline` or Stop(); false when stopping.
  bool WaitUntil(std::chrono::steady_clock::time_point deadline);
  void SetSourceState(SourceState state, std::string error);

  std::unique_ptr<drivers::StereoSource> source_;
  const std::string source_description_;
  const cv::Size source_image_size_;
  pipeline::ConfigStore config_;
  Sink sink_;
  LatestMailbox<StereoFrame> mailbox_;
  pipeline::Pipeline pipeline_;                              // Finish() only: the tracker
  std::vector<std::unique_ptr<pipeline::FrontEnd>> fronts_;  // one per worker
  struct Prepared {
    pipeline::PreparedFrame frame;
    pipeline::Snapshot snapshot;  // the one Prepare() used: Finish() uses it too
  };
  std::mutex take_mu_;      // a frame's sequence number is the order it was taken in
  uint64_t next_take_ = 0;  // (take_mu_)
  std::mutex order_mu_;     // guards the three below
  std::condition_variable order_cv_;
  std::map<uint64_t, std::optional<Prepared>> ready_;  // by sequence; nullopt: the frame failed
  uint64_t next_finish_ = 0;
  size_t workers_running_ = 0;
  const std::chrono::steady_clock::time_point started_;

  mutable std::mutex mu_;  // guards everything below
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  bool started_threads_ = false;
  size_t workers_ = 0;
  SourceState source_state_ = SourceState::kStarting;
  std::string source_error_;
  uint64_t frames_captured_ = 0;
  uint64_t frames_processed_ = 0;
  uint64_t frames_failed_ = 0;
  std::deque<std::chrono::steady_clock::time_point> capture_times_, process_times_;
  std::deque<std::vector<pipeline::StageTiming>> recent_timings_;
  std::shared_ptr<const pipeline::FrameResult> latest_;
  std::shared_ptr<const geometry::StereoRig> rig_;
  bool swap_left_right_ = false;
  std::function<geo::PoseLookup(int64_t, int64_t)> pose_at_;
  std::shared_ptr<const CaptureTap> capture_tap_;
  std::condition_variable capture_cv_;
  StereoFrame last_capture_;  // shares the images with the frame in the mailbox (never written)

  std::thread capture_thread_;
  std::vector<std::thread> worker_threads_;
  std::thread finish_thread_;
};

std::string_view SourceStateName(SourceState state);

}  // namespace stevi::server
