#include "drivers/gstreamer/gst_source.h"

#include <array>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <mutex>
#include <utility>

#include <gst/gst.h>

#include "core/common/format.h"
#include "drivers/aravis/stereo_pairer.h"
#include "drivers/gstreamer/gst_capture.h"
#include "drivers/gstreamer/gst_ptr.h"
#include "drivers/gstreamer/pipelines.h"
#include "drivers/live_source.h"

namespace stevi::drivers {
namespace {

using Clock = std::chrono::steady_clock;

// Files: pairs decoded ahead of Next().
constexpr size_t kFileQueue = 4;
// two: frames a side keeps waiting for its partner.
constexpr int kMaxPending = 4;
// Pipelines in Describe() are cut after this many characters.
constexpr size_t kDescribeChars = 60;

std::string Cut(const std::string& text) {
  return text.size() <= kDescribeChars ? text : text.substr(0, kDescribeChars) + "...";
}

// A short name for the capture of a one-pipeline source: its first element without "src"
// ("rtspsrc location=..." is "rtsp"), or "gst".
std::string CaptureName(const std::string& pipeline) {
  const size_t start = pipeline.find_first_not_of(" \t");
  if (start == std::string::npos) return "gst";
  const size_t end = pipeline.find_first_of(" \t!", start);
  std::string first = pipeline.substr(start, end == std::string::npos ? end : end - start);
  if (first.empty() || first.find_first_of("=(/.,") != std::string::npos) return "gst";
  if (first.size() > 3 && first.ends_with("src")) first.resize(first.size() - 3);
  return first;
}

// Where the expected view size comes from, for messages.
enum class SizeOrigin { kOptions, kRig, kFirstFrames };

std::string ExpectedSize(SizeOrigin origin, cv::Size view) {
  switch (origin) {
    case SizeOrigin::kOptions: return "width/height say " + SizeText(view) + " per view";
    case SizeOrigin::kRig: return "the calibration's image size is " + SizeText(view);
    case SizeOrigin::kFirstFrames: break;
  }
  return "the first frames had " + SizeText(view) + " views";
}

}  // namespace

const char* GstLayoutName(GstLayout layout) {
  switch (layout) {
    case GstLayout::kSideBySide: return "side-by-side";
    case GstLayout::kTopBottom: return "top-bottom";
    case GstLayout::kTwo: return "two";
  }
  return "?";
}

std::optional<GstLayout> ParseGstLayout(std::string_view text) {
  if (text == "side-by-side") return GstLayout::kSideBySide;
  if (text == "top-bottom") return GstLayout::kTopBottom;
  for (const auto& n : GstOptions::kLayoutNames) {
    if (n.name == text) return n.value;
  }
  return std::nullopt;
}

int64_t GstOptions::FramePeriodNs() const {
  return fps > 0 ? static_cast<int64_t>(std::llround(1e9 / fps)) : 0;
}

int64_t GstOptions::PairToleranceNs() const {
  return pair_tolerance_ms > 0 ? static_cast<int64_t>(std::llround(pair_tolerance_ms * 1e6))
                               : FramePeriodNs() / 2;
}

std::chrono::nanoseconds GstOptions::LostAfter() const {
  return std::max<std::chrono::nanoseconds>(timeout, 5 * std::chrono::nanoseconds(FramePeriodNs()));
}

std::vector<std::string> GstOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  const auto check_pipeline = [&](const std::string& text, const char* field) {
    if (text.find_first_not_of(" \t\n") == std::string::npos) {
      problems.push_back(std::string(field) + ": must be a gst-launch pipeline for layout " +
                         GstLayoutName(layout));
    } else if (MentionsGstSinkName(text)) {
      problems.push_back(std::string(field) + ": must not name an element " +
                         std::string(kGstSinkName) + " (the driver appends its own appsink)");
    }
  };
  const auto check_unused = [&](const std::string& text, const char* field) {
    if (!text.empty()) {
      problems.push_back(std::string(field) + ": unused with layout " + GstLayoutName(layout) +
                         " (got '" + Cut(text) + "')");
    }
  };
  if (layout == GstLayout::kTwo) {
    check_pipeline(left_pipeline, "left_pipeline");
    check_pipeline(right_pipeline, "right_pipeline");
    check_unused(pipeline, "pipeline");
  } else {
    check_pipeline(pipeline, "pipeline");
    check_unused(left_pipeline, "left_pipeline");
    check_unused(right_pipeline, "right_pipeline");
  }
  if ((width == 0) != (height == 0)) {
    problems.push_back("width, height: give both or neither (got " + std::to_string(width) + "x" +
                       std::to_string(height) + ")");
  }
  const bool rate_ok = std::isfinite(fps) && fps > 0 && fps <= 1000;
  if (layout == GstLayout::kTwo && rate_ok && pair_tolerance_ms > 0 &&
      pair_tolerance_ms * 1e6 > static_cast<double>(FramePeriodNs()) / 2) {
    problems.push_back("pair_tolerance_ms: must be at most half the frame period (" +
                       MillisText(FramePeriodNs() / 2) +
                       " at fps), else a frame could pair with its partner's neighbour" +
                       Got(pair_tolerance_ms));
  }
  if (loop && live) problems.push_back("loop: only for files (live = false)");
  if (timeout.count() <= 0) {
    problems.push_back("timeout: must be > 0 ms (got " + std::to_string(timeout.count()) + ")");
  }
  if (start_timeout.count() <= 0) {
    problems.push_back("start_timeout: must be > 0 ms (got " +
                       std::to_string(start_timeout.count()) + ")");
  }
  return problems;
}

