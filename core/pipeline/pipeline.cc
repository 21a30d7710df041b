#include "core/pipeline/pipeline.h"

#include "core/common/format.h"

#include <chrono>
#include <string>
#include <utility>

#include <GeographicLib/LocalCartesian.hpp>
#include <opencv2/imgproc.hpp>

#include "core/detection/canonical.h"
#include "core/geo/mount.h"
#include "core/geo/vehicle_state.h"

namespace stevi::pipeline {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Converts an already rectified 8-bit image to grey into `out` (reused when it fits).
// Returns false for types other than CV_8UC1 / CV_8UC3 / CV_8UC4.
bool ToGrey(const cv::Mat& in, cv::Mat& out) {
  switch (in.type()) {
    case CV_8UC1: in.copyTo(out); return true;
    case CV_8UC3: cv::cvtColor(in, out, cv::COLOR_BGR2GRAY); return true;
    case CV_8UC4: cv::cvtColor(in, out, cv::COLOR_BGRA2GRAY); return true;
    default: return false;
  }
}

// `in` as grey into `out`: `in` itself when it is grey and may be read in place (`in_place`),
// else converted into `buffer`. `name` says which image an error is about.
Status GreyOf(const cv::Mat& in, bool in_place, const char* name, cv::Mat& buffer, cv::Mat& out) {
  if (in_place && in.type() == CV_8UC1) {
    out = in;  // only read: no copy needed
    return Status::Ok();
  }
  if (!ToGrey(in, buffer)) {
    return InvalidArgument(std::string(name) + ": unsupported image type " +
                           cv::typeToString(in.type()) + " (want CV_8UC1, CV_8UC3 or CV_8UC4)");
  }
  out = buffer;
  return Status::Ok();
}

}  // namespace

// A frame's images through the front end: the processed (binned) pair, and the full-resolution
// left and right the detectors range on.
struct FrameImages {
  cv::Mat rect_left;        // processed left: published in the FrameResult
  cv::Mat rect_right;       // processed right: only read
  cv::Mat full_left;        // the camera-resolution rectified left: only read
  cv::Mat rect_right_full;  // the camera-resolution rectified right: only read
};

namespace {

// The range options of the processed (binned) images: the disparity floor (camera pixels) divided
// by the binning.
geometry::RangeOptions ProcessedRange(const PipelineConfig& config, int factor) {
  geometry::RangeOptions range = config.range;
  range.min_disparity_px /= factor;
  return range;
}

// Stage: extract. The detectors work on the processed (binned) images, where the disparity floor
// (camera pixels) is divided by the binning; each hypothesis is then ranged on the camera's own
// images.
void Extract(const PipelineConfig& config, int factor, const FrameImages& images,
             const stereo::DisparityMap& trusted,
             const std::optional<detection::GroundPlane>& ground, FrameResult& result) {
  const geometry::StereoRig& work_rig = *result.rig;
  const geometry::RangeOptions range = ProcessedRange(config, factor);
  detection::FullResolutionPair full;
  if (factor > 1) {
    full.left = images.full_left;
    full.right = images.rect_right_full;
  } else {
    full.left = images.rect_left;
    full.right = images.rect_right;
  }
  full.binning = factor;
  if (full.left.type() != CV_8UC1 || full.right.type() != CV_8UC1) full = {};
  const cv::Mat& rect_left = images.rect_left;
  switch (config.algorithm) {
    case Algorithm::kCanonical:
      result.detections =
          detection::DetectCanonical(trusted, work_rig, range, config.canonical, &full);
      break;
    case Algorithm::kSteViE:
      result.detections =
          detection::DetectSteViE(rect_left, trusted, work_rig, range, config.stevie, &full);
      break;
    case Algorithm::kSteViS:
      result.detections =
          detection::DetectSteViS(rect_left, trusted, work_rig, range, config.stevis, &full);
      break;
    case Algorithm::kStixels: {
      // The group support is in camera pixels: a binned pixel stands for factor^2 of them.
      detection::StixelOptions stixels = config.stixels;
      stixels.min_support_px /= static_cast<double>(factor) * factor;
      result.stixels =
          detection::ComputeStixels(result.disparity, work_rig, ground, range, stixels);
      result.detections = detection::ObstaclesFromStixels(
          *result.stixels, result.disparity, rect_left, work_rig, ground, range, stixels);
      break;
    }
  }
}

// The vehicle's down axis in the camera frame: from the mount, and from the autopilot's attitude
// at the capture time when a pose is known (a level vehicle otherwise).
Eigen::Vector3d DownInCam(const PipelineConfig& config, const Snapshot& snapshot,
                          const StereoFrame& frame) {
  const Eigen::Isometry3d body_from_cam = geo::BodyFromCam(config.mount);
  Eigen::Vector3d down_in_body = Eigen::Vector3d::UnitZ();
  if (snapshot.pose_at) {
    const geo::PoseLookup lookup = snapshot.pose_at(frame.t_ns, frame.unix_time_ns);
    if (lookup.ok()) {
      down_in_body = geo::NedFromBody(lookup.pose->state).conjugate() * Eigen::Vector3d::UnitZ();
    }
  }
  return body_from_cam.linear().transpose() * down_in_body;
}

// Stage: ground. One plane per frame, fitted to the processed disparity with the vehicle's down
// axis as its prior: the stixel world and the range scan share it (core/detection/README.md).
std::optional<detection::GroundPlane> Ground(const PipelineConfig& config, int factor,
                                             const Snapshot& snapshot, const StereoFrame& frame,
                                             const stereo::DisparityMap& trusted,
                                             const FrameResult& result) {
  const geometry::RangeOptions range = ProcessedRange(config, factor);
  return detection::FitGroundPlane(trusted, *result.rig, DownInCam(config, snapshot, frame),
                                   range.min_disparity_px, config.range_scan.ground);
}

// Stage: scan. The range scan of the processed disparity, leaving out the frame's ground plane.
detection::RangeScan Scan(const PipelineConfig& config, int factor,
                          const stereo::DisparityMap& trusted,
                          const std::optional<detection::GroundPlane>& ground,
                          const FrameResult& result) {
  const geometry::RangeOptions range = ProcessedRange(config, factor);
  const Eigen::Isometry3d body_from_cam = geo::BodyFromCam(config.mount);
  return detection::ComputeRangeScan(trusted, *result.rig, range, body_from_cam, ground,
                                     config.range_scan);
}

}  // namespace

