#include "drivers/aravis/aravis_source.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <future>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>

#include "core/common/thread_name.h"
#include "drivers/live_source.h"

namespace stevi::drivers {
namespace {

using Clock = std::chrono::steady_clock;

constexpr auto kReconnectFirst = std::chrono::milliseconds(250);
constexpr auto kReconnectMax = std::chrono::milliseconds(1000);
// Longest single wait of an acquisition thread, so that it notices a stop request promptly.
constexpr auto kPollSlice = std::chrono::milliseconds(100);

}  // namespace

int64_t AravisOptions::FramePeriodNs() const {
  return frame_rate_hz > 0 ? static_cast<int64_t>(std::llround(1e9 / frame_rate_hz)) : 0;
}

int64_t AravisOptions::PairToleranceNs() const {
  return pair_tolerance_ms > 0 ? static_cast<int64_t>(std::llround(pair_tolerance_ms * 1e6))
                               : FramePeriodNs() / 2;
}

std::vector<std::string> AravisOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (left_id.empty()) problems.push_back("left_id: must name a camera (id, serial or address)");
  if (right_id.empty()) {
    problems.push_back("right_id: must name a camera (id, serial or address)");
  }
  if (!left_id.empty() && left_id == right_id) {
    problems.push_back("right_id: must be another camera than the left one (both are '" + left_id +
                       "')");
  }
  if (!pixel_format.empty()) {
    const std::optional<PixelFormat> format = ParsePixelFormat(pixel_format);
    if (!format) {
      problems.push_back("pixel_format: " + pixel_format + " is not supported (supported: " +
                         SupportedPixelFormats() + ", or empty for automatic)");
    } else if (*format != PixelFormat::kMono8 && (roi_width % 2 != 0 || roi_height % 2 != 0)) {
      problems.push_back("width, height: a Bayer mosaic needs an even size (got " +
                         std::to_string(roi_width) + "x" + std::to_string(roi_height) + ")");
    }
  }
  const bool rate_ok = std::isfinite(frame_rate_hz) && frame_rate_hz > 0 && frame_rate_hz <= 1000;
  if (rate_ok && exposure_us >= 0 && trigger.mode != TriggerMode::kHardware &&
      exposure_us * 1e3 > static_cast<double>(FramePeriodNs())) {
    problems.push_back("exposure_us: longer than the frame period " +
                       std::to_string(FramePeriodNs() / 1000) + " us at " +
                       std::to_string(frame_rate_hz) + " Hz" + Got(exposure_us));
  }
  if (trigger.mode == TriggerMode::kHardware && trigger.line.empty()) {
    problems.push_back("trigger_line: a hardware trigger needs the camera's line (e.g. Line0)");
  }
  if (rate_ok && pair_tolerance_ms >= 0 && pair_tolerance_ms * 1e6 > FramePeriodNs() / 2) {
    problems.push_back("pair_tolerance_ms: must be at most half the frame period (" +
                       std::to_string(FramePeriodNs() / 2) +
                       " ns), else a frame could pair with its partner's neighbour" +
                       Got(pair_tolerance_ms));
  }
  if (timeout.count() <= 0) {
    problems.push_back("timeout: must be > 0 ms (got " + std::to_string(timeout.count()) + ")");
  }
  return problems;
}

struct AravisStereoSource::Impl {
  // One camera and its acquisition thread. Fields marked (mu) are guarded by Impl::mu; the
  // others belong to the thread (or to Open() before the thread starts).
  struct Slot {
    Side side = Side::kLeft;
    CameraSettings settings;
    std::unique_ptr<AravisCamera> camera;
    // Lost cameras being released in the background (a lost GigE camera takes ~2.5 s).
    std::vector<std::future<void>> releases;
    std::thread thread;