struct GstStereoSource::Impl {
  GstOptions options;
  std::shared_ptr<const geometry::StereoRig> rig;
  bool rectified = false;
  int count = 1;                     // pipelines: 1, or 2 for kTwo
  std::array<std::string, 2> names;  // of the captures
  std::vector<std::unique_ptr<GstCapture>> captures;

  mutable std::mutex mu;
  std::condition_variable cv;         // a pair, a status change, room in the queue, stop
  bool stop = false;                  // (mu)
  bool interrupted = false;           // (mu)
  std::optional<cv::Size> view_size;  // (mu) of one view: the options', the rig's or the first
  SizeOrigin view_size_origin = SizeOrigin::kFirstFrames;  // (mu)
  std::array<CaptureStatus, 2> statuses;                   // (mu) the captures' latest
  std::array<uint64_t, 2> reported_losses{};               // (mu) losses Next() has told of
  std::array<uint64_t, 2> frames{};                        // (mu) frames per side (two)
  std::array<int64_t, 2> last_t_ns{};  // (mu) newest capture time per side (two)
  std::optional<StereoFrame> latest;   // (mu) live: the newest pair not yet taken
  std::deque<StereoFrame> queue;       // (mu) files: pairs in order
  StereoPairer pairer;                 // (mu) two
  uint64_t pairs = 0;                  // (mu) one pipeline: pairs made

  ~Impl() {
    {
      std::lock_guard lock(mu);
      stop = true;
    }
    cv.notify_all();
    captures.clear();  // joins their threads, which no longer wait for room
  }

  std::string CheckFrameSize(cv::Size frame);
  StereoFrame Split(CapturedFrame frame) const;
  void OnSingle(CapturedFrame frame);
  void OnSide(Side side, CapturedFrame frame);
  void Push(StereoFrame pair);  // (mu held)
  bool SideDone(Side side) const;
  bool Ended() const;
  std::optional<Error> Trouble(bool fresh_only);
  std::string LostMessage(int i) const;
  std::string NoPairMessage(const std::array<uint64_t, 2>& frames_before) const;
  Status StartCaptures();
};

// The problem with a frame of `frame` size, or "": an odd size that does not split, or views of
// another size than the expected (or, when none is, the first frames').
std::string GstStereoSource::Impl::CheckFrameSize(cv::Size frame) {
  cv::Size view = frame;
  if (options.layout == GstLayout::kSideBySide) {
    if (frame.width % 2 != 0) {
      return "frame width " + std::to_string(frame.width) + " (of " + SizeText(frame) +
             ") is odd: a side-by-side frame must split into two halves of one width";
    }
    view.width /= 2;
  } else if (options.layout == GstLayout::kTopBottom) {
    if (frame.height % 2 != 0) {
      return "frame height " + std::to_string(frame.height) + " (of " + SizeText(frame) +
             ") is odd: a top-bottom frame must split into two halves of one height";
    }
    view.height /= 2;
  }
  std::lock_guard lock(mu);
  if (!view_size) {
    view_size = view;
    view_size_origin = SizeOrigin::kFirstFrames;
    return "";
  }
  if (view != *view_size) {
    std::string text = "frame is " + SizeText(frame);
    if (options.layout != GstLayout::kTwo) text += " (" + SizeText(view) + " views)";
    return text + " but " + ExpectedSize(view_size_origin, *view_size);
  }
  return "";
}

