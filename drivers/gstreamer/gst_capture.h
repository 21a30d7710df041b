// One GStreamer pipeline ending in the driver's appsink, pulled by a thread of its own.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace stevi::drivers {

// Initialises GStreamer once per process (std::call_once); safe from any thread. Every entry of
// the driver calls it; tests that use GStreamer directly call it first too.
void InitGStreamer();

// One frame of a pipeline.
struct CapturedFrame {
  cv::Mat image;  // CV_8UC1, continuous: a copy of the buffer's rows (its stride honoured)
  // Live: the capture time (the pipeline clock's base time + the buffer's running time) on
  // CLOCK_MONOTONIC (std::chrono::steady_clock), ns. Files: the buffer's PTS, ns, plus the length
  // of the laps already played when looping.
  int64_t t_ns = 0;
  // Live: the same instant on the Unix clock (CLOCK_REALTIME), ns. Files: 0 (unknown).
  int64_t unix_time_ns = 0;
  // Frames delivered by this capture before this one, over every rebuild and lap.
  int64_t index = 0;
};

enum class CaptureState {
  kStarting,  // built, waiting for its first frame
  kRunning,   // frames arrive
  kLost,      // live only: failed after running; being rebuilt (see reconnect_attempts)
  kEnded,     // files only: end of stream, not looping
  kFailed,    // stopped for good: see `failure`
};

// "starting", "running", "lost", "ended", "failed".
const char* CaptureStateName(CaptureState state);

struct CaptureStatus {
  CaptureState state = CaptureState::kStarting;
  Error failure;                // kFailed: why
  std::string lost_reason;      // kLost: what happened ("Could not read from resource")
  std::string reconnect_error;  // kLost: why the last rebuild failed ("" = none yet)
  int reconnect_attempts = 0;   // kLost: rebuilds since the loss (the current one included)
  std::chrono::steady_clock::time_point lost_since;  // kLost: when
  uint64_t losses = 0;                               // times the pipeline was lost since the start
  uint64_t reconnects = 0;                           // rebuilds that delivered frames again
  uint64_t frames = 0;                               // frames delivered, over every rebuild
  double stream_fps = 0;     // the framerate of the caps; 0 when unknown or variable
  std::string last_warning;  // the last WARNING on the bus ("" = none), with its element
};

struct CaptureOptions {
  // For messages and the thread's name: "rtsp", "left".
  std::string name;
  // The user's part of the pipeline; the capture appends GstSinkTail(live).
  std::string pipeline;
  // Live (a camera, a stream): the newest frame wins, an ERROR, an end of stream or no frame for
  // `lost_after` is a loss, and the pipeline is torn down and rebuilt with a backoff of 250 ms
  // doubling to 1 s. Not live (a file): every frame in order with back-pressure, an ERROR is
  // fatal, the end of stream ends it (or starts it again when `loop`).
  bool live = true;
  bool loop = false;
  std::chrono::nanoseconds lost_after{std::chrono::seconds(1)};
  // How long Start() waits for the first frame.
  std::chrono::nanoseconds start_timeout{std::chrono::seconds(10)};
  // Frames per second assumed when the caps give none (a looping file's lap length).
  double fps = 30;
  // Checks a frame's size: "" when fine, else the problem, which stops the capture for good
  // (kInvalidArgument). May be empty.
  std::function<std::string(cv::Size)> check_size;
  // Live only: the base time of the pipeline on the system clock (CLOCK_MONOTONIC), ns, instead
  // of the instant it starts playing; -1 = its own. Pipelines given one base time share one
  // running time. That matters to sources whose times start at 0 and follow the clock (a test
  // source paced by clocksync), not to the ones that stamp the capture instant (v4l2src,
  // rtspsrc), nor to live GstBaseSrc sources (a live videotestsrc), which move their first
  // buffer to the running time at which they start. A rebuilt pipeline takes its own.
  int64_t base_time_ns = -1;
};

// Thread-safe: status() from any thread; the callbacks run on the capture's thread.
//
// The thread pulls samples (100 ms at a time) and copies their luma, watches the bus (ERROR, EOS,
// WARNING) and, when live, a no-frame watchdog. On a loss it sets the pipeline to NULL, unrefs it
// and parses it again (a parsed pipeline with sometimes-pads is not reliably reusable), after 250
// ms, then 500 ms, then every second, until frames come again.
class GstCapture {
 public:
  // Gets each frame; may block (a file's back-pressure) until it returns, and must return soon
  // once its owner is stopping.
  using FrameSink = std::function<void(CapturedFrame)>;
  // Told of every change of status(), with the new status; runs on the capture's thread, in the
  // order of the changes.
  using Notify = std::function<void(const CaptureStatus&)>;

  // Parses the pipeline (with GST_PARSE_FLAG_FATAL_ERRORS), sets it PLAYING and waits for the
  // first frame (pulled and checked; it goes on to `on_frame`). Errors, each naming the capture:
  // kInvalidArgument for a bad description or a missing element (named, with the Debian package
  // for the usual ones), a size check's problem or a stream that does not negotiate one of
  // kGstLumaFormats; kNotFound for a missing device or file; kUnavailable for a device that cannot
  // be opened or no frame within start_timeout.
  static Result<std::unique_ptr<GstCapture>> Start(CaptureOptions options, FrameSink on_frame,
                                                   Notify on_change);
  // Stops the thread (within about 100 ms, once `on_frame` has returned) and tears the pipeline
  // down.
  ~GstCapture();
  GstCapture(const GstCapture&) = delete;
  GstCapture& operator=(const GstCapture&) = delete;

  CaptureStatus status() const;
  const CaptureOptions& options() const;
  // The whole description as parsed: the user's part and the driver's tail.
  const std::string& description() const;

 private:
  struct Impl;
  explicit GstCapture(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::drivers