    std::string name;              // (mu) device id of the last opened camera
    CameraInfo info;               // (mu)
    CameraStats stats;             // (mu) totals over reopenings
    CameraStats closed_stats;      // statistics of the cameras already released
    bool lost = false;             // (mu)
    bool lost_reported = false;    // (mu) Next() has returned the loss once
    std::string lost_reason;       // (mu)
    Clock::time_point lost_since;  // (mu)
    std::string reconnect_error;   // (mu) why the last reopening failed
    int reconnect_attempts = 0;    // (mu) since the loss
    uint64_t frames = 0;           // (mu) complete frames, all reopenings
    int64_t last_t_ns = 0;         // (mu) capture time of the newest frame
  };

  AravisOptions options;
  std::shared_ptr<const geometry::StereoRig> rig;
  Clock::duration lost_after{};
  Clock::time_point trigger_epoch;  // software trigger instants: epoch + k * period

  mutable std::mutex mu;
  std::condition_variable cv;         // a pair, a loss, a recovery, or stop
  bool stop = false;                  // (mu)
  bool interrupted = false;           // (mu) Interrupt(): Next() returns at once
  StereoPairer pairer;                // (mu)
  std::optional<StereoFrame> latest;  // (mu) newest pair not yet taken
  uint64_t reconnects = 0;            // (mu)
  std::array<Slot, 2> slots;

  Slot& slot(Side side) { return slots[side == Side::kLeft ? 0 : 1]; }
  const Slot& slot(Side side) const { return slots[side == Side::kLeft ? 0 : 1]; }

  // What a slot's acquisition thread (Run) keeps between its steps: the software trigger's next
  // instant, the last sign of life of the camera, and the reopening's back-off.
  struct RunState {
    Clock::time_point next_trigger;
    Clock::time_point last_buffer;
    uint64_t incomplete_seen = 0;  // the camera's incomplete count at the last poll
    Clock::duration backoff{};
    Clock::time_point next_attempt;
    bool refresh_list = false;  // rediscover the devices before the next reopening
  };

  void Run(Slot& s);
  // Run's steps. Reopen: waits for the next attempt, then opens and starts the slot's camera;
  // false when the source stops meanwhile. Poll: one round with an open camera (a software
  // trigger when it is due, a frame popped and paired, a loss detected).
  bool Reopen(Slot& s, RunState& r);
  void Poll(Slot& s, RunState& r);
  // The next software trigger instant after `t`, on the time grid shared by both cameras.
  Clock::time_point NextGridPoint(Clock::time_point t) const;
  void Lose(Slot& s, const std::string& reason);
  void PublishStats(Slot& s, const CameraStats& current);
  std::string LostMessage(const Slot& s) const;
};

// Publishes the slot's totals: the released cameras' plus `now`, the current camera's.
void AravisStereoSource::Impl::PublishStats(Slot& s, const CameraStats& now) {
  std::lock_guard lock(mu);
  s.stats.frames = s.closed_stats.frames + now.frames;
  s.stats.incomplete = s.closed_stats.incomplete + now.incomplete;
  s.stats.resent_packets = s.closed_stats.resent_packets + now.resent_packets;
  s.stats.missing_packets = s.closed_stats.missing_packets + now.missing_packets;
  s.stats.underruns = s.closed_stats.underruns + now.underruns;
}

void AravisStereoSource::Impl::Lose(Slot& s, const std::string& reason) {
  const CameraStats last = s.camera->Stats();
  s.closed_stats.frames += last.frames;
  s.closed_stats.incomplete += last.incomplete;
  s.closed_stats.resent_packets += last.resent_packets;
  s.closed_stats.missing_packets += last.missing_packets;
  s.closed_stats.underruns += last.underruns;
  s.camera->MarkLost();
  // Releasing a lost GigE camera blocks for Aravis's control timeout; do it aside so that
  // reopening starts at once.
  s.releases.push_back(std::async(std::launch::async, [camera = std::move(s.camera)]() mutable {
    NameThisThread("stevi-arv-free");
    camera.reset();
  }));
  PublishStats(s, CameraStats{});
  {
    std::lock_guard lock(mu);
    s.lost = true;
    s.lost_reported = false;
    s.lost_reason = reason;
    s.lost_since = Clock::now();
    s.reconnect_error.clear();
    s.reconnect_attempts = 0;
  }
  cv.notify_all();
}