StereoFrame GstStereoSource::Impl::Split(CapturedFrame frame) const {
  StereoFrame pair;
  const cv::Mat& image = frame.image;
  if (options.layout == GstLayout::kSideBySide) {
    const int half = image.cols / 2;
    pair.left = image.colRange(0, half).clone();
    pair.right = image.colRange(half, image.cols).clone();
  } else {
    // Row ranges of a continuous image are continuous: no copy.
    const int half = image.rows / 2;
    pair.left = image.rowRange(0, half);
    pair.right = image.rowRange(half, image.rows);
  }
  pair.t_ns = frame.t_ns;
  pair.unix_time_ns = frame.unix_time_ns;
  pair.index = frame.index;
  pair.rectified = rectified;
  return pair;
}

void GstStereoSource::Impl::OnSingle(CapturedFrame frame) {
  StereoFrame pair = Split(std::move(frame));
  std::unique_lock lock(mu);
  if (!options.live) {
    cv.wait(lock, [&] { return stop || queue.size() < kFileQueue; });
    if (stop) return;
  }
  ++pairs;
  Push(std::move(pair));
}

void GstStereoSource::Impl::OnSide(Side side, CapturedFrame frame) {
  std::unique_lock lock(mu);
  const Side other = side == Side::kLeft ? Side::kRight : Side::kLeft;
  if (!options.live) {
    // Room for the pair this frame may complete, before it is made: a pair is never held back
    // out of the queue, where Next() could not see it. And a side that runs ahead waits for the
    // other rather than drop frames that would pair.
    cv.wait(lock, [&] {
      return stop || (queue.size() < kFileQueue &&
                      (pairer.pending(side) < static_cast<size_t>(kMaxPending) || SideDone(other)));
    });
    if (stop) return;
  }
  const int i = side == Side::kLeft ? 0 : 1;
  ++frames[i];
  last_t_ns[i] = frame.t_ns;
  MonoFrame mono{std::move(frame.image), frame.t_ns, frame.unix_time_ns,
                 static_cast<uint64_t>(frame.index)};
  std::optional<StereoFrame> pair = pairer.Add(side, std::move(mono));
  if (pair) {
    pair->rectified = rectified;
    Push(std::move(*pair));
  } else {
    cv.notify_all();  // the other side may wait for this one's progress
  }
}

// Live: the pair replaces the one not yet taken. Files: the caller made room in the queue.
void GstStereoSource::Impl::Push(StereoFrame pair) {
  if (options.live) {
    latest = std::move(pair);
  } else {
    queue.push_back(std::move(pair));
  }
  cv.notify_all();
}

bool GstStereoSource::Impl::SideDone(Side side) const {
  const CaptureState state = statuses[side == Side::kLeft ? 0 : 1].state;
  return state == CaptureState::kEnded || state == CaptureState::kFailed;
}

// Files: no pair can come any more.
bool GstStereoSource::Impl::Ended() const {
  if (count == 1) return statuses[0].state == CaptureState::kEnded;
  const bool left = statuses[0].state == CaptureState::kEnded;
  const bool right = statuses[1].state == CaptureState::kEnded;
  return (left && right) || (left && pairer.pending(Side::kLeft) == 0) ||
         (right && pairer.pending(Side::kRight) == 0);
}

// A failed capture's error; a lost capture's message (only a loss not yet told of when
// `fresh_only`).
std::optional<Error> GstStereoSource::Impl::Trouble(bool fresh_only) {
  for (int i = 0; i < count; ++i) {
    const CaptureStatus& s = statuses[i];
    if (s.state == CaptureState::kFailed) return s.failure;
    if (s.state == CaptureState::kLost && (!fresh_only || s.losses > reported_losses[i])) {
      reported_losses[i] = s.losses;
      return Unavailable(LostMessage(i));
    }
  }
  return std::nullopt;
}

