#include "drivers/recording/recorder.h"

#include "core/common/format.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <utility>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/util/json_util.h>
#include <opencv2/imgcodecs.hpp>

#include "core/common/atomic_file.h"
#include "core/common/thread_name.h"
#include "core/geometry/calibration_io.h"

namespace stevi::drivers {
namespace {

namespace fs = std::filesystem;

// Vehicle states and calibration changes waiting behind the frames. They are small, but a writer
// stuck on a slow disk must not let a 100 Hz pose stream grow without bound.
constexpr size_t kMaxQueuedOther = 4096;
// Calibration YAML is a few KiB; this keeps a change record far inside kMaxRecordBytes.
constexpr size_t kMaxCalibrationYamlBytes = 1 << 20;

std::string ManifestJson(const v1::RecordingManifest& manifest) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = true;
  std::string out;
  // Printing a message we built cannot fail (no Any fields to resolve).
  (void)google::protobuf::util::MessageToJsonString(manifest, &out, options);
  return out;
}

// The problem with one image handed to AddFrame, empty when it can be recorded.
std::string ImageProblem(const cv::Mat& image, const char* side) {
  std::string problem;
  if (image.empty()) {
    problem = ": empty image";
  } else if (image.type() != CV_8UC1 && image.type() != CV_8UC3) {
    problem =
        ": expected 8-bit grey (CV_8UC1) or BGR (CV_8UC3), got " + cv::typeToString(image.type());
  } else if (image.cols > kMaxImageSide || image.rows > kMaxImageSide ||
             int64_t{image.cols} * image.rows > kMaxImagePixels) {
    problem = ": " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
              " is larger than the recording format allows";
  }
  if (problem.empty()) return problem;
  return std::string(side) + problem;
}

// The error code of a failed write: a full disk or file-size limit is an exhausted resource, the
// rest (EIO, a vanished device) an unavailable one.
ErrorCode WriteErrorCode(int err) {
  return (err == ENOSPC || err == EDQUOT || err == EFBIG) ? ErrorCode::kResourceExhausted
                                                          : ErrorCode::kUnavailable;
}

bool IsFrame(const std::variant<StereoFrame, geo::VehicleState, CalibrationChange>& entry) {
  return std::holds_alternative<StereoFrame>(entry);
}

}  // namespace

Result<std::unique_ptr<Recorder>> Recorder::Start(const std::string& dir, RecorderOptions options,
                                                  RecordingInfo info) {
  std::vector<std::string> problems;
  if (dir.empty()) problems.push_back("dir: must not be empty");
  AppendPrefixed(problems, "options.", options.Validate());
  if (!info.rig) problems.push_back("info.rig: missing (the rig the frames follow)");
  if (!problems.empty()) return InvalidArgument(problems);
  // Check that the rig can be stored exactly before touching the disk.
  Result<v1::RecordedRig> rig = RecordedRigOf(*info.rig);
  if (!rig.ok()) return rig.error();

  std::error_code ec;
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec)) {
    return InvalidArgument("recording directory " + dir + ": exists and is not a directory");
  }
  fs::create_directories(dir, ec);
  if (ec) {
    return InvalidArgument("recording directory " + dir + ": cannot create it (" + ec.message() +
                           ")");
  }
  const std::string manifest_path = (fs::path(dir) / kManifestFileName).string();
  const std::string records_path = (fs::path(dir) / kRecordsFileName).string();
  if (fs::exists(manifest_path, ec)) {
    return AlreadyExists("recording directory " + dir + " already holds a recording (" +
                         kManifestFileName + " exists); record to a new directory");
  }
  // O_EXCL: of two recorders started on one directory, only one gets it.
  const int fd = ::open(records_path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    const int err = errno;
    if (err == EEXIST) {
      return AlreadyExists("recording directory " + dir + " already holds a recording (" +
                           kRecordsFileName + " exists); record to a new directory");
    }
    return InvalidArgument(records_path + ": cannot create it (" + std::strerror(err) + ")");
  }

  v1::RecordingManifest manifest;
  manifest.set_format_version(kRecordingFormatVersion);
  manifest.set_created_unix_ns(UnixNowNs());
  manifest.set_source(info.source);
  *manifest.mutable_rig() = std::move(rig.value());
  manifest.set_calibration_id(info.calibration_id.empty() ? info.rig->calibration_id()
                                                          : info.calibration_id);
  manifest.set_encoding(v1::IMAGE_ENCODING_PNG);
  manifest.set_png_compression(options.png_compression);
  manifest.set_max_bytes(options.max_bytes);
  manifest.set_state(v1::RECORDING_STATE_RECORDING);
  if (stevi::Status written = AtomicWriteFile(manifest_path, ManifestJson(manifest)); !written) {
    // Leave the directory as it was, so that a retry is not refused.
    ::close(fd);
    ::unlink(records_path.c_str());
    return written.error();
  }

  auto recorder = std::unique_ptr<Recorder>(new Recorder(dir, options, std::move(manifest), fd));
  recorder->writer_ = std::thread([r = recorder.get()] {
    NameThisThread("stevi-recorder");
    r->WriterLoop();
  });
  return recorder;
}

