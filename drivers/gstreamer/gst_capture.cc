#include "drivers/gstreamer/gst_capture.h"

#include <time.h>

#include <algorithm>
#include <condition_variable>
#include <cstdio>
#include <limits>
#include <mutex>
#include <thread>
#include <utility>

#include <gst/app/gstappsink.h>
#include <gst/gst.h>
#include <gst/video/video.h>

#include "core/common/thread_name.h"
#include "drivers/gstreamer/gst_errors.h"
#include "drivers/gstreamer/gst_ptr.h"
#include "drivers/gstreamer/pipelines.h"

namespace stevi::drivers {
namespace {

using Clock = std::chrono::steady_clock;

constexpr auto kReconnectFirst = std::chrono::milliseconds(250);
constexpr auto kReconnectMax = std::chrono::milliseconds(1000);

// out[i] = in[2 * i] for i < n, in blocks of 16 that GCC unrolls, then the remainder. Scalar code
// (GCC 12 at -O2 does not vectorise it; the object has no packing instructions): in a profile of
// raw YUY2 video flat out it took about 5 % of the samples; with cv::extractChannel instead,
// libopencv_core as a whole took 7.5 %.
void TakeEveryOtherByte(const uint8_t* in, uint8_t* out, int n) {
  int x = 0;
  for (; x + 16 <= n; x += 16) {
    for (int i = 0; i < 16; ++i) out[x + i] = in[2 * (x + i)];
  }
  for (; x < n; ++x) out[x] = in[2 * x];
}

// Where a format of kGstLumaFormats keeps its luma: kLumaPlane for a plane of its own (plane 0),
// else the byte of each two-byte pixel of a packed 4:2:2 format; -1 for a format without one.
constexpr int kLumaPlane = 2;
int LumaChannel(GstVideoFormat format) {
  switch (format) {
    case GST_VIDEO_FORMAT_GRAY8:
    case GST_VIDEO_FORMAT_I420:
    case GST_VIDEO_FORMAT_YV12:
    case GST_VIDEO_FORMAT_NV12:
    case GST_VIDEO_FORMAT_NV21:
    case GST_VIDEO_FORMAT_Y42B:
    case GST_VIDEO_FORMAT_Y444: return kLumaPlane;
    case GST_VIDEO_FORMAT_YUY2:
    case GST_VIDEO_FORMAT_YVYU: return 0;
    case GST_VIDEO_FORMAT_UYVY: return 1;
    default: return -1;
  }
}
// Longest wait for a sample, so that the thread sees the bus and a stop request promptly.
constexpr GstClockTime kPullSliceNs = 100 * GST_MSECOND;

std::string Seconds(Clock::duration d) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f s", std::chrono::duration<double>(d).count());
  return buf;
}

int64_t NowNs(clockid_t id) {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// What to add to a reading of `from` to get the same instant on `to`, ns: the reading of `from`
// bracketed by two of `to`, the tightest of three tries.
template <class From, class To>
int64_t ClockOffset(From from, To to) {
  int64_t best_gap = std::numeric_limits<int64_t>::max();
  int64_t offset = 0;
  for (int i = 0; i < 3; ++i) {
    const int64_t before = to();
    const int64_t reading = from();
    const int64_t after = to();
    if (after - before < best_gap) {
      best_gap = after - before;
      offset = before + (after - before) / 2 - reading;
    }
  }
  return offset;
}

}  // namespace

void InitGStreamer() {
  static std::once_flag once;
  std::call_once(once, [] { gst_init(nullptr, nullptr); });
}

const char* CaptureStateName(CaptureState state) {
  switch (state) {
    case CaptureState::kStarting: return "starting";
    case CaptureState::kRunning: return "running";
    case CaptureState::kLost: return "lost";
    case CaptureState::kEnded: return "ended";
    case CaptureState::kFailed: return "failed";
  }
  return "?";
}

struct GstCapture::Impl {
  CaptureOptions options;
  FrameSink on_frame;
  Notify on_change;
  std::string description;