std::string AravisStereoSource::Impl::LostMessage(const Slot& s) const {
  std::string message = "camera " + s.name + " (" + SideName(s.side) + ") lost " +
                        SecondsText(Clock::now() - s.lost_since) + " ago: " + s.lost_reason;
  if (s.reconnect_attempts == 0) {
    message += "; reopening it";
  } else {
    message += "; reopening failed " + std::to_string(s.reconnect_attempts) +
               " time(s), last: " + s.reconnect_error;
  }
  return message;
}

Clock::time_point AravisStereoSource::Impl::NextGridPoint(Clock::time_point t) const {
  const auto period = std::chrono::nanoseconds(options.FramePeriodNs());
  const auto k = (t - trigger_epoch) / period + 1;
  return trigger_epoch + k * period;
}

void AravisStereoSource::Impl::Run(Slot& s) {
  RunState r;
  r.next_trigger = NextGridPoint(Clock::now());
  r.last_buffer = Clock::now();
  r.backoff = std::chrono::duration_cast<Clock::duration>(kReconnectFirst);
  r.next_attempt = Clock::now() + r.backoff;

  while (true) {
    {
      std::lock_guard lock(mu);
      if (stop) break;
    }
    // Forget releases that have finished.
    std::erase_if(s.releases, [](std::future<void>& f) {
      return f.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
    });
    if (!s.camera) {
      if (!Reopen(s, r)) break;
      continue;
    }
    Poll(s, r);
  }
  // Stopping: release the camera here (its AcquisitionStop is sent unless it was lost) and wait
  // for the releases still running.
  s.camera.reset();
  s.releases.clear();
}

bool AravisStereoSource::Impl::Reopen(Slot& s, RunState& r) {
  {
    std::unique_lock lock(mu);
    if (cv.wait_until(lock, r.next_attempt, [&] { return stop; })) return false;
  }
  Result<std::unique_ptr<AravisCamera>> opened = AravisCamera::Open(s.settings, r.refresh_list);
  Status started = opened.ok() ? opened.value()->StartAcquisition() : Status::Ok();
  if (!opened.ok() || !started.ok()) {
    const Error& error = opened.ok() ? started.error() : opened.error();
    {
      std::lock_guard lock(mu);
      s.reconnect_error = error.message;
      ++s.reconnect_attempts;
    }
    // Rediscover next time: the camera may come back at another address.
    r.refresh_list = true;
    r.backoff = std::min<Clock::duration>(r.backoff * 2, kReconnectMax);
    r.next_attempt = Clock::now() + r.backoff;
    cv.notify_all();
    return true;
  }
  s.camera = std::move(opened.value());
  r.refresh_list = false;
  r.backoff = std::chrono::duration_cast<Clock::duration>(kReconnectFirst);
  r.last_buffer = Clock::now();
  r.incomplete_seen = 0;
  r.next_trigger = NextGridPoint(Clock::now());
  {
    std::lock_guard lock(mu);
    // A reopened camera may have restarted its clock: pair only its new frames.
    pairer.ResetSide(s.side);
    s.lost = false;
    s.lost_reported = false;
    s.name = s.camera->id();
    s.info = s.camera->info();
    ++reconnects;
  }
  cv.notify_all();
  return true;
}

