// Assembles the stages: rectify -> disparity -> extract -> detections (and the range scan) ->
// tracks.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/detection/detection.h"
#include "core/detection/range_scan.h"
#include "core/detection/stixels.h"
#include "core/geo/georeferencer.h"
#include "core/geo/pose_buffer.h"
#include "core/geometry/stereo_rig.h"
#include "core/pipeline/config.h"
#include "core/stereo/disparity.h"
#include "core/stereo/matcher.h"
#include "core/tracking/tracker.h"

namespace stevi::pipeline {

struct StageTiming {
  std::string stage;  // "rectify", "disparity", "ground", "extract", "scan", "track", "geo",
                      // "total"
  double ms = 0;
};

// Everything one frame produced. Immutable once published.
struct FrameResult {
  uint64_t frame_id = 0;  // the pipeline's own count, from 1
  int64_t capture_time_ns = 0;
  int64_t capture_unix_time_ns = 0;
  int64_t source_index = 0;
  int64_t pair_skew_ns = 0;  // the frame's right minus left capture time (two cameras)
  Algorithm algorithm = Algorithm::kCanonical;
  std::vector<detection::Detection> detections;
  // Every live track after this frame's detections (tentative, confirmed, coasting), by id.
  std::vector<tracking::Track> tracks;
  // Per track, in the order of `tracks`: its position_cam_m in the body frame (x forward, y right,
  // z down, metres from the vehicle's reference point) through PipelineConfig::mount.
  std::vector<cv::Vec3d> track_position_body_m;
  // The nearest range per azimuth bin in the body frame (PipelineConfig::range_scan); absent when
  // the scan is disabled.
  std::optional<detection::RangeScan> range_scan;
  // The frame's ground plane (processed images), shared by the stixel world and the range scan;
  // absent when neither ran, when range_scan.ground is disabled, or when no plane was found.
  std::optional<detection::GroundPlane> ground;
  // The stixel world (algorithm stixels only).
  std::optional<detection::StixelWorld> stixels;
  // Georeferencing: the vehicle pose looked up at the capture time (absent when there is no pose
  // source), and per track, in the order of `tracks`, its WGS84 position, NED velocity and sigma
  // (absent when the pose was not found or the track could not be georeferenced).
  std::optional<geo::PoseLookup> pose;
  std::vector<std::optional<geo::GeoPoint>> track_geo;
  // The disparity, the rectified left image, the detections' boxes and the tracks' boxes are all
  // in the images the frame was processed at: binned (PipelineConfig::max_width_px) when the
  // camera is wider than that, and `rig` is then the binned rig (StereoRig::Binned).
  stereo::DisparityMap disparity;
  cv::Mat rectified_left;  // 8-bit grey
  std::vector<StageTiming> timings;
  std::shared_ptr<const geometry::StereoRig> rig;  // the rig the frame was processed with
  int binning = 1;  // the binning factor of the processed images (1 = the camera's own)
};

// What one frame is processed with: an immutable config and rig.
struct Snapshot {
  std::shared_ptr<const PipelineConfig> config;
  std::shared_ptr<const geometry::StereoRig> rig;
  // The vehicle pose at a frame's capture, asked with its source time t_ns and its unix_time_ns
  // (the wall clock an autopilot's GNSS-disciplined states share): a pose buffer fed by the
  // autopilot, a fixed pose, or the synthetic rig's own flight. Empty: no georeferencing.
  std::function<geo::PoseLookup(int64_t t_ns, int64_t unix_time_ns)> pose_at = {};
};

// What a frame gives on its own (checks, rectify, disparity, extract, scan), for
// Pipeline::Finish().
struct PreparedFrame {
  FrameResult result;  // the capture fields, rig, algorithm, rectified_left, disparity,
                       // detections, range_scan, timings
  double ms = 0;       // time spent in Prepare()
};

// The part of the pipeline that needs no other frame: checks, rectification, disparity,
// extraction and the range scan. Its state is the matcher and its buffers. Thread-compatible: one
// Prepare() at a time; several FrontEnds may work on different frames at once (the engine runs one
// per core).
class FrontEnd {
 public:
  FrontEnd();
  ~FrontEnd();
  FrontEnd(const FrontEnd&) = delete;
  FrontEnd& operator=(const FrontEnd&) = delete;

  Result<PreparedFrame> Prepare(const StereoFrame& frame, const Snapshot& snapshot);

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// Thread-compatible: call Process() from one thread at a time. Or split it: Prepare() (or the
// Prepare() of FrontEnds of one's own, on other threads) and Finish(), which must take the frames
// in their capture order.
class Pipeline {
 public:
  Pipeline();
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  // Processes one frame. The frame must match the rig's image size (else kInvalidArgument).
  // The matcher is rebuilt only when the matcher options change. The tracker lives across frames:
  // a change of its options, of the algorithm or of the rig keeps the tracks (ids never reuse).
  Result<FrameResult> Process(const StereoFrame& frame, const Snapshot& snapshot);

  // Process() in two halves. Prepare(): this pipeline's own FrontEnd. Finish(): tracking,
  // georeferencing and the frame id (the tracker, the georeferencer), frame after frame in
  // capture order. Give Finish() the same snapshot as Prepare(). The "total" timing is the sum of
  // both halves' work, without the time between them.
  Result<PreparedFrame> Prepare(const StereoFrame& frame, const Snapshot& snapshot);
  Result<FrameResult> Finish(PreparedFrame prepared, const Snapshot& snapshot);

 private:
  struct State;
  std::unique_ptr<State> state_;
  uint64_t next_frame_id_ = 1;
};

}  // namespace stevi::pipeline
