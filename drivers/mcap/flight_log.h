// A flight as an MCAP file that Foxglove opens: the channels `stevi station` serves, with the same
// topics, schemas and messages (proto/foxglove/convert.h), written through the MCAP writer. Used by
// stevi-server --record-mcap, stevi-process --mcap and stevi export --format mcap.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <google/protobuf/message.h>

#include "core/common/error.h"
#include "core/common/fields.h"
#include "drivers/mcap/mcap_writer.h"
#include "stevi/v1/geo.pb.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::drivers {

struct FlightLogOptions {
  // The rig's name: topics are "/RIG/tracks", "/RIG/image/left", ... as the station names them.
  std::string rig = "rig1";
  // Images (left and disparity) per second of each kind, on capture time; 0 = no images.
  double image_hz = 5;
  mcap::WriterOptions mcap;

  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.McapRecordConfig (its file, compression and chunk span are the
  // server's).
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Text(s.rig, Field("rig", "", "the topics' first part"));
    v.Number(s.image_hz, Field("image_hz", "Hz",
                               "left and disparity images per second of each kind in the MCAP "
                               "file, on capture time; 0 = none")
                             .In(0, 30)
                             .Flag("mcap-image-hz", "N"));
  }
};

// The counts of what was written, for status and the closing message.
struct FlightLogCounts {
  uint64_t track_frames = 0;
  uint64_t images = 0;
  uint64_t vehicle_fixes = 0;
  uint64_t statuses = 0;
  uint64_t messages = 0;  // every MCAP message, all channels
  uint64_t bytes = 0;     // the file's size so far
};

// Thread-compatible: one thread at a time (the server's writer thread, stevi-process's loop).
// Channels are created on first use, so a flight without images has no image channels. Every
// message is logged at its capture's Unix time (TrackFrame.capture_unix_time_ns), the time
// Foxglove's timeline shows; a frame without one (image files) at its capture time.
class FlightLog {
 public:
  // Creates PATH (never over an existing file: kAlreadyExists) and writes the metadata "stevi"
  // (`metadata`: the source, the version, what the operator should know).
  static Result<std::unique_ptr<FlightLog>> Create(
      const std::string& path, FlightLogOptions options,
      const std::map<std::string, std::string>& metadata);
  ~FlightLog();
  FlightLog(const FlightLog&) = delete;
  FlightLog& operator=(const FlightLog&) = delete;

  // A processed frame: /RIG/tracks (stevi.v1.TrackFrame as is), /RIG/annotations (the boxes, in
  // the pixels of the last image written), /RIG/scene (tracks in 3-D) and, when the frame is
  // georeferenced, /RIG/vehicle (foxglove.LocationFix).
  Status AddFrame(const v1::TrackFrame& frame);
  // True when an image of `kind` of `frame` is due (image_hz, on the frames' log time): the caller
  // then renders and encodes it, and passes it to AddImage. Never for kinds a flight log does not
  // keep (only the left and the disparity image). A caller that gets its images already paced
  // (the server, from its preview hub) need not ask.
  bool ImageDue(v1::PreviewKind kind, const v1::TrackFrame& frame) const;
  // A JPEG preview as foxglove.CompressedImage on /RIG/image/left or /RIG/image/disparity.
  Status AddImage(const v1::Preview& preview);
  // An image in its own encoding ("png": a recording's lossless frames, "jpeg"), as
  // foxglove.CompressedImage on the kind's topic, stamped `time_ns`.
  Status AddEncodedImage(v1::PreviewKind kind, const std::string& format, const std::string& data,
                         int64_t time_ns);
  // A vehicle state (a recording's, between the frames) on /RIG/vehicle.
  Status AddVehicleState(const v1::VehicleState& state);
  // A status message on /RIG/status, with its own schema (stevi.v1.ServerStatus for the server).
  Status AddStatus(const google::protobuf::Message& status, int64_t unix_time_ns);
  // A file to keep with the flight (the calibration YAML), as an MCAP attachment.
  Status AddAttachment(const std::string& name, const std::string& media_type, int64_t unix_time_ns,
                       const std::string& data);

  // Finishes the file (summary and index: Foxglove opens it at once and can seek). Idempotent;
  // the destructor closes too.
  Status Close();

  FlightLogCounts counts() const;
  const std::string& path() const { return path_; }

 private:
  FlightLog(std::string path, FlightLogOptions options, std::unique_ptr<mcap::Writer> writer);
  // The channel of `topic`, created (with the schema of `type`) on first use.
  uint16_t Channel(const std::string& topic, const google::protobuf::Descriptor* type);
  Status Write(const std::string& topic, const google::protobuf::Message& message,
               int64_t unix_time_ns);

  std::string path_;
  FlightLogOptions options_;
  std::unique_ptr<mcap::Writer> writer_;
  std::map<std::string, uint16_t> channels_;  // topic -> channel id
  struct ImagePace {
    int64_t last_ns = 0;      // capture time of the last image written
    int64_t next_due_ns = 0;  // the capture time from which the next one is due
  };
  std::map<v1::PreviewKind, ImagePace> image_pace_;
  double image_scale_ = 1;  // JPEG pixels per frame pixel, of the last image
  FlightLogCounts counts_;
};

}  // namespace stevi::drivers
