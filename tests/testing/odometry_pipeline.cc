#include "tests/testing/odometry_pipeline.h"

#include <algorithm>
#include <memory>
#include <string>

#include <GeographicLib/LocalCartesian.hpp>

#include "core/geometry/stereo_rig.h"
#include "core/pipeline/pipeline.h"

namespace stevi::testing {
namespace {

// NED (and body) from the camera axes: north/forward = z, east/right = x, down = y.
const cv::Matx33d kNedFromCamAxes(0, 0, 1, 1, 0, 0, 0, 1, 0);

cv::Vec3d NedPosition(const OdometrySequence& sequence, int k) {
  return kNedFromCamAxes * sequence.poses[static_cast<size_t>(k)].t;
}

}  // namespace

geo::VehicleState VehicleStateOfFrame(const OdometrySequence& sequence, int k) {
  const CamPose& pose = sequence.poses[static_cast<size_t>(k)];
  const cv::Matx33d ned_from_body = kNedFromCamAxes * pose.R * kNedFromCamAxes.t();
  Eigen::Matrix3d m;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m(r, c) = ned_from_body(r, c);
  }
  const geo::EulerDeg euler = geo::EulerFromNedFromBody(Eigen::Quaterniond(m).normalized());
  const cv::Vec3d ned = NedPosition(sequence, k);
  const GeographicLib::LocalCartesian origin(kOdometryOriginLatDeg, kOdometryOriginLonDeg,
                                             kOdometryOriginAltM);
  geo::VehicleState s;
  s.t_ns = static_cast<int64_t>(1e9 * k / sequence.fps);
  origin.Reverse(ned[1], ned[0], -ned[2], s.lat_deg, s.lon_deg, s.alt_m);
  s.roll_deg = euler.roll_deg;
  s.pitch_deg = euler.pitch_deg;
  s.yaw_deg = euler.yaw_deg;
  const int a = std::max(0, k - 1), b = std::min(sequence.frames() - 1, k + 1);
  if (b > a) {
    const cv::Vec3d v = (NedPosition(sequence, b) - NedPosition(sequence, a)) * sequence.fps /
                        static_cast<double>(b - a);
    s.velocity_ned_mps = Eigen::Vector3d(v[0], v[1], v[2]);
  }
  return s;
}

Result<std::vector<OdometryFrame>> RunOdometrySequence(const OdometrySequence& sequence,
                                                       const OdometryRunOptions& options) {
  pipeline::PipelineConfig config = pipeline::ConfigForAlgorithm(options.algorithm);
  if (options.max_width_px) config.max_width_px = *options.max_width_px;
  if (std::vector<std::string> problems = pipeline::ApplySettings(config, options.settings);
      !problems.empty()) {
    return InvalidArgument("settings: " + problems.front());
  }
  const auto rig = std::make_shared<const geometry::StereoRig>(
      geometry::StereoRig::Ideal(sequence.left.front().size(), sequence.f_px, sequence.baseline_m,
                                 sequence.cx, sequence.cy, sequence.name));
  pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config), rig};
  if (options.with_poses) {
    std::vector<geo::VehicleState> states;
    for (int k = 0; k < sequence.frames(); ++k) states.push_back(VehicleStateOfFrame(sequence, k));
    const double fps = sequence.fps;
    snapshot.pose_at = [states, fps](int64_t t_ns, int64_t) {
      geo::PoseLookup lookup;
      const long k = std::lround(static_cast<double>(t_ns) * 1e-9 * fps);
      if (k < 0 || k >= static_cast<long>(states.size())) {
        lookup.message = "no pose for the frame";
        return lookup;
      }
      lookup.status = geo::GeoStatus::kOk;
      lookup.message = "ok";
      geo::VehiclePose pose;
      pose.state = states[static_cast<size_t>(k)];
      pose.state.t_ns = t_ns;
      lookup.pose = pose;
      return lookup;
    };
  }
  pipeline::Pipeline pipe;
  std::vector<OdometryFrame> frames;
  for (int k = 0; k < sequence.frames(); ++k) {
    StereoFrame frame;
    frame.left = sequence.left[static_cast<size_t>(k)];
    frame.right = sequence.right[static_cast<size_t>(k)];
    frame.rectified = true;
    frame.index = k;
    frame.t_ns = static_cast<int64_t>(1e9 * k / sequence.fps);
    frame.unix_time_ns = frame.t_ns;
    Result<pipeline::FrameResult> result = pipe.Process(frame, snapshot);
    if (!result.ok()) {
      return Error{result.error().code,
                   "frame " + std::to_string(k) + ": " + result.error().message};
    }
    OdometryFrame out;
    out.detections = static_cast<int>(result->detections.size());
    out.live_tracks = static_cast<int>(result->tracks.size());
    out.binning = std::max(1, result->binning);
    out.pose_ok = result->pose && result->pose->ok();
    const GeographicLib::LocalCartesian origin(kOdometryOriginLatDeg, kOdometryOriginLonDeg,
                                               kOdometryOriginAltM);
    for (size_t i = 0; i < result->track_geo.size() && i < result->tracks.size(); ++i) {
      const std::optional<geo::GeoPoint>& g = result->track_geo[i];
      if (!g) continue;
      ++out.georeferenced;
      double east = 0, north = 0, up = 0;
      origin.Forward(g->lat_deg, g->lon_deg, g->alt_m, east, north, up);
      const CamPose& pose = sequence.poses[static_cast<size_t>(k)];
      const cv::Vec3d truth = kNedFromCamAxes * pose.ToWorld(result->tracks[i].position_cam_m);
      out.geo_mismatch_m =
          std::max(out.geo_mismatch_m, cv::norm(cv::Vec3d(north, east, -up) - truth));
    }
    for (const pipeline::StageTiming& t : result->timings) {
      if (t.stage == "total") out.total_ms = t.ms;
    }
    for (const detection::Detection& d : result->detections) {
      out.detection_boxes.emplace_back(d.bbox.x * out.binning, d.bbox.y * out.binning,
                                       d.bbox.width * out.binning, d.bbox.height * out.binning);
    }
    for (const tracking::Track& track : result->tracks) {
      if (track.state != tracking::TrackState::kConfirmed) continue;
      const cv::Rect& b = track.detection.bbox;
      const int bin = out.binning;
      out.confirmed.push_back({k, track.id,
                               cv::Rect(b.x * bin, b.y * bin, b.width * bin, b.height * bin),
                               track.position_cam_m, track.position_sigma_m});
    }
    frames.push_back(std::move(out));
  }
  return frames;
}

}  // namespace stevi::testing