  // The thread's (and Start()'s, before the thread runs).
  gst::ElementPtr pipeline;
  gst::ElementPtr sink;
  gst::BusPtr bus;
  gst::ClockPtr clock;              // the pipeline's, taken at its first live frame
  bool clock_is_monotonic = false;  // the system clock on CLOCK_MONOTONIC: no offset to measure
  bool first_build = true;
  Clock::time_point progress;  // the last frame, or the last build
  Clock::duration backoff = kReconnectFirst;
  Clock::time_point next_attempt;
  int64_t lap_offset_ns = 0;  // files: the length of the laps played
  int64_t last_t_ns = -1;     // files: t_ns of the newest frame
  int64_t lap_frames = 0;     // files: frames of the current lap
  int64_t next_index = 0;

  mutable std::mutex mu;
  std::condition_variable cv;                              // status changes and stop
  bool stop = false;                                       // (mu)
  CaptureStatus status;                                    // (mu)
  CaptureState published_state = CaptureState::kStarting;  // (mu) as on_change last heard it
  bool published_running = false;  // (mu) on_change heard of a frame: the start succeeded
  std::thread thread;

  ~Impl() { TearDown(); }

  // Changes the status, tells on_change, then wakes Start(): when Start() returns, the owner
  // knows the status it returns with.
  template <class F>
  void Update(F&& change) {
    CaptureStatus now;
    {
      std::lock_guard lock(mu);
      change(status);
      now = status;
    }
    if (on_change) on_change(now);
    {
      std::lock_guard lock(mu);
      published_state = now.state;
      if (now.state == CaptureState::kRunning) published_running = true;
    }
    cv.notify_all();
  }
  CaptureState state() const {
    std::lock_guard lock(mu);
    return status.state;
  }
  bool Stopping() const {
    std::lock_guard lock(mu);
    return stop;
  }
  int64_t PeriodNs(double stream_fps) const {
    const double fps = stream_fps > 0 ? stream_fps : options.fps;
    return static_cast<int64_t>(1e9 / fps);
  }