Recorder::Recorder(std::string dir, RecorderOptions options, v1::RecordingManifest manifest, int fd)
    : dir_(std::move(dir)),
      options_(options),
      records_path_((fs::path(dir_) / kRecordsFileName).string()),
      manifest_path_((fs::path(dir_) / kManifestFileName).string()),
      fd_(fd),
      manifest_(std::move(manifest)) {
  status_.recording = true;
  status_.dir = dir_;
}

Recorder::~Recorder() { (void)Stop("recorder destroyed"); }

stevi::Status Recorder::AddFrame(const StereoFrame& frame) {
  std::string problem = ImageProblem(frame.left, "left");
  if (problem.empty()) problem = ImageProblem(frame.right, "right");
  if (problem.empty() && frame.left.size() != frame.right.size()) {
    problem = "left and right differ in size";
  }
  if (!problem.empty()) {
    return InvalidArgument("recording " + dir_ + ": frame " + std::to_string(frame.index) + ": " +
                           problem);
  }
  {
    // Refuse before copying the images when there is no room anyway (Enqueue checks again).
    std::lock_guard lock(mu_);
    if (std::optional<Error> refused = RefuseLocked(/*frame=*/true)) return *refused;
  }
  // A deep copy: the caller may reuse its buffers for the next capture.
  StereoFrame copy = frame;
  copy.left = frame.left.clone();
  copy.right = frame.right.clone();
  return Enqueue(Item{std::move(copy)});
}

stevi::Status Recorder::AddVehicleState(const geo::VehicleState& state) {
  return Enqueue(Item{state});
}

stevi::Status Recorder::SetCalibration(const std::string& calibration_id, const std::string& yaml) {
  std::vector<std::string> problems;
  if (calibration_id.empty()) problems.push_back("calibration_id: must not be empty");
  if (yaml.size() > kMaxCalibrationYamlBytes) {
    problems.push_back("yaml: " + FormatBytes(yaml.size()) + " is more than the " +
                       FormatBytes(kMaxCalibrationYamlBytes) + " a calibration may have");
  } else if (Result<geometry::StereoCalibration> parsed = geometry::ParseCalibrationYaml(yaml);
             !parsed.ok()) {
    problems.push_back("yaml: " + parsed.error().message);
  }
  if (!problems.empty()) {
    Error e = InvalidArgument(problems);
    e.message = "recording " + dir_ + ": calibration change refused: " + e.message;
    return e;
  }
  return Enqueue(Item{CalibrationChange{calibration_id, yaml, UnixNowNs()}});
}

std::optional<Error> Recorder::RefuseLocked(bool frame) {
  if (stopped_) {
    const std::string& why = stopping_reason_.empty() ? requested_reason_ : stopping_reason_;
    return FailedPrecondition("recording " + dir_ + " has stopped (" + why + ")");
  }
  if (frame && queued_frames_ >= static_cast<size_t>(options_.queue_frames)) {
    ++status_.frames_dropped;
    return ResourceExhausted("recording " + dir_ + ": the writer is behind (" +
                             std::to_string(options_.queue_frames) +
                             " frames queued); frame dropped");
  }
  if (!frame && queued_other_ >= kMaxQueuedOther) {
    ++status_.other_dropped;
    return ResourceExhausted("recording " + dir_ + ": the writer is behind (" +
                             std::to_string(kMaxQueuedOther) + " records queued); record dropped");
  }
  return std::nullopt;
}

stevi::Status Recorder::Enqueue(Item item) {
  const bool frame = IsFrame(item.entry);
  {
    std::lock_guard lock(mu_);
    if (std::optional<Error> refused = RefuseLocked(frame)) return *refused;
    ++(frame ? queued_frames_ : queued_other_);
    queue_.push_back(std::move(item));
  }
  wake_.notify_one();
  return stevi::Status::Ok();
}

