#include "drivers/mcap/flight_log.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>

#include "foxglove/CompressedImage.pb.h"
#include "foxglove/ImageAnnotations.pb.h"
#include "foxglove/LocationFix.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "proto/foxglove/convert.h"

namespace stevi::drivers {
namespace {

// Frames of reference, as the station names them ("rig1_camera", "rig1_vehicle").
std::string CameraFrame(const FlightLogOptions& options) { return options.rig + "_camera"; }
std::string VehicleFrame(const FlightLogOptions& options) { return options.rig + "_vehicle"; }

uint64_t LogTime(int64_t unix_time_ns) {
  return unix_time_ns > 0 ? static_cast<uint64_t>(unix_time_ns) : 0;
}

// A frame's log time: its capture's Unix time, or (a source that does not know the wall clock,
// such as image files) its capture time, so that the timeline still runs.
int64_t FrameTime(int64_t capture_unix_time_ns, int64_t capture_time_ns) {
  return capture_unix_time_ns > 0 ? capture_unix_time_ns : capture_time_ns;
}

// The topic of a kept image kind, or "" for kinds a flight log does not keep.
std::string ImageTopic(const FlightLogOptions& options, v1::PreviewKind kind) {
  switch (kind) {
    case v1::PREVIEW_KIND_LEFT: return "/" + options.rig + "/image/left";
    case v1::PREVIEW_KIND_DISPARITY: return "/" + options.rig + "/image/disparity";
    default: return "";
  }
}

void SetStamp(int64_t time_ns, google::protobuf::Timestamp& stamp) {
  const int64_t t = std::max<int64_t>(0, time_ns);
  stamp.set_seconds(t / 1'000'000'000);
  stamp.set_nanos(static_cast<int32_t>(t % 1'000'000'000));
}

bool ValidRigName(const std::string& rig) {
  if (rig.empty() || rig.size() > 64) return false;
  for (const char c : rig) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

}  // namespace

std::vector<std::string> FlightLogOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (!ValidRigName(rig)) {
    problems.push_back("rig: 1..64 of [A-Za-z0-9_-], a topic's first part (got '" + rig + "')");
  }
  AppendPrefixed(problems, "mcap.", mcap.Validate());
  return problems;
}

FlightLog::FlightLog(std::string path, FlightLogOptions options,
                     std::unique_ptr<mcap::Writer> writer)
    : path_(std::move(path)), options_(std::move(options)), writer_(std::move(writer)) {}

FlightLog::~FlightLog() {
  if (Status closed = Close(); !closed.ok()) {
    std::fprintf(stderr, "stevi: %s\n", closed.error().message.c_str());
  }
}

Result<std::unique_ptr<FlightLog>> FlightLog::Create(
    const std::string& path, FlightLogOptions options,
    const std::map<std::string, std::string>& metadata) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  Result<std::unique_ptr<mcap::Writer>> writer = mcap::Writer::Create(path, options.mcap);
  if (!writer.ok()) return writer.error();
  std::unique_ptr<FlightLog> log(
      new FlightLog(path, std::move(options), std::move(writer).value()));
  if (Status written = log->writer_->AddMetadata("stevi", metadata); !written.ok()) {
    return written.error();
  }
  return log;
}

uint16_t FlightLog::Channel(const std::string& topic, const google::protobuf::Descriptor* type) {
  if (const auto it = channels_.find(topic); it != channels_.end()) return it->second;
  const uint16_t schema =
      writer_->AddSchema(type->full_name(), "protobuf", to_foxglove::FileDescriptorSetFor(type));
  const uint16_t id = writer_->AddChannel(schema, topic, "protobuf");
  channels_.emplace(topic, id);
  return id;
}

Status FlightLog::Write(const std::string& topic, const google::protobuf::Message& message,
                        int64_t unix_time_ns) {
  const uint16_t channel = Channel(topic, message.GetDescriptor());
  const uint64_t t = LogTime(unix_time_ns);
  Status written = writer_->Write(channel, t, t, message.SerializeAsString());
  if (written.ok()) ++counts_.messages;
  return written;
}

Status FlightLog::AddFrame(const v1::TrackFrame& frame) {
  const int64_t t = FrameTime(frame.capture_unix_time_ns(), frame.capture_time_ns());
  const std::string p = "/" + options_.rig;
  if (Status s = Write(p + "/tracks", frame, t); !s.ok()) return s;
  ++counts_.track_frames;
  if (Status s = Write(p + "/annotations", to_foxglove::ToImageAnnotations(frame, image_scale_), t);
      !s.ok()) {
    return s;
  }
  if (Status s = Write(p + "/scene", to_foxglove::ToSceneUpdate(frame, CameraFrame(options_)), t);
      !s.ok()) {
    return s;
  }
  foxglove::LocationFix fix;
  if (to_foxglove::ToLocationFix(frame, VehicleFrame(options_), fix)) {
    if (Status s = Write(p + "/vehicle", fix, t); !s.ok()) return s;
    ++counts_.vehicle_fixes;
  }
  return Status::Ok();
}

bool FlightLog::ImageDue(v1::PreviewKind kind, const v1::TrackFrame& frame) const {
  const int64_t t = FrameTime(frame.capture_unix_time_ns(), frame.capture_time_ns());
  if (options_.image_hz <= 0 || ImageTopic(options_, kind).empty()) return false;
  const auto it = image_pace_.find(kind);
  if (it == image_pace_.end()) return true;
  // As the preview hub paces: one image with the first frame at or past each slot of a grid of
  // multiples of the period, so that the mean rate is the one asked for whatever the frame rate.
  // A capture time going back (a new source) starts again.
  return t >= it->second.next_due_ns || t < it->second.last_ns;
}

Status FlightLog::AddImage(const v1::Preview& preview) {
  const std::string topic = ImageTopic(options_, preview.kind());
  if (options_.image_hz <= 0) {
    return FailedPrecondition("flight log: images are off (image_hz 0)");
  }
  if (topic.empty()) {
    return InvalidArgument(
        "flight log: only the left and the disparity images are kept (got kind " +
        v1::PreviewKind_Name(preview.kind()) + ")");
  }
  const int64_t t = FrameTime(preview.capture_unix_time_ns(), preview.capture_time_ns());
  foxglove::CompressedImage image = to_foxglove::ToCompressedImage(preview, CameraFrame(options_));
  SetStamp(t, *image.mutable_timestamp());  // the log time, also without a Unix time
  if (Status s = Write(topic, image, t); !s.ok()) return s;
  const auto period_ns = static_cast<int64_t>(std::llround(1e9 / options_.image_hz));
  int64_t slot = t / period_ns;
  if (t % period_ns < 0) --slot;  // floor, also before the epoch
  image_pace_[preview.kind()] = ImagePace{t, (slot + 1) * period_ns};
  if (preview.scale() > 0) image_scale_ = preview.scale();
  ++counts_.images;
  return Status::Ok();
}

Status FlightLog::AddEncodedImage(v1::PreviewKind kind, const std::string& format,
                                  const std::string& data, int64_t time_ns) {
  const std::string topic = ImageTopic(options_, kind);
  if (topic.empty()) {
    return InvalidArgument(
        "flight log: only the left and the disparity images are kept (got kind " +
        v1::PreviewKind_Name(kind) + ")");
  }
  foxglove::CompressedImage image;
  SetStamp(time_ns, *image.mutable_timestamp());
  image.set_frame_id(CameraFrame(options_));
  image.set_format(format);
  image.set_data(data);
  if (Status s = Write(topic, image, time_ns); !s.ok()) return s;
  ++counts_.images;
  return Status::Ok();
}

Status FlightLog::AddVehicleState(const v1::VehicleState& state) {
  if (Status s =
          Write("/" + options_.rig + "/vehicle",
                to_foxglove::ToLocationFix(state, VehicleFrame(options_)), state.unix_time_ns());
      !s.ok()) {
    return s;
  }
  ++counts_.vehicle_fixes;
  return Status::Ok();
}

Status FlightLog::AddStatus(const google::protobuf::Message& status, int64_t unix_time_ns) {
  if (Status s = Write("/" + options_.rig + "/status", status, unix_time_ns); !s.ok()) return s;
  ++counts_.statuses;
  return Status::Ok();
}

Status FlightLog::AddAttachment(const std::string& name, const std::string& media_type,
                                int64_t unix_time_ns, const std::string& data) {
  return writer_->AddAttachment(name, media_type, LogTime(unix_time_ns), data);
}

Status FlightLog::Close() { return writer_->Close(); }

FlightLogCounts FlightLog::counts() const {
  FlightLogCounts c = counts_;
  c.bytes = writer_->bytes();
  return c;
}

}  // namespace stevi::drivers