  Status Build();
  void TearDown();
  void Run();
  void Reconnect();
  void Step();
  bool PollBus();
  void OnError(GstMessage* message);
  void OnEndOfStream();
  void Deliver(GstSample* sample);
  Result<CapturedFrame> Convert(GstSample* sample, double* stream_fps);
  void Stamp(CapturedFrame& frame, GstSample* sample, double stream_fps);
  void Fail(Error error);
  void Lose(const std::string& reason);
  void AttemptFailed(const std::string& why);
};

Status GstCapture::Impl::Build() {
  const gst::ParseContextPtr context(gst_parse_context_new());
  GError* raw_error = nullptr;
  gst::ElementPtr parsed = gst::AdoptFloating(gst_parse_launch_full(
      description.c_str(), context.get(), GST_PARSE_FLAG_FATAL_ERRORS, &raw_error));
  const gst::ErrorPtr error(raw_error);
  if (error) return gst::ParseFailure(*error, context.get());
  if (!parsed || !GST_IS_PIPELINE(parsed.get())) {
    return InvalidArgument("the description gave no pipeline");
  }
  gst::ElementPtr appsink(
      gst_bin_get_by_name(GST_BIN(parsed.get()), std::string(kGstSinkName).c_str()));
  if (!appsink || !GST_IS_APP_SINK(appsink.get())) {
    return Internal("the pipeline has no appsink " + std::string(kGstSinkName));
  }
  gst::BusPtr new_bus(gst_element_get_bus(parsed.get()));
  if (options.live && options.base_time_ns >= 0 && first_build) {
    // One running time for pipelines started together: the base time is ours, not the instant
    // each reaches PLAYING.
    gst::ClockPtr system(gst_system_clock_obtain());
    gst_pipeline_use_clock(GST_PIPELINE(parsed.get()), system.get());
    gst_element_set_start_time(parsed.get(), GST_CLOCK_TIME_NONE);
    gst_element_set_base_time(parsed.get(), static_cast<GstClockTime>(options.base_time_ns));
  }
  first_build = false;
  if (gst_element_set_state(parsed.get(), GST_STATE_PLAYING) == GST_STATE_CHANGE_FAILURE) {
    const gst::MessagePtr message(gst_bus_pop_filtered(new_bus.get(), GST_MESSAGE_ERROR));
    gst_element_set_state(parsed.get(), GST_STATE_NULL);
    if (message) return gst::BusFailure(message.get());
    return Unavailable("the pipeline did not start");
  }
  pipeline = std::move(parsed);
  sink = std::move(appsink);
  bus = std::move(new_bus);
  progress = Clock::now();
  return Status::Ok();
}

void GstCapture::Impl::TearDown() {
  if (!pipeline) return;
  gst_element_set_state(pipeline.get(), GST_STATE_NULL);
  clock.reset();
  bus.reset();
  sink.reset();
  pipeline.reset();
}

void GstCapture::Impl::Run() {
  NameThisThread("stevi-gst-" + options.name);
  while (!Stopping()) {
    if (pipeline) {
      Step();
    } else {
      Reconnect();
    }
  }
  TearDown();
}

// Without a pipeline: idles when ended or failed, else (live, lost) rebuilds it after the backoff.
void GstCapture::Impl::Reconnect() {
  {
    std::unique_lock lock(mu);
    if (status.state == CaptureState::kEnded || status.state == CaptureState::kFailed) {
      cv.wait(lock, [&] { return stop; });
      return;
    }
    if (cv.wait_until(lock, next_attempt, [&] { return stop; })) return;
  }
  Update([](CaptureStatus& s) { ++s.reconnect_attempts; });
  if (Status built = Build(); !built.ok()) AttemptFailed(built.error().message);
}

void GstCapture::Impl::Step() {
  const gst::SamplePtr sample(gst_app_sink_try_pull_sample(GST_APP_SINK(sink.get()), kPullSliceNs));
  if (sample) {
    Deliver(sample.get());
    if (!pipeline) return;
  }
  if (!PollBus()) return;
  if (!sample && gst_app_sink_is_eos(GST_APP_SINK(sink.get()))) {
    OnEndOfStream();
    return;
  }
  const CaptureState now_state = state();
  if (!options.live || now_state == CaptureState::kStarting) return;  // Start() times out
  const Clock::duration idle = Clock::now() - progress;
  if (idle <= options.lost_after) return;
  if (now_state == CaptureState::kRunning) {
    Lose("no frame for " + Seconds(idle));
  } else {
    AttemptFailed("no frame within " + Seconds(idle) + " of restarting");
  }
}

// Handles the bus's ERROR and WARNING messages; false when an error tore the pipeline down.
bool GstCapture::Impl::PollBus() {
  while (true) {
    const gst::MessagePtr message(gst_bus_pop_filtered(
        bus.get(), static_cast<GstMessageType>(GST_MESSAGE_ERROR | GST_MESSAGE_WARNING)));
    if (!message) return true;
    if (GST_MESSAGE_TYPE(message.get()) == GST_MESSAGE_WARNING) {
      std::string text = gst::WarningText(message.get());
      Update([&](CaptureStatus& s) { s.last_warning = std::move(text); });
      continue;
    }
    OnError(message.get());
    return false;
  }
}

void GstCapture::Impl::OnError(GstMessage* message) {
  const CaptureState now_state = state();
  if (!options.live || now_state == CaptureState::kStarting) {
    Fail(gst::BusFailure(message));
  } else if (now_state == CaptureState::kRunning) {
    Lose(gst::ShortReason(message));
  } else {
    AttemptFailed(gst::BusFailure(message).message);
  }
}

void GstCapture::Impl::OnEndOfStream() {
  const CaptureState now_state = state();
  if (now_state == CaptureState::kStarting) {
    Fail(Error{options.live ? ErrorCode::kUnavailable : ErrorCode::kInvalidArgument,
               "the stream ended before its first frame"});
  } else if (options.live) {
    if (now_state == CaptureState::kRunning) {
      Lose("end of stream");
    } else {
      AttemptFailed("end of stream before a frame");
    }
  } else if (options.loop && lap_frames > 0) {
    // Next lap: its times follow the last frame of this one by a frame period.
    double stream_fps = 0;
    {
      std::lock_guard lock(mu);
      stream_fps = status.stream_fps;
    }
    lap_offset_ns = last_t_ns + PeriodNs(stream_fps);
    lap_frames = 0;
    TearDown();
    if (Status built = Build(); !built.ok()) Fail(built.error());
  } else {
    TearDown();
    Update([](CaptureStatus& s) { s.state = CaptureState::kEnded; });
  }
}

void GstCapture::Impl::Deliver(GstSample* sample) {
  double stream_fps = 0;
  Result<CapturedFrame> frame = Convert(sample, &stream_fps);
  if (!frame.ok()) {
    Fail(frame.error());
    return;
  }
  Stamp(frame.value(), sample, stream_fps);
  frame->index = next_index++;
  ++lap_frames;
  progress = Clock::now();
  // The status first: whoever gets the frame sees the recovery it proves.
  Update([&](CaptureStatus& s) {
    ++s.frames;
    s.stream_fps = stream_fps;
    if (s.state == CaptureState::kLost) {
      ++s.reconnects;
      s.reconnect_attempts = 0;
      s.reconnect_error.clear();
    }
    s.state = CaptureState::kRunning;
  });
  backoff = kReconnectFirst;
  on_frame(std::move(frame.value()));
}

Result<CapturedFrame> GstCapture::Impl::Convert(GstSample* sample, double* stream_fps) {
  GstCaps* caps = gst_sample_get_caps(sample);
  GstBuffer* buffer = gst_sample_get_buffer(sample);
  GstVideoInfo info;
  if (caps == nullptr || buffer == nullptr || !gst_video_info_from_caps(&info, caps)) {
    return Internal("a sample without video caps");
  }
  const int luma_channel = LumaChannel(GST_VIDEO_INFO_FORMAT(&info));
  if (luma_channel < 0) {
    return Internal(std::string("a sample in a format without a luma plane: ") +
                    gst_video_format_to_string(GST_VIDEO_INFO_FORMAT(&info)));
  }
  const cv::Size size(GST_VIDEO_INFO_WIDTH(&info), GST_VIDEO_INFO_HEIGHT(&info));
  if (options.check_size) {
    if (std::string problem = options.check_size(size); !problem.empty()) {
      return InvalidArgument(problem);
    }
  }
  GstVideoFrame mapped;
  if (!gst_video_frame_map(&mapped, &info, buffer, GST_MAP_READ)) {
    return Internal("cannot map a buffer");
  }
  CapturedFrame frame;
  // Plane 0 holds the luma; its stride is the video meta's when there is one, else the caps'
  // (rows are padded to 4).
  void* data = GST_VIDEO_FRAME_PLANE_DATA(&mapped, 0);
  const auto stride = static_cast<size_t>(GST_VIDEO_FRAME_PLANE_STRIDE(&mapped, 0));
  if (luma_channel == kLumaPlane) {
    cv::Mat(size, CV_8UC1, data, stride).copyTo(frame.image);
  } else {
    // Packed 4:2:2: two bytes a pixel, the luma one of them.
    frame.image.create(size, CV_8UC1);
    for (int y = 0; y < size.height; ++y) {
      TakeEveryOtherByte(static_cast<const uint8_t*>(data) + y * stride + luma_channel,
                         frame.image.ptr<uint8_t>(y), size.width);
    }
  }
  gst_video_frame_unmap(&mapped);
  *stream_fps = GST_VIDEO_INFO_FPS_N(&info) > 0 && GST_VIDEO_INFO_FPS_D(&info) > 0
                    ? static_cast<double>(GST_VIDEO_INFO_FPS_N(&info)) /
                          static_cast<double>(GST_VIDEO_INFO_FPS_D(&info))
                    : 0.0;
  return frame;
}

void GstCapture::Impl::Stamp(CapturedFrame& frame, GstSample* sample, double stream_fps) {
  const GstClockTime pts = GST_BUFFER_PTS(gst_sample_get_buffer(sample));
  if (!options.live) {
    frame.t_ns = GST_CLOCK_TIME_IS_VALID(pts)
                     ? lap_offset_ns + static_cast<int64_t>(pts)
                     : (last_t_ns < 0 ? lap_offset_ns : last_t_ns + PeriodNs(stream_fps));
    last_t_ns = frame.t_ns;
    return;
  }
  const auto mono = [] { return NowNs(CLOCK_MONOTONIC); };
  const auto real = [] { return NowNs(CLOCK_REALTIME); };
  const GstSegment* segment = gst_sample_get_segment(sample);
  const GstClockTime running = segment != nullptr && GST_CLOCK_TIME_IS_VALID(pts)
                                   ? gst_segment_to_running_time(segment, GST_FORMAT_TIME, pts)
                                   : GST_CLOCK_TIME_NONE;
  if (!clock) {
    clock.reset(gst_element_get_clock(pipeline.get()));
    GstClockType type = GST_CLOCK_TYPE_REALTIME;
    if (clock && GST_IS_SYSTEM_CLOCK(clock.get()))
      g_object_get(clock.get(), "clock-type", &type, nullptr);
    clock_is_monotonic =
        clock && GST_IS_SYSTEM_CLOCK(clock.get()) && type == GST_CLOCK_TYPE_MONOTONIC;
  }
  if (!clock || !GST_CLOCK_TIME_IS_VALID(running)) {
    // No capture time in the stream: the arrival.
    frame.t_ns = mono();
  } else {
    const int64_t clock_time =
        static_cast<int64_t>(gst_element_get_base_time(pipeline.get()) + running);
    GstClock* c = clock.get();
    frame.t_ns =
        clock_is_monotonic
            ? clock_time
            : clock_time +
                  ClockOffset([c] { return static_cast<int64_t>(gst_clock_get_time(c)); }, mono);
  }
  frame.unix_time_ns = frame.t_ns + ClockOffset(mono, real);
}

void GstCapture::Impl::Fail(Error error) {
  TearDown();
  Update([&](CaptureStatus& s) {
    s.state = CaptureState::kFailed;
    s.failure = error.Prefixed(options.name + ": ");
  });
}

void GstCapture::Impl::Lose(const std::string& reason) {
  TearDown();
  backoff = kReconnectFirst;
  next_attempt = Clock::now() + backoff;
  Update([&](CaptureStatus& s) {
    s.state = CaptureState::kLost;
    s.lost_reason = reason;
    s.reconnect_error.clear();
    s.reconnect_attempts = 0;
    s.lost_since = Clock::now();
    ++s.losses;
  });
}

void GstCapture::Impl::AttemptFailed(const std::string& why) {
  TearDown();
  backoff = std::min<Clock::duration>(backoff * 2, kReconnectMax);
  next_attempt = Clock::now() + backoff;
  Update([&](CaptureStatus& s) { s.reconnect_error = why; });
}

GstCapture::GstCapture(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GstCapture::~GstCapture() {
  {
    std::lock_guard lock(impl_->mu);
    impl_->stop = true;
  }
  impl_->cv.notify_all();
  if (impl_->thread.joinable()) impl_->thread.join();
}

Result<std::unique_ptr<GstCapture>> GstCapture::Start(CaptureOptions options, FrameSink on_frame,
                                                      Notify on_change) {
  InitGStreamer();
  if (MentionsGstSinkName(options.pipeline)) {
    return InvalidArgument(options.name + ": the pipeline must not name an element " +
                           std::string(kGstSinkName) + " (the driver appends its own appsink)");
  }
  auto impl = std::make_unique<Impl>();
  impl->description = options.pipeline + GstSinkTail(options.live);
  impl->options = std::move(options);
  impl->on_frame = std::move(on_frame);
  impl->on_change = std::move(on_change);
  if (Status built = impl->Build(); !built.ok()) {
    return built.error().Prefixed(impl->options.name + ": ");
  }

  std::unique_ptr<GstCapture> capture(new GstCapture(std::move(impl)));
  Impl& m = *capture->impl_;
  m.thread = std::thread([&m] { m.Run(); });
  std::unique_lock lock(m.mu);
  m.cv.wait_for(lock, m.options.start_timeout,
                [&] { return m.published_running || m.published_state == CaptureState::kFailed; });
  // A failure after the first frame (a later frame's size, say) is for Next() to report.
  if (m.published_running) {
    lock.unlock();
    return capture;
  }
  if (m.published_state == CaptureState::kFailed) return m.status.failure;
  std::string message =
      m.options.name + ": no frame within " +
      Seconds(std::chrono::duration_cast<Clock::duration>(m.options.start_timeout)) +
      " of starting";
  if (!m.status.last_warning.empty()) message += " (last warning: " + m.status.last_warning + ")";
  lock.unlock();
  return Unavailable(message);
}

CaptureStatus GstCapture::status() const {
  std::lock_guard lock(impl_->mu);
  return impl_->status;
}

const CaptureOptions& GstCapture::options() const { return impl_->options; }

const std::string& GstCapture::description() const { return impl_->description; }

}  // namespace stevi::drivers