void Recorder::WriterLoop() {
  std::optional<Outcome> outcome;
  while (!outcome) {
    Item item;
    {
      std::unique_lock lock(mu_);
      wake_.wait(lock, [&] { return !queue_.empty() || stop_requested_; });
      if (queue_.empty()) {
        // Asked to stop and everything queued before is written.
        outcome = Outcome{requested_reason_, "", ErrorCode::kInternal};
        break;
      }
      item = std::move(queue_.front());
      queue_.pop_front();
      --(IsFrame(item.entry) ? queued_frames_ : queued_other_);
    }
    outcome = Write(item);
  }
  {
    // Refuse new items at once; what is still queued (after a disk limit or an error) is lost.
    std::lock_guard lock(mu_);
    stopped_ = true;
    stopping_reason_ = outcome->reason;
    for (const Item& left_over : queue_) {
      ++(IsFrame(left_over.entry) ? status_.frames_dropped : status_.other_dropped);
    }
    queue_.clear();
    queued_frames_ = queued_other_ = 0;
  }
  const std::string finish_error = Finish(*outcome);
  // Only now is the recording complete on disk: Status() says "stopped" from here on.
  std::lock_guard lock(mu_);
  status_.recording = false;
  status_.stop_reason = outcome->reason;
  status_.error = outcome->error;
  error_code_ = outcome->code;
  if (!finish_error.empty()) {
    if (status_.error.empty()) {
      status_.error = finish_error;
      error_code_ = ErrorCode::kUnavailable;
    } else {
      status_.error += "; " + finish_error;
    }
  }
}

namespace {

// `frame` as a record's frame, both images as PNGs; false (with `why`, an OpenCV message or
// empty) when they cannot be encoded, and then `entry` is left as it was.
bool EncodeFrame(const StereoFrame& frame, int png_compression, v1::RecordEntry& entry,
                 std::string& why) {
  std::vector<uchar> left_png, right_png;
  const std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, png_compression};
  bool encoded = false;
  try {
    encoded = cv::imencode(".png", frame.left, left_png, params) &&
              cv::imencode(".png", frame.right, right_png, params);
  } catch (const cv::Exception& e) {
    why = std::string(" (") + e.what() + ")";
  }
  if (!encoded) return false;
  v1::RecordedFrame* out = entry.mutable_frame();
  out->set_index(frame.index);
  out->set_t_ns(frame.t_ns);
  out->set_unix_time_ns(frame.unix_time_ns);
  out->set_pair_skew_ns(frame.pair_skew_ns);
  out->set_rectified(frame.rectified);
  for (auto [image, png, side] : {std::tuple{&frame.left, &left_png, out->mutable_left()},
                                  std::tuple{&frame.right, &right_png, out->mutable_right()}}) {
    side->set_width(image->cols);
    side->set_height(image->rows);
    side->set_channels(image->channels());
    side->set_data(png->data(), png->size());
  }
  return true;
}

}  // namespace

std::optional<Recorder::Outcome> Recorder::Write(const Item& item) {
  v1::RecordEntry entry;
  const StereoFrame* frame = std::get_if<StereoFrame>(&item.entry);
  if (frame != nullptr) {
    std::string why;
    if (!EncodeFrame(*frame, options_.png_compression, entry, why)) {
      // AddFrame checked the images, so this is a library failure: stop rather than lose frames
      // silently one by one.
      return Outcome{"cannot encode frame " + std::to_string(frame->index) + " as PNG" + why,
                     "recording " + dir_ + ": cannot encode frame " + std::to_string(frame->index) +
                         " as PNG" + why,
                     ErrorCode::kInternal};
    }
  } else if (const auto* state = std::get_if<geo::VehicleState>(&item.entry)) {
    *entry.mutable_vehicle_state() = VehicleStateToProto(*state);
  } else {
    const auto& change = std::get<CalibrationChange>(item.entry);
    v1::CalibrationChange* out = entry.mutable_calibration();
    out->set_calibration_id(change.calibration_id);
    out->set_calibration_yaml(change.yaml);
    out->set_unix_time_ns(change.unix_time_ns);
  }

  // The framing of util::SerializeDelimitedToOstream: varint32 size, then the message. Built in
  // one buffer so that it goes to the file in one write.
  const size_t size = entry.ByteSizeLong();
  if (size > kMaxRecordBytes) {
    // AddFrame's limits make this impossible; a reader would refuse the record, so drop it.
    std::lock_guard lock(mu_);
    ++(frame != nullptr ? status_.frames_dropped : status_.other_dropped);
    return std::nullopt;
  }
  uint8_t prefix[5];
  const uint8_t* prefix_end = google::protobuf::io::CodedOutputStream::WriteVarint32ToArray(
      static_cast<uint32_t>(size), prefix);
  const size_t prefix_size = static_cast<size_t>(prefix_end - prefix);
  std::string record(prefix_size + size, '\0');
  std::memcpy(record.data(), prefix, prefix_size);
  entry.SerializeWithCachedSizesToArray(reinterpret_cast<uint8_t*>(record.data() + prefix_size));

  {
    std::lock_guard lock(mu_);
    if (status_.bytes_written + record.size() > options_.max_bytes) {
      return Outcome{"disk limit of " + FormatBytes(options_.max_bytes) + " reached after " +
                         std::to_string(status_.frames_written) + " frames",
                     "", ErrorCode::kInternal};
    }
  }
  if (std::optional<Outcome> failed = Append(record)) return failed;

  std::lock_guard lock(mu_);
  status_.bytes_written += record.size();
  if (frame != nullptr) {
    if (status_.frames_written == 0) manifest_.set_first_t_ns(frame->t_ns);
    manifest_.set_last_t_ns(frame->t_ns);
    ++status_.frames_written;
  } else if (std::holds_alternative<geo::VehicleState>(item.entry)) {
    ++status_.vehicle_states_written;
  } else {
    ++status_.calibration_changes_written;
  }
  return std::nullopt;
}