void AravisStereoSource::Impl::Poll(Slot& s, RunState& r) {
  auto wait = std::chrono::duration_cast<Clock::duration>(kPollSlice);
  if (options.trigger.mode == TriggerMode::kSoftware) {
    const auto now = Clock::now();
    if (now >= r.next_trigger) {
      if (Status triggered = s.camera->SoftwareTrigger(); !triggered.ok()) {
        Lose(s, triggered.error().message);
        r.next_attempt = Clock::now() + r.backoff;
        return;
      }
      r.next_trigger = NextGridPoint(now);
    }
    wait = std::min<Clock::duration>(wait, r.next_trigger - Clock::now());
  }
  Result<std::optional<MonoFrame>> popped =
      s.camera->Pop(std::chrono::duration_cast<std::chrono::microseconds>(wait));
  if (!popped.ok()) {
    Lose(s, popped.error().message);
    r.next_attempt = Clock::now() + r.backoff;
    return;
  }
  const CameraStats stats = s.camera->Stats();
  if (popped.value() || stats.incomplete != r.incomplete_seen) r.last_buffer = Clock::now();
  r.incomplete_seen = stats.incomplete;
  PublishStats(s, stats);
  if (std::optional<MonoFrame>& frame = popped.value()) {
    bool paired = false;
    {
      std::lock_guard lock(mu);
      ++s.frames;
      s.last_t_ns = frame->t_ns;
      if (std::optional<StereoFrame> pair = pairer.Add(s.side, std::move(*frame))) {
        latest = std::move(pair);
        paired = true;
      }
    }
    if (paired) cv.notify_all();
    return;
  }
  if (Clock::now() - r.last_buffer > lost_after) {
    // An idle hardware trigger is no fault: ask the camera whether it is still there.
    if (options.trigger.mode == TriggerMode::kHardware && s.camera->Ping().ok()) {
      r.last_buffer = Clock::now();
      return;
    }
    Lose(s, "no frame for " + SecondsText(Clock::now() - r.last_buffer));
    r.next_attempt = Clock::now() + r.backoff;
  }
}

AravisStereoSource::AravisStereoSource(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

AravisStereoSource::~AravisStereoSource() {
  {
    std::lock_guard lock(impl_->mu);
    impl_->stop = true;
  }
  impl_->cv.notify_all();
  for (Impl::Slot& s : impl_->slots) {
    if (s.thread.joinable()) s.thread.join();
  }
}

Result<std::unique_ptr<AravisStereoSource>> AravisStereoSource::Open(
    AravisOptions options, std::shared_ptr<const geometry::StereoRig> rig) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  if (rig && rig->image_size() != cv::Size(options.roi_width, options.roi_height)) {
    return InvalidArgument(
        "the calibration's image size " + std::to_string(rig->image_size().width) + "x" +
        std::to_string(rig->image_size().height) + " differs from the region of interest " +
        std::to_string(options.roi_width) + "x" + std::to_string(options.roi_height));
  }

  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->rig = std::move(rig);
  impl->pairer = StereoPairer(PairerOptions{options.PairToleranceNs(), 4});
  const auto exposure = std::chrono::microseconds(static_cast<int64_t>(options.exposure_us));
  impl->lost_after = std::max<Clock::duration>(
      options.timeout, 5 * std::chrono::nanoseconds(options.FramePeriodNs()) + exposure);

  for (Side side : {Side::kLeft, Side::kRight}) {
    Impl::Slot& s = impl->slot(side);
    s.side = side;
    CameraSettings& c = s.settings;
    c.id = side == Side::kLeft ? options.left_id : options.right_id;
    c.roi_width = options.roi_width;
    c.roi_height = options.roi_height;
    c.pixel_format = options.pixel_format;
    c.frame_rate_hz = options.frame_rate_hz;
    c.exposure_us = options.exposure_us;
    c.gain_db = options.gain_db;
    c.trigger = options.trigger.mode;
    c.trigger_line = options.trigger.line;
    c.buffers = options.buffers;
    c.timestamps = options.timestamps;
    Result<std::unique_ptr<AravisCamera>> camera = AravisCamera::Open(c);
    if (!camera.ok()) {
      return Error{camera.error().code,
                   std::string(SideName(side)) + ": " + camera.error().message};
    }
    s.camera = std::move(camera.value());
    s.name = s.camera->id();
    s.info = s.camera->info();
  }
  // Start both as close together as possible, then their threads.
  for (Impl::Slot& s : impl->slots) {
    if (Status started = s.camera->StartAcquisition(); !started.ok()) {
      return Error{started.error().code,
                   std::string(SideName(s.side)) + ": " + started.error().message};
    }
  }
  impl->trigger_epoch = Clock::now();
  std::unique_ptr<AravisStereoSource> source(new AravisStereoSource(std::move(impl)));
  for (Impl::Slot& s : source->impl_->slots) {
    s.thread = std::thread([impl = source->impl_.get(), &s] {
      NameThisThread("stevi-aravis");
      impl->Run(s);
    });
  }
  return source;
}