struct FrontEnd::State {
  // The matcher and the options it was built with (rebuilt when they change).
  std::unique_ptr<stereo::DisparityMatcher> matcher;
  stereo::MatcherOptions matcher_options;
  // Rectified right image: only read during Prepare(), so its buffer is reused frame to frame.
  // (The rectified left image is published in the FrameResult and gets a fresh buffer.)
  cv::Mat rect_right;
  // Binning (PipelineConfig::max_width_px): the full-size rectified left image (only when it had
  // to be made), the binned right image, and the binned rig of the snapshot rig `binned_from` by
  // `binned_factor` (rebuilt when either changes).
  cv::Mat full_left;
  cv::Mat binned_right;
  std::shared_ptr<const geometry::StereoRig> binned_from;
  int binned_factor = 1;
  std::shared_ptr<const geometry::StereoRig> binned_rig;

  // Stage: rectify, then bin by `factor` (PipelineConfig::max_width_px): `images` and, when
  // binning, result.rig and result.binning. The published left image is a fresh buffer; when
  // binning, the full-size left is only read (the caller's grey image, or a buffer kept between
  // frames) and the binned one is published.
  Status Rectify(const StereoFrame& frame, const Snapshot& snapshot, int factor,
                 FrameImages& images, FrameResult& result);
  // Stage: disparity, with the matcher rebuilt when its options changed.
  Status ComputeDisparity(const stereo::MatcherOptions& options, const FrameImages& images,
                          FrameResult& result);
};

Status FrontEnd::State::Rectify(const StereoFrame& frame, const Snapshot& snapshot, int factor,
                                FrameImages& images, FrameResult& result) {
  const geometry::StereoRig& rig = *snapshot.rig;
  cv::Mat& full_out = factor > 1 ? full_left : images.rect_left;
  cv::Mat& out_left = images.full_left;  // never written to from here
  cv::Mat& out_right =
      images.rect_right;  // a view of frame.right or of rect_right; never written to
  if (frame.rectified) {
    // The left is published: read in place only when binning makes a fresh image of it.
    Status status = GreyOf(frame.left, factor > 1, "frame.left", full_out, out_left);
    if (!status.ok()) return status;
    status = GreyOf(frame.right, true, "frame.right", rect_right, out_right);
    if (!status.ok()) return status;
  } else {
    Status status = rig.Rectify(frame.left, frame.right, full_out, rect_right);
    if (!status.ok()) return status.error();
    out_left = full_out;
    out_right = rect_right;
  }
  // From here on the frame is the binned one, with its own rig.
  images.rect_right_full = out_right;
  if (factor > 1) {
    if (binned_from != snapshot.rig || binned_factor != factor) {
      binned_rig = std::make_shared<const geometry::StereoRig>(rig.Binned(factor));
      binned_from = snapshot.rig;
      binned_factor = factor;
    }
    geometry::BinImage(out_left, factor, images.rect_left);
    geometry::BinImage(out_right, factor, binned_right);
    out_right = binned_right;
    result.rig = binned_rig;
    result.binning = factor;
  }
  return Status::Ok();
}