std::string GstStereoSource::Impl::LostMessage(int i) const {
  const CaptureStatus& s = statuses[i];
  std::string message = names[i] + ": lost (" + s.lost_reason + ") " +
                        SecondsText(Clock::now() - s.lost_since) + " ago; reconnecting";
  if (s.reconnect_attempts > 0) message += ", attempt " + std::to_string(s.reconnect_attempts);
  if (!s.reconnect_error.empty()) message += " (last: " + s.reconnect_error + ")";
  return message;
}

std::string GstStereoSource::Impl::NoPairMessage(const std::array<uint64_t, 2>& before) const {
  char waited[32];
  std::snprintf(waited, sizeof waited, "%g s",
                std::chrono::duration<double>(options.timeout).count());
  if (count == 1) {
    return names[0] + ": no frame for " + waited + " (" + CaptureStateName(statuses[0].state) +
           ", " + std::to_string(statuses[0].frames) + " frames so far)";
  }
  const uint64_t left = frames[0] - before[0];
  const uint64_t right = frames[1] - before[1];
  std::string message = std::string("no pair for ") + waited + " (left: " + std::to_string(left) +
                        " frames, right: " + std::to_string(right) + " frames)";
  if (left > 0 && right > 0) {
    message += "; frames do not pair within " + MillisText(options.PairToleranceNs()) +
               " (latest right - left: " + MillisText(last_t_ns[1] - last_t_ns[0]) + ")";
  }
  return message;
}

GstStereoSource::GstStereoSource(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GstStereoSource::~GstStereoSource() = default;

// Starts the pipeline(s), each waiting for its first frame. Two live pipelines share one base
// time, so that sources stamping frames with their running time pair by it.
Status GstStereoSource::Impl::StartCaptures() {
  int64_t base_time_ns = -1;
  if (count == 2 && options.live) {
    InitGStreamer();
    const gst::ClockPtr system(gst_system_clock_obtain());
    base_time_ns = static_cast<int64_t>(gst_clock_get_time(system.get()));
  }
  for (int i = 0; i < count; ++i) {
    CaptureOptions c;
    c.name = names[i];
    c.pipeline = count == 1 ? options.pipeline
                 : i == 0   ? options.left_pipeline
                            : options.right_pipeline;
    c.live = options.live;
    c.loop = options.loop;
    c.lost_after = options.LostAfter();
    c.start_timeout = options.start_timeout;
    c.fps = options.fps;
    c.base_time_ns = base_time_ns;
    c.check_size = [this](cv::Size size) { return CheckFrameSize(size); };
    GstCapture::FrameSink sink;
    if (count == 1) {
      sink = [this](CapturedFrame frame) { OnSingle(std::move(frame)); };
    } else {
      const Side side = i == 0 ? Side::kLeft : Side::kRight;
      sink = [this, side](CapturedFrame frame) { OnSide(side, std::move(frame)); };
    }
    auto notify = [this, i](const CaptureStatus& status) {
      {
        std::lock_guard lock(mu);
        statuses[i] = status;
      }
      cv.notify_all();
    };
    Result<std::unique_ptr<GstCapture>> capture =
        GstCapture::Start(std::move(c), std::move(sink), std::move(notify));
    if (!capture.ok()) return capture.error();
    captures.push_back(std::move(capture.value()));
  }
  return Status::Ok();
}

Result<std::unique_ptr<GstStereoSource>> GstStereoSource::Open(
    GstOptions options, std::shared_ptr<const geometry::StereoRig> rig) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  const cv::Size wanted(options.width, options.height);
  if (rig && options.width > 0 && rig->image_size() != wanted) {
    return InvalidArgument("the calibration's image size " + SizeText(rig->image_size()) +
                           " differs from width/height " + SizeText(wanted));
  }
  auto impl = std::make_unique<Impl>();
  Impl& m = *impl;
  m.options = std::move(options);
  m.rig = std::move(rig);
  m.rectified = m.rig && !m.rig->needs_remap();
  m.count = m.options.layout == GstLayout::kTwo ? 2 : 1;
  if (m.count == 2) {
    m.names = {"left", "right"};
  } else {
    m.names = {CaptureName(m.options.pipeline), ""};
  }
  if (m.options.width > 0) {
    m.view_size = wanted;
    m.view_size_origin = SizeOrigin::kOptions;
  } else if (m.rig) {
    m.view_size = m.rig->image_size();
    m.view_size_origin = SizeOrigin::kRig;
  }
  m.pairer = StereoPairer(PairerOptions{m.options.PairToleranceNs(), kMaxPending});
  if (Status started = m.StartCaptures(); !started.ok()) return started.error();
  return std::unique_ptr<GstStereoSource>(new GstStereoSource(std::move(impl)));
}

