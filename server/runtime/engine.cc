#include "server/runtime/engine.h"

#include "core/common/format.h"

#include "core/common/thread_name.h"
#include "server/runtime/log.h"

#include <algorithm>
#include <chrono>
#include <map>

#include <opencv2/core/utility.hpp>

namespace stevi::server {
namespace {

using Clock = std::chrono::steady_clock;
constexpr size_t kRateWindow = 30;  // frames over which fps and mean timings are taken
constexpr auto kRetryFirst = std::chrono::milliseconds(200);
// Capped at 2 s so that a camera that comes back is streaming again within a few seconds.
constexpr auto kRetryMax = std::chrono::seconds(2);

void PushBounded(std::deque<Clock::time_point>& times, Clock::time_point t) {
  times.push_back(t);
  while (times.size() > kRateWindow) times.pop_front();
}

// Frames per second over the window; 0 when fewer than two frames or none for 2 s.
double Rate(const std::deque<Clock::time_point>& times) {
  if (times.size() < 2 || Clock::now() - times.back() > std::chrono::seconds(2)) return 0;
  const double span_s = std::chrono::duration<double>(times.back() - times.front()).count();
  return span_s > 0 ? static_cast<double>(times.size() - 1) / span_s : 0;
}

// The threads must outlive any failure of a library underneath: an exception (a bug, or input a
// library refuses in a way we did not foresee) becomes an error value and is counted.
Result<StereoFrame> NextFrame(drivers::StereoSource& source) {
  try {
    return source.Next();
  } catch (const std::exception& e) {
    return Internal(std::string("source: unexpected failure: ") + e.what());
  }
}

// Runs one half of the pipeline, turning an exception (a library failure) into an error.
template <typename Fn>
auto Guarded(Fn&& fn) -> decltype(fn()) {
  try {
    return fn();
  } catch (const std::exception& e) {
    return Internal(std::string("unexpected failure: ") + e.what());
  }
}

}  // namespace

std::string_view SourceStateName(SourceState state) {
  switch (state) {
    case SourceState::kStarting: return "starting";
    case SourceState::kRunning: return "running";
    case SourceState::kDown: return "down";
    case SourceState::kEnded: return "ended";
  }
  return "unknown";
}

Result<std::unique_ptr<Engine>> Engine::Create(std::unique_ptr<drivers::StereoSource> source,
                                               pipeline::PipelineConfig config, Sink sink) {
  if (source == nullptr) return Internal("engine: no source");
  if (std::vector<std::string> problems = config.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  return std::unique_ptr<Engine>(new Engine(std::move(source), std::move(config), std::move(sink)));
}

Engine::Engine(std::unique_ptr<drivers::StereoSource> source, pipeline::PipelineConfig config,
               Sink sink)
    : source_(std::move(source)),
      source_description_(source_->Describe()),
      source_image_size_(source_->ImageSize()),
      config_(std::move(config)),
      sink_(std::move(sink)),
      started_(Clock::now()),
      rig_(source_->Rig()) {}

void Engine::SetRig(std::shared_ptr<const geometry::StereoRig> rig, bool swap_left_right) {
  std::lock_guard lock(mu_);
  rig_ = std::move(rig);
  swap_left_right_ = swap_left_right;
}

void Engine::SetPoseSource(std::function<geo::PoseLookup(int64_t, int64_t)> pose_at) {
  std::lock_guard lock(mu_);
  pose_at_ = std::move(pose_at);
}

std::shared_ptr<const geometry::StereoRig> Engine::rig() const {
  std::lock_guard lock(mu_);
  return rig_;
}

Result<StereoFrame> Engine::WaitForCapture(Clock::duration timeout) {
  std::unique_lock lock(mu_);
  const uint64_t seen = frames_captured_;
  const bool got =
      capture_cv_.wait_for(lock, timeout, [&] { return stopping_ || frames_captured_ > seen; });
  if (stopping_) return Cancelled("the server is stopping");
  if (!got) {
    return Unavailable("no frame from the source within the timeout (" +
                       std::string(SourceStateName(source_state_)) +
                       (source_error_.empty() ? "" : ": " + source_error_) + ")");
  }
  return last_capture_;
}

Engine::~Engine() { Stop(); }

void Engine::Start(size_t workers, int opencv_threads) {
  std::lock_guard lock(mu_);
  if (started_threads_ || stopping_) return;
  started_threads_ = true;
  capture_thread_ = std::thread([this] {
    NameThisThread("stevi-capture");
    CaptureLoop();
  });
  // By default one worker per core (at least 1, at most kDefaultWorkers): each keeps a frame's
  // worth of buffers.
  if (workers == 0) {
    workers = std::clamp<size_t>(std::thread::hardware_concurrency(), 1, kDefaultWorkers);
  }
  workers_ = workers;
  // Set before the workers start, and only when it changes: cv::setNumThreads rebuilds OpenCV's
  // thread pool, which must not be in use meanwhile.
  if (opencv_threads == 0 && workers > 1) opencv_threads = 1;
  if (opencv_threads > 0 && cv::getNumThreads() != opencv_threads)
    cv::setNumThreads(opencv_threads);
  Log(LogLevel::kInfo, "engine_started",
      {{"pipeline_workers", std::to_string(workers)},
       {"opencv_threads", std::to_string(cv::getNumThreads())}});
  {
    std::lock_guard order(order_mu_);
    workers_running_ = workers;
  }
  // Every front end exists before any worker starts: a worker reads fronts_, which must not grow
  // (and move) under it.
  for (size_t i = 0; i < workers; ++i) fronts_.push_back(std::make_unique<pipeline::FrontEnd>());
  for (size_t i = 0; i < workers; ++i) {
    worker_threads_.emplace_back([this, i] {
      NameThisThread("stevi-worker-" + std::to_string(i));
      WorkerLoop(i);
    });
  }
  finish_thread_ = std::thread([this] {
    NameThisThread("stevi-finish");
    FinishLoop();
  });
}

void Engine::Stop() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  stop_cv_.notify_all();
  capture_cv_.notify_all();
  // A source waiting for its next frame (a replay's long recorded gap, a camera's timeout) gives
  // up at once, so that the capture thread joins promptly.
  if (source_) source_->Interrupt();
  mailbox_.Close();
  if (capture_thread_.joinable()) capture_thread_.join();
  for (std::thread& worker : worker_threads_) {
    if (worker.joinable()) worker.join();  // the last one to stop ends FinishLoop
  }
  if (finish_thread_.joinable()) finish_thread_.join();
}

bool Engine::WaitUntil(Clock::time_point deadline) {
  std::unique_lock lock(mu_);
  stop_cv_.wait_until(lock, deadline, [&] { return stopping_; });
  return !stopping_;
}

void Engine::SetSourceState(SourceState state, std::string error) {
  bool changed = false;
  {
    std::lock_guard lock(mu_);
    changed = source_state_ != state;
    source_state_ = state;
    source_error_ = error;
  }
  if (changed) {
    Log(state == SourceState::kDown ? LogLevel::kWarning : LogLevel::kInfo, "source_state",
        {{"state", std::string(SourceStateName(state))},
         {"source", source_description_},
         {"error", error}});
  }
}

void Engine::CaptureLoop() {
  const double fps = source_->NominalFps();
  const auto period =
      fps > 0
          ? std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / fps))
          : Clock::duration::zero();
  auto next_tick = Clock::now();
  auto retry = std::chrono::duration_cast<Clock::duration>(kRetryFirst);
  while (WaitUntil(next_tick)) {
    Result<StereoFrame> frame = NextFrame(*source_);
    const auto now = Clock::now();
    if (!frame.ok()) {
      if (frame.error().code == ErrorCode::kOutOfRange) {
        SetSourceState(SourceState::kEnded, frame.error().message);
        return;
      }
      SetSourceState(SourceState::kDown, frame.error().message);
      next_tick = now + retry;
      retry = std::min<Clock::duration>(retry * 2, kRetryMax);
      continue;
    }
    retry = std::chrono::duration_cast<Clock::duration>(kRetryFirst);
    if (frame->unix_time_ns == 0) frame->unix_time_ns = UnixNowNs();
    std::shared_ptr<const CaptureTap> tap;
    bool recovered = false;
    {
      std::lock_guard lock(mu_);
      recovered = source_state_ != SourceState::kRunning;
      source_state_ = SourceState::kRunning;
      source_error_.clear();
      ++frames_captured_;
      PushBounded(capture_times_, now);
      last_capture_ = *frame;
      tap = capture_tap_;
    }
    capture_cv_.notify_all();
    if (recovered) {
      Log(LogLevel::kInfo, "source_state",
          {{"state", std::string(SourceStateName(SourceState::kRunning))},
           {"source", source_description_}});
    }
    if (tap) (*tap)(*frame);
    mailbox_.Put(std::move(frame).value());
    // Pace; when the source itself is slower than the period, do not try to catch up.
    next_tick = std::max(next_tick + period, now);
  }
}