Status FrontEnd::State::ComputeDisparity(const stereo::MatcherOptions& options,
                                         const FrameImages& images, FrameResult& result) {
  if (matcher == nullptr || !(matcher_options == options)) {
    const std::vector<std::string> problems = options.Validate();
    if (!problems.empty()) {
      std::vector<std::string> prefixed;
      AppendPrefixed(prefixed, "matcher.", problems);
      return InvalidArgument(prefixed);
    }
    matcher = stereo::MakeMatcher(options);
    matcher_options = options;
  }
  result.disparity = matcher->Compute(images.rect_left, images.rect_right);
  return Status::Ok();
}

FrontEnd::FrontEnd() : state_(std::make_unique<State>()) {}
FrontEnd::~FrontEnd() = default;

struct Pipeline::State {
  FrontEnd front;
  // Tracks across frames; created at the first frame with the config's options.
  std::unique_ptr<tracking::Tracker> tracker;
  // Rebuilt when the mount changes.
  std::unique_ptr<geo::Georeferencer> georeferencer;
  // The last frame's pose when it was found, and that frame's capture time: with this frame's
  // pose, the camera's motion between the two for the tracker.
  std::optional<geo::VehiclePose> previous_pose;
  int64_t previous_pose_t_ns = 0;

  // The tracker with the config's options (created at the first frame, its options replaced when
  // they change); kInvalidArgument naming the fields when they are invalid.
  Status ConfigureTracker(const tracking::TrackerOptions& options);
  // The georeferencer of the mount (rebuilt when it changes); kInvalidArgument naming the fields
  // when the mount is invalid.
  Status ConfigureGeoreferencer(const geo::MountOptions& mount);
  // The camera's motion from the previous frame to this one (`result`: its capture time and pose),
  // when both poses were found and the frames are 0 < gap <= tracking.max_dt_s apart; remembers
  // this frame's pose for the next.
  std::optional<tracking::EgoMotion> EgoMotionSincePrevious(const FrameResult& result,
                                                            const PipelineConfig& config);
  // cam_now_from_cam_prev of two vehicle poses and the mount: both cams into the local NED tangent
  // plane at the previous pose (GeographicLib::LocalCartesian, whose ENU is turned to NED). The
  // tangent planes of the two poses differ by their distance over the Earth's radius (1.6e-7 rad
  // a metre), which is neglected.
  static Eigen::Isometry3d CamNowFromCamPrev(const geo::VehiclePose& prev,
                                             const geo::VehiclePose& now,
                                             const geo::MountOptions& mount);
  // Stage: geo. Each track's WGS84 position with the frame's pose (result.pose, found).
  void Georeference(FrameResult& result) const;
};

Status Pipeline::State::ConfigureTracker(const tracking::TrackerOptions& options) {
  if (tracker != nullptr && tracker->options() == options) return Status::Ok();
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) {
    std::vector<std::string> prefixed;
    AppendPrefixed(prefixed, "tracking.", problems);
    return InvalidArgument(prefixed);
  }
  if (tracker == nullptr) {
    tracker = std::make_unique<tracking::Tracker>(options);
  } else {
    tracker->SetOptions(options);
  }
  return Status::Ok();
}

Status Pipeline::State::ConfigureGeoreferencer(const geo::MountOptions& mount) {
  if (georeferencer != nullptr && georeferencer->mount() == mount) return Status::Ok();
  const std::vector<std::string> problems = mount.Validate();
  if (!problems.empty()) {
    std::vector<std::string> prefixed;
    AppendPrefixed(prefixed, "mount.", problems);
    return InvalidArgument(prefixed);
  }
  georeferencer = std::make_unique<geo::Georeferencer>(mount);
  return Status::Ok();
}