std::optional<Recorder::Outcome> Recorder::Append(const std::string& record) {
  uint64_t good_size = 0;
  uint64_t frames = 0;
  {
    std::lock_guard lock(mu_);
    good_size = status_.bytes_written;
    frames = status_.frames_written;
  }
  size_t done = 0;
  while (done < record.size()) {
    const ssize_t n = ::write(fd_, record.data() + done, record.size() - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    // n == 0 does not happen for regular files; treat it as a full disk rather than spin.
    const int err = n < 0 ? errno : ENOSPC;
    std::string message = records_path_ + ": write failed after " + std::to_string(frames) +
                          " frames (" + std::strerror(err) + ")";
    // Cut the torn record off, so the file ends on a whole record.
    if (::ftruncate(fd_, static_cast<off_t>(good_size)) != 0 ||
        ::lseek(fd_, static_cast<off_t>(good_size), SEEK_SET) < 0) {
      message += "; truncating back to the last whole record (byte " + std::to_string(good_size) +
                 ") also failed (" + std::strerror(errno) + ")";
    }
    return Outcome{message, message, WriteErrorCode(err)};
  }
  return std::nullopt;
}

std::string Recorder::Finish(const Outcome& outcome) {
  std::string error;
  if (::fsync(fd_) != 0) {
    error = records_path_ + ": fsync failed (" + std::strerror(errno) + ")";
  }
  if (::close(fd_) != 0 && error.empty()) {
    error = records_path_ + ": close failed (" + std::strerror(errno) + ")";
  }
  fd_ = -1;
  {
    std::lock_guard lock(mu_);
    manifest_.set_frames_written(status_.frames_written);
    manifest_.set_bytes_written(status_.bytes_written);
    manifest_.set_frames_dropped(status_.frames_dropped);
    manifest_.set_vehicle_states_written(status_.vehicle_states_written);
    manifest_.set_calibration_changes_written(status_.calibration_changes_written);
    manifest_.set_other_dropped(status_.other_dropped);
  }
  manifest_.set_state(v1::RECORDING_STATE_STOPPED);
  manifest_.set_stopped_unix_ns(UnixNowNs());
  manifest_.set_stop_reason(outcome.reason);
  manifest_.set_failed(!outcome.error.empty());
  if (stevi::Status written = AtomicWriteFile(manifest_path_, ManifestJson(manifest_)); !written) {
    if (!error.empty()) error += "; ";
    error += written.error().message;
  }
  return error;
}

stevi::Status Recorder::Stop(const std::string& reason) {
  std::lock_guard stop_lock(stop_mu_);
  {
    std::lock_guard lock(mu_);
    if (!stop_requested_) {
      stop_requested_ = true;
      requested_reason_ = reason;
    }
    stopped_ = true;
  }
  wake_.notify_all();
  if (writer_.joinable()) writer_.join();
  std::lock_guard lock(mu_);
  if (!status_.error.empty()) return Error{error_code_, status_.error};
  return stevi::Status::Ok();
}

RecorderStatus Recorder::Status() const {
  std::lock_guard lock(mu_);
  RecorderStatus status = status_;
  status.frames_queued = queued_frames_;
  return status;
}

}  // namespace stevi::drivers