void Engine::WorkerLoop(size_t index) {
  pipeline::FrontEnd& front = *fronts_[index];
  while (true) {
    std::optional<StereoFrame> frame;
    uint64_t sequence = 0;
    {
      std::lock_guard take(take_mu_);
      frame = mailbox_.Take();
      if (!frame) break;  // closed: stopping
      sequence = next_take_++;
    }
    pipeline::Snapshot snapshot{config_.Get(), nullptr};
    {
      std::lock_guard lock(mu_);
      snapshot.rig = rig_;
      snapshot.pose_at = pose_at_;
      if (swap_left_right_) {
        // The views change places, and so does the sign of their skew (right minus left).
        std::swap(frame->left, frame->right);
        frame->pair_skew_ns = -frame->pair_skew_ns;
      }
    }
    Result<pipeline::PreparedFrame> prepared =
        Guarded([&] { return front.Prepare(*frame, snapshot); });
    std::optional<Prepared> item;
    if (prepared.ok()) {
      item = Prepared{std::move(prepared).value(), std::move(snapshot)};
    } else {
      CountFailure(prepared.error());
    }
    {
      std::lock_guard order(order_mu_);
      ready_.emplace(sequence, std::move(item));
    }
    order_cv_.notify_all();
  }
  {
    std::lock_guard order(order_mu_);
    --workers_running_;
  }
  order_cv_.notify_all();
}