std::optional<tracking::EgoMotion> Pipeline::State::EgoMotionSincePrevious(
    const FrameResult& result, const PipelineConfig& config) {
  std::optional<tracking::EgoMotion> ego;
  const bool found = result.pose.has_value() && result.pose->ok() && result.pose->pose;
  if (found && previous_pose) {
    const double gap_s = static_cast<double>(result.capture_time_ns - previous_pose_t_ns) * 1e-9;
    if (gap_s > 0 && gap_s <= config.tracking.max_dt_s) {
      ego = tracking::EgoMotion{.cam_now_from_cam_prev = CamNowFromCamPrev(
                                    *previous_pose, *result.pose->pose, config.mount)};
    }
  }
  if (found) {
    previous_pose = *result.pose->pose;
    previous_pose_t_ns = result.capture_time_ns;
  } else {
    previous_pose.reset();
  }
  return ego;
}

Eigen::Isometry3d Pipeline::State::CamNowFromCamPrev(const geo::VehiclePose& prev,
                                                     const geo::VehiclePose& now,
                                                     const geo::MountOptions& mount) {
  const GeographicLib::LocalCartesian enu_at_prev(prev.state.lat_deg, prev.state.lon_deg,
                                                  prev.state.alt_m);
  double east = 0, north = 0, up = 0;
  enu_at_prev.Forward(now.state.lat_deg, now.state.lon_deg, now.state.alt_m, east, north, up);
  Eigen::Isometry3d ned_from_body_prev = Eigen::Isometry3d::Identity();
  ned_from_body_prev.linear() = geo::NedFromBody(prev.state).toRotationMatrix();
  Eigen::Isometry3d ned_from_body_now = Eigen::Isometry3d::Identity();
  ned_from_body_now.linear() = geo::NedFromBody(now.state).toRotationMatrix();
  ned_from_body_now.translation() = Eigen::Vector3d(north, east, -up);
  const Eigen::Isometry3d body_from_cam = geo::BodyFromCam(mount);
  return (ned_from_body_now * body_from_cam).inverse() * ned_from_body_prev * body_from_cam;
}

void Pipeline::State::Georeference(FrameResult& result) const {
  result.track_geo.assign(result.tracks.size(), std::nullopt);
  if (!result.pose || !result.pose->ok() || !result.pose->pose) return;
  for (size_t i = 0; i < result.tracks.size(); ++i) {
    const tracking::Track& track = result.tracks[i];
    geo::PointInCam point;
    point.position_m =
        Eigen::Vector3d(track.position_cam_m[0], track.position_cam_m[1], track.position_cam_m[2]);
    point.velocity_mps = Eigen::Vector3d(track.velocity_cam_mps[0], track.velocity_cam_mps[1],
                                         track.velocity_cam_mps[2]);
    point.covariance_m2 = geo::DiagonalCovariance(track.position_sigma_m);
    Result<geo::GeoPoint> geo_point = georeferencer->Georeference(*result.pose->pose, point);
    if (geo_point.ok()) result.track_geo[i] = std::move(geo_point).value();
  }
}

Pipeline::Pipeline() : state_(std::make_unique<State>()) {}
Pipeline::~Pipeline() = default;

Result<FrameResult> Pipeline::Process(const StereoFrame& frame, const Snapshot& snapshot) {
  Result<PreparedFrame> prepared = Prepare(frame, snapshot);
  if (!prepared.ok()) return prepared.error();
  return Finish(std::move(prepared).value(), snapshot);
}

Result<PreparedFrame> Pipeline::Prepare(const StereoFrame& frame, const Snapshot& snapshot) {
  return state_->front.Prepare(frame, snapshot);
}