std::string AravisStereoSource::Describe() const {
  std::string left, right;
  {
    std::lock_guard lock(impl_->mu);
    left = impl_->slot(Side::kLeft).name;
    right = impl_->slot(Side::kRight).name;
  }
  const AravisOptions& o = impl_->options;
  char rate[32];
  std::snprintf(rate, sizeof rate, "%g", o.frame_rate_hz);
  std::string text = "aravis " + left + " + " + right + " " + std::to_string(o.roi_width) + "x" +
                     std::to_string(o.roi_height) + " " + rate + " fps";
  if (o.trigger.mode != TriggerMode::kFreeRun)
    text += std::string(" ") + TriggerModeName(o.trigger.mode) + " trigger";
  if (o.trigger.mode == TriggerMode::kHardware) text += " on " + o.trigger.line;
  return text;
}

std::shared_ptr<const geometry::StereoRig> AravisStereoSource::Rig() const { return impl_->rig; }

void AravisStereoSource::Interrupt() { InterruptWait(impl_->mu, impl_->interrupted, impl_->cv); }

Result<StereoFrame> AravisStereoSource::Next() {
  Impl& m = *impl_;
  std::unique_lock lock(m.mu);
  const auto deadline = Clock::now() + m.options.timeout;
  const uint64_t frames_before[2] = {m.slots[0].frames, m.slots[1].frames};
  while (true) {
    if (m.interrupted) return Unavailable("camera pair: stopped");
    if (m.latest) {
      return *std::exchange(m.latest, std::nullopt);
    }
    for (Impl::Slot& s : m.slots) {
      if (s.lost && !s.lost_reported) {
        s.lost_reported = true;
        return Unavailable(m.LostMessage(s));
      }
    }
    if (m.cv.wait_until(lock, deadline) == std::cv_status::timeout && !m.latest) break;
  }

  // Timed out: say which side is at fault.
  for (Impl::Slot& s : m.slots) {
    if (s.lost) {
      s.lost_reported = true;
      return Unavailable(m.LostMessage(s));
    }
  }
  const Impl::Slot& l = m.slot(Side::kLeft);
  const Impl::Slot& r = m.slot(Side::kRight);
  const uint64_t left_frames = l.frames - frames_before[0];
  const uint64_t right_frames = r.frames - frames_before[1];
  char waited[32];
  std::snprintf(waited, sizeof waited, "%g s",
                std::chrono::duration<double>(m.options.timeout).count());
  std::string message = "no pair from " + l.name + "/" + r.name + " for " + waited +
                        " (left: " + std::to_string(left_frames) +
                        " frames, right: " + std::to_string(right_frames) + " frames)";
  if (left_frames > 0 && right_frames > 0) {
    const int64_t gap = r.last_t_ns - l.last_t_ns;
    if (std::llabs(gap) > 1'000'000'000) {
      message += "; their capture times differ by " + SecondsText(std::chrono::nanoseconds(gap)) +
                 ": the camera clocks do not share a time base (synchronise them with PTP, or "
                 "pair by host timestamps)";
    } else {
      message += "; frames do not pair within " + MillisText(m.options.PairToleranceNs()) +
                 " (latest right - left: " + MillisText(gap) + ")";
    }
  }
  return Unavailable(message);
}

SourceCounters AravisStereoSource::Counters() const {
  std::lock_guard lock(impl_->mu);
  SourceCounters counters = impl_->pairer.Counters();
  counters.incomplete_dropped = 0;
  for (const Impl::Slot& s : impl_->slots) counters.incomplete_dropped += s.stats.incomplete;
  counters.reconnects = impl_->reconnects;
  return counters;
}

CameraInfo AravisStereoSource::camera_info(Side side) const {
  std::lock_guard lock(impl_->mu);
  return impl_->slot(side).info;
}

CameraStats AravisStereoSource::camera_stats(Side side) const {
  std::lock_guard lock(impl_->mu);
  return impl_->slot(side).stats;
}

}  // namespace stevi::drivers