void Engine::FinishLoop() {
  while (true) {
    std::optional<Prepared> item;
    {
      std::unique_lock order(order_mu_);
      order_cv_.wait(order,
                     [&] { return ready_.count(next_finish_) > 0 || workers_running_ == 0; });
      const auto it = ready_.find(next_finish_);
      if (it == ready_.end()) return;  // every worker has stopped and nothing is left
      item = std::move(it->second);
      ready_.erase(it);
      ++next_finish_;
    }
    if (!item) continue;  // the frame failed in its worker (counted there)
    Result<pipeline::FrameResult> result =
        Guarded([&] { return pipeline_.Finish(std::move(item->frame), item->snapshot); });
    const auto now = Clock::now();
    if (!result.ok()) {
      CountFailure(result.error());
      continue;
    }
    auto shared = std::make_shared<const pipeline::FrameResult>(std::move(result).value());
    {
      std::lock_guard lock(mu_);
      ++frames_processed_;
      PushBounded(process_times_, now);
      recent_timings_.push_back(shared->timings);
      while (recent_timings_.size() > kRateWindow) recent_timings_.pop_front();
      latest_ = shared;
    }
    if (sink_) sink_(shared);
  }
}

void Engine::CountFailure(const Error& error) {
  std::lock_guard lock(mu_);
  ++frames_failed_;
  source_error_ = "pipeline: " + error.message;
}

std::shared_ptr<const pipeline::FrameResult> Engine::Latest() const {
  std::lock_guard lock(mu_);
  return latest_;
}

void Engine::SetCaptureTap(CaptureTap tap) {
  auto shared = tap ? std::make_shared<const CaptureTap>(std::move(tap)) : nullptr;
  std::lock_guard lock(mu_);
  capture_tap_ = std::move(shared);
}

EngineStatus Engine::Status() const {
  EngineStatus s;
  s.source = source_description_;
  s.pairing = source_->Counters();
  s.frames_dropped_capture = mailbox_.dropped();
  const std::shared_ptr<const pipeline::PipelineConfig> config = config_.Get();
  s.algorithm = config->algorithm;
  s.uptime_s = std::chrono::duration<double>(Clock::now() - started_).count();
  std::lock_guard lock(mu_);
  s.calibration_id = rig_ ? rig_->calibration_id() : "";
  if (rig_) s.image_size = rig_->image_size();
  if (latest_ && latest_->rig) {
    s.processed_size = latest_->rig->image_size();
    s.binning = latest_->binning;
  }
  s.source_state = source_state_;
  s.source_error = source_error_;
  s.workers = workers_;
  s.opencv_threads = cv::getNumThreads();
  s.fps_in = Rate(capture_times_);
  s.fps_out = Rate(process_times_);
  s.frames_captured = frames_captured_;
  s.frames_processed = frames_processed_;
  s.frames_failed = frames_failed_;
  // Mean per stage, in the order the stages first appear.
  std::vector<std::string> order;
  std::map<std::string, std::pair<double, int>> sums;
  for (const auto& timings : recent_timings_) {
    for (const pipeline::StageTiming& t : timings) {
      auto [it, inserted] = sums.try_emplace(t.stage, 0.0, 0);
      if (inserted) order.push_back(t.stage);
      it->second.first += t.ms;
      it->second.second += 1;
    }
  }
  for (const std::string& stage : order) {
    const auto& [sum, n] = sums[stage];
    s.mean_timings.push_back({stage, sum / n});
  }
  return s;
}

}  // namespace stevi::server