Result<PreparedFrame> FrontEnd::Prepare(const StereoFrame& frame, const Snapshot& snapshot) {
  const Clock::time_point start = Clock::now();
  if (snapshot.config == nullptr) return InvalidArgument("snapshot.config: is null");
  if (snapshot.rig == nullptr) return InvalidArgument("snapshot.rig: is null (no calibration)");
  const PipelineConfig& config = *snapshot.config;
  const geometry::StereoRig& rig = *snapshot.rig;

  const cv::Size want = rig.image_size();
  if (frame.left.empty()) return InvalidArgument("frame.left: image is empty");
  if (frame.right.empty()) return InvalidArgument("frame.right: image is empty");
  if (frame.left.size() != want || frame.right.size() != want) {
    return InvalidArgument("frame: left image is " + SizeText(frame.left.size()) +
                           " and right image is " + SizeText(frame.right.size()) +
                           ", but the rig '" + rig.calibration_id() + "' expects " +
                           SizeText(want));
  }

  PreparedFrame prepared;
  FrameResult& result = prepared.result;
  result.capture_time_ns = frame.t_ns;
  result.capture_unix_time_ns = frame.unix_time_ns;
  result.source_index = frame.index;
  result.pair_skew_ns = frame.pair_skew_ns;
  result.algorithm = config.algorithm;
  result.rig = snapshot.rig;
  result.timings.reserve(7);

  Clock::time_point t = Clock::now();
  const int factor =
      geometry::BinningFactor(want.width, config.max_width_px, config.range.min_disparity_px);
  FrameImages images;
  Status status = state_->Rectify(frame, snapshot, factor, images, result);
  if (!status.ok()) return status.error();
  result.timings.push_back({"rectify", MsSince(t)});

  t = Clock::now();
  status = state_->ComputeDisparity(config.matcher, images, result);
  if (!status.ok()) return status.error();
  result.timings.push_back({"disparity", MsSince(t)});

  // What the consumers that read no confidence see: the disparities the matcher is sure of.
  const stereo::DisparityMap trusted =
      stereo::TrustedOnly(result.disparity, config.range.min_confidence);
  const bool needs_ground = config.algorithm == Algorithm::kStixels || config.range_scan.enabled;
  if (needs_ground && config.range_scan.ground.enabled) {
    t = Clock::now();
    result.ground = Ground(config, factor, snapshot, frame, trusted, result);
    result.timings.push_back({"ground", MsSince(t)});
  }

  t = Clock::now();
  Extract(config, factor, images, trusted, result.ground, result);
  result.timings.push_back({"extract", MsSince(t)});

  if (config.range_scan.enabled) {
    t = Clock::now();
    result.range_scan = Scan(config, factor, trusted, result.ground, result);
    result.timings.push_back({"scan", MsSince(t)});
  }
  result.rectified_left = std::move(images.rect_left);
  prepared.ms = MsSince(start);
  return prepared;
}

Result<FrameResult> Pipeline::Finish(PreparedFrame prepared, const Snapshot& snapshot) {
  const Clock::time_point start = Clock::now();
  if (snapshot.config == nullptr) return InvalidArgument("snapshot.config: is null");
  if (snapshot.rig == nullptr) return InvalidArgument("snapshot.rig: is null (no calibration)");
  const PipelineConfig& config = *snapshot.config;
  FrameResult result = std::move(prepared.result);
  // The rig the frame was processed with: the binned one when the frame was binned.
  const geometry::StereoRig& rig = result.rig ? *result.rig : *snapshot.rig;

  // Stage: track.
  Clock::time_point t = Clock::now();
  if (Status status = state_->ConfigureTracker(config.tracking); !status.ok()) {
    return status.error();
  }
  // The pose at the capture, looked up once, before tracking: with the last frame's, it gives the
  // tracker the camera's motion. Kept for the geo stage, and timed with it.
  double geo_ms = 0;
  if (snapshot.pose_at) {
    const Clock::time_point g = Clock::now();
    if (Status status = state_->ConfigureGeoreferencer(config.mount); !status.ok()) {
      return status.error();
    }
    result.pose = snapshot.pose_at(result.capture_time_ns, result.capture_unix_time_ns);
    geo_ms = MsSince(g);
  }
  const std::optional<tracking::EgoMotion> ego = state_->EgoMotionSincePrevious(result, config);
  const tracking::CameraModel camera{rig.f_px(),
                                     rig.cx(),
                                     rig.cy(),
                                     rig.baseline_m(),
                                     rig.image_size().width,
                                     rig.image_size().height};
  result.tracks = state_->tracker->Update(result.detections, result.capture_time_ns, camera, ego);
  result.timings.push_back({"track", MsSince(t) - geo_ms});

  // The tracks in the body frame (the mount alone: no pose needed).
  const Eigen::Isometry3d body_from_cam = geo::BodyFromCam(config.mount);
  result.track_position_body_m.clear();
  result.track_position_body_m.reserve(result.tracks.size());
  for (const tracking::Track& track : result.tracks) {
    const Eigen::Vector3d p =
        body_from_cam *
        Eigen::Vector3d(track.position_cam_m[0], track.position_cam_m[1], track.position_cam_m[2]);
    result.track_position_body_m.emplace_back(p.x(), p.y(), p.z());
  }

  // Stage: geo.
  if (snapshot.pose_at) {
    t = Clock::now();
    state_->Georeference(result);
    result.timings.push_back({"geo", geo_ms + MsSince(t)});
  }

  result.frame_id = next_frame_id_++;
  result.timings.push_back({"total", prepared.ms + MsSince(start)});
  return result;
}

}  // namespace stevi::pipeline