std::string GstStereoSource::Describe() const {
  const Impl& m = *impl_;
  const cv::Size size = ImageSize();
  std::string text = std::string("gst ") + GstLayoutName(m.options.layout) + " " + SizeText(size);
  if (m.count == 1) return text + " (" + Cut(m.options.pipeline) + ")";
  return text + " (left: " + Cut(m.options.left_pipeline) +
         "; right: " + Cut(m.options.right_pipeline) + ")";
}

std::shared_ptr<const geometry::StereoRig> GstStereoSource::Rig() const { return impl_->rig; }

cv::Size GstStereoSource::ImageSize() const {
  if (impl_->rig) return impl_->rig->image_size();
  std::lock_guard lock(impl_->mu);
  return impl_->view_size.value_or(cv::Size());
}

void GstStereoSource::Interrupt() { InterruptWait(impl_->mu, impl_->interrupted, impl_->cv); }

Result<StereoFrame> GstStereoSource::Next() {
  Impl& m = *impl_;
  std::unique_lock lock(m.mu);
  const auto deadline = Clock::now() + m.options.timeout;
  const std::array<uint64_t, 2> frames_before = m.frames;
  while (true) {
    if (m.interrupted) return Unavailable("gst: stopped");
    if (m.options.live && m.latest) {
      return *std::exchange(m.latest, std::nullopt);
    }
    if (!m.options.live && !m.queue.empty()) {
      StereoFrame frame = std::move(m.queue.front());
      m.queue.pop_front();
      m.cv.notify_all();  // room for the decoders
      return frame;
    }
    if (std::optional<Error> trouble = m.Trouble(true)) return *trouble;
    if (!m.options.live && m.Ended()) {
      const uint64_t pairs = m.count == 1 ? m.pairs : m.pairer.Counters().pairs;
      return OutOfRange((m.count == 1 ? m.names[0] : "left/right") + ": end of the stream after " +
                        std::to_string(pairs) + " pairs");
    }
    if (m.cv.wait_until(lock, deadline) == std::cv_status::timeout) break;
  }
  if (std::optional<Error> trouble = m.Trouble(false)) return *trouble;
  return Unavailable(m.NoPairMessage(frames_before));
}

double GstStereoSource::NominalFps() const {
  if (impl_->options.live) return 0;
  std::lock_guard lock(impl_->mu);
  const double stream_fps = impl_->statuses[0].stream_fps;
  return stream_fps > 0 ? stream_fps : impl_->options.fps;
}

SourceCounters GstStereoSource::Counters() const {
  const Impl& m = *impl_;
  std::lock_guard lock(m.mu);
  SourceCounters counters;
  if (m.count == 2) {
    counters = m.pairer.Counters();
  } else {
    counters.pairs = m.pairs;
  }
  counters.reconnects = 0;
  for (int i = 0; i < m.count; ++i) counters.reconnects += m.statuses[i].reconnects;
  return counters;
}

std::vector<std::string> GstStereoSource::Notes() const {
  const Impl& m = *impl_;
  std::vector<std::string> notes;
  for (int i = 0; i < m.count; ++i) {
    notes.push_back(m.names[i] + ": pipeline " + m.captures[i]->description());
  }
  std::lock_guard lock(m.mu);
  for (int i = 0; i < m.count; ++i) {
    const CaptureStatus& s = m.statuses[i];
    if (!s.last_warning.empty()) notes.push_back(m.names[i] + ": last warning: " + s.last_warning);
    if (m.options.live && s.stream_fps > 0 &&
        std::abs(s.stream_fps - m.options.fps) > 0.01 * m.options.fps) {
      notes.push_back(m.names[i] + ": the stream's caps say " + FormatNumber(s.stream_fps) +
                      " fps but fps is " + FormatNumber(m.options.fps) +
                      ": loss detection and the pair tolerance assume " +
                      FormatNumber(m.options.fps));
    }
    if (!m.options.live && s.stream_fps <= 0 && s.frames > 0) {
      notes.push_back(m.names[i] + ": the stream gives no frame rate: it plays at fps = " +
                      FormatNumber(m.options.fps));
    }
  }
  return notes;
}

}  // namespace stevi::drivers
