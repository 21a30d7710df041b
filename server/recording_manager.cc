#include "server/recording_manager.h"

#include <ctime>
#include <filesystem>

#include "core/geometry/calibration_io.h"

namespace stevi::server {
namespace {

constexpr size_t kMaxNameLength = 64;

v1::RecordingStatus ToProto(const drivers::RecorderStatus& s, uint64_t max_bytes) {
  v1::RecordingStatus out;
  out.set_active(s.recording);
  out.set_dir(s.dir);
  out.set_frames_written(s.frames_written);
  out.set_bytes_written(s.bytes_written);
  out.set_frames_dropped(s.frames_dropped);
  out.set_max_bytes(max_bytes);
  out.set_stop_reason(s.stop_reason);
  return out;
}

// "rec-20261121-103412" (UTC), for a recording started without a name.
std::string NameFromTime() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char buf[32];
  std::strftime(buf, sizeof buf, "rec-%Y%m%d-%H%M%S", &utc);
  return buf;
}

}  // namespace

std::string CheckRecordingName(const std::string& name) {
  if (name.empty()) return "must not be empty";
  if (name.size() > kMaxNameLength) {
    return "must be at most " + std::to_string(kMaxNameLength) + " characters (got " +
           std::to_string(name.size()) + ")";
  }
  if (name.front() == '.') return "must not start with '.' (got '" + name + "')";
  for (const char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '-' || c == '_' || c == '.';
    if (!ok) {
      return "may hold only letters, digits, '-', '_' and '.': a plain name, not a path (got '" +
             name + "')";
    }
  }
  return "";
}

RecordingManager::RecordingManager(std::string data_dir, Engine& engine, const PoseSource& poses)
    : recordings_root_((std::filesystem::path(data_dir) / "recordings").string()),
      engine_(engine),
      poses_(poses) {
  engine_.SetCaptureTap([this](const StereoFrame& frame) { OnFrame(frame); });
}

RecordingManager::~RecordingManager() {
  engine_.SetCaptureTap(nullptr);
  Stop("the server stopped");
}

Result<v1::RecordingStatus> RecordingManager::StartIn(const std::string& dir, uint64_t max_bytes,
                                                      int queue_frames) {
  drivers::RecorderOptions options;
  options.max_bytes = max_bytes;
  options.queue_frames = queue_frames;
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  std::lock_guard lock(mu_);
  if (active_ != nullptr) {
    return FailedPrecondition("a recording is running in " + active_dir_ + ": stop it first");
  }
  std::error_code ec;
  if (std::filesystem::exists(std::filesystem::path(dir) / "manifest.json", ec)) {
    return AlreadyExists(dir + " already holds a recording: choose another name or directory");
  }
  const std::shared_ptr<const geometry::StereoRig> rig = engine_.rig();
  if (rig == nullptr) {
    return FailedPrecondition("no calibration yet: a recording needs the rig its frames follow");
  }
  drivers::RecordingInfo info;
  info.source = engine_.Status().source;
  info.rig = rig;
  info.calibration_id = rig->calibration_id();
  Result<std::unique_ptr<drivers::Recorder>> recorder =
      drivers::Recorder::Start(dir, options, std::move(info));
  if (!recorder.ok()) return recorder.error();
  active_ = std::move(recorder).value();
  active_dir_ = dir;
  active_max_bytes_ = max_bytes;
  recorded_calibration_id_ = rig->calibration_id();
  return ToProto(active_->Status(), max_bytes);
}

Result<v1::RecordingStatus> RecordingManager::Start(const v1::StartRecordingRequest& request) {
  const std::string name = request.name().empty() ? NameFromTime() : request.name();
  if (const std::string problem = CheckRecordingName(name); !problem.empty()) {
    return InvalidArgument("name: " + problem);
  }
  const uint64_t max_bytes =
      request.max_bytes() == 0 ? drivers::RecorderOptions().max_bytes : request.max_bytes();
  return StartIn((std::filesystem::path(recordings_root_) / name).string(), max_bytes);
}

v1::RecordingStatus RecordingManager::Stop(const std::string& reason) {
  std::shared_ptr<drivers::Recorder> recorder;
  uint64_t max_bytes = 0;
  {
    std::lock_guard lock(mu_);
    if (active_ == nullptr) return last_.value_or(v1::RecordingStatus());
    recorder = std::move(active_);
    max_bytes = active_max_bytes_;
  }
  // Outside the lock: draining the queue writes to disk. A write error is in the status.
  (void)recorder->Stop(reason);
  v1::RecordingStatus status = ToProto(recorder->Status(), max_bytes);
  std::lock_guard lock(mu_);
  last_ = status;
  return status;
}

v1::RecordingStatus RecordingManager::Status() const {
  std::lock_guard lock(mu_);
  if (active_ != nullptr) return ToProto(active_->Status(), active_max_bytes_);
  return last_.value_or(v1::RecordingStatus());
}

void RecordingManager::OnFrame(const StereoFrame& frame) {
  std::shared_ptr<drivers::Recorder> recorder;
  bool calibration_changed = false;
  std::shared_ptr<const geometry::StereoRig> rig = engine_.rig();
  {
    std::lock_guard lock(mu_);
    if (active_ == nullptr) return;
    recorder = active_;
    if (rig != nullptr && rig->calibration_id() != recorded_calibration_id_) {
      recorded_calibration_id_ = rig->calibration_id();
      calibration_changed = true;
    }
  }
  if (calibration_changed) {
    if (Result<std::string> yaml = geometry::CalibrationYamlText(rig->calibration()); yaml.ok()) {
      (void)recorder->SetCalibration(rig->calibration_id(), *yaml);
    }
  }
  // The pose the pipeline will look up for this frame, recorded just before it with the frame's
  // wall-clock time: a replay finds it again by that time and georeferences exactly as live.
  const geo::PoseLookup pose = poses_.At(frame.t_ns, frame.unix_time_ns);
  if (pose.ok()) {
    geo::VehicleState state = pose.pose->state;
    state.t_ns = frame.unix_time_ns;
    (void)recorder->AddVehicleState(state);
  }
  // A full queue drops and counts the frame; a stopped recorder (disk limit, write error) refuses
  // it. Both are in its status; the capture thread never waits.
  (void)recorder->AddFrame(frame);
  if (!recorder->Status().recording) {
    std::lock_guard lock(mu_);
    if (active_ == recorder) {
      last_ = ToProto(recorder->Status(), active_max_bytes_);
      active_.reset();
    }
  }
}

}  // namespace stevi::server
