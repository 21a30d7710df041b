#include "tests/testing/tracking_eval.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>

#include "core/pipeline/pipeline.h"

namespace stevi::testing {
namespace {

// The truth's position_cam_m: the centre of the face towards the camera.
cv::Vec3d FrontFaceCentre(const drivers::Obstacle& obstacle, double t_s) {
  return obstacle.path.PositionAt(t_s) - cv::Vec3d(0.0, 0.0, 0.5 * obstacle.size_m[2]);
}

const drivers::Obstacle* FindObstacle(const drivers::Scene& scene, int id) {
  for (const drivers::Obstacle& o : scene.obstacles) {
    if (o.id == id) return &o;
  }
  return nullptr;
}

}  // namespace

RenderedScenario RenderScenario(const drivers::Scenario& scenario, int max_frames) {
  RenderedScenario rendered;
  rendered.scenario = scenario;
  const int frames = max_frames > 0 ? std::min(max_frames, scenario.frames) : scenario.frames;
  drivers::SyntheticRenderer renderer(scenario.options);
  rendered.rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
  rendered.frames.reserve(frames);
  rendered.truths.resize(frames);
  for (int k = 0; k < frames; ++k) {
    rendered.frames.push_back(renderer.Render(k, &rendered.truths[k]));
    rendered.truths[k].disparity_px.release();
    rendered.truths[k].object_id.release();
  }
  return rendered;
}

cv::Rect ProjectedBox(const drivers::Obstacle& obstacle, double t_s,
                      const geometry::StereoRig& rig) {
  const cv::Vec3d centre = obstacle.path.PositionAt(t_s);
  double u_min = std::numeric_limits<double>::infinity(), u_max = -u_min;
  double v_min = u_min, v_max = -u_min;
  for (int corner = 0; corner < 8; ++corner) {
    const cv::Vec3d p(centre[0] + ((corner & 1) ? 0.5 : -0.5) * obstacle.size_m[0],
                      centre[1] + ((corner & 2) ? 0.5 : -0.5) * obstacle.size_m[1],
                      centre[2] + ((corner & 4) ? 0.5 : -0.5) * obstacle.size_m[2]);
    if (!(p[2] > 1e-3)) return {};
    const double u = rig.cx() + rig.f_px() * p[0] / p[2];
    const double v = rig.cy() + rig.f_px() * p[1] / p[2];
    u_min = std::min(u_min, u);
    u_max = std::max(u_max, u);
    v_min = std::min(v_min, v);
    v_max = std::max(v_max, v);
  }
  // Pixel (u, v) sees the ray through its centre: the box covers the pixels whose centres fall
  // inside the projection (the truth's visible boxes follow the same rule).
  const auto px = [](double x) { return static_cast<int>(std::clamp(x, -1e6, 1e6)); };
  const int u0 = px(std::ceil(u_min)), u1 = px(std::floor(u_max));
  const int v0 = px(std::ceil(v_min)), v1 = px(std::floor(v_max));
  if (u1 < u0 || v1 < v0) return {};
  return {u0, v0, u1 - u0 + 1, v1 - v0 + 1};
}

cv::Vec3d PathVelocity(const drivers::Path& path, double t_s) {
  switch (path.kind) {
    case drivers::Path::Kind::kStatic: return {0.0, 0.0, 0.0};
    case drivers::Path::Kind::kLinear: return path.velocity_mps;
    case drivers::Path::Kind::kCircle: {
      const double angle = path.phase_rad + path.angular_rate_rad_s * t_s;
      const double speed = path.radius_m * path.angular_rate_rad_s;
      return {-speed * std::sin(angle), 0.0, speed * std::cos(angle)};
    }
  }
  return {0.0, 0.0, 0.0};
}

std::optional<double> TruthTimeToCollision(const drivers::Obstacle& obstacle, double t_s) {
  const cv::Vec3d p = FrontFaceCentre(obstacle, t_s);
  const cv::Vec3d v = PathVelocity(obstacle.path, t_s);
  const double speed2 = v.dot(v);
  if (!(speed2 > 1e-12)) return std::nullopt;
  const double t_closest = -p.dot(v) / speed2;
  if (!(t_closest > 0)) return std::nullopt;
  if (cv::norm(p + v * t_closest) > kCollisionCourseM) return std::nullopt;
  return t_closest;
}

std::vector<MotTruth> ScoringTruth(const drivers::FrameTruth& truth,
                                   const drivers::SyntheticOptions& options,
                                   const geometry::StereoRig& rig) {
  const double fB = rig.f_px() * rig.baseline_m();
  std::vector<MotTruth> out;
  out.reserve(truth.obstacles.size());
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    MotTruth m;
    m.id = o.id;
    m.expected =
        o.visible_px >= kMinVisiblePx && o.depth_m > 0 && fB / o.depth_m >= kMinDisparityPx;
    m.box = o.bbox;
    m.range_m = o.range_m;
    if (const drivers::Obstacle* obstacle = FindObstacle(options.scene, o.id)) {
      m.full_box = ProjectedBox(*obstacle, truth.t_s, rig);
      m.time_to_collision_s = TruthTimeToCollision(*obstacle, truth.t_s);
    }
    out.push_back(m);
  }
  return out;
}

std::vector<MotTrack> ScoringTracks(const std::vector<tracking::Track>& tracks) {
  std::vector<MotTrack> out;
  for (const tracking::Track& t : tracks) {
    if (t.state == tracking::TrackState::kTentative) continue;
    MotTrack m;
    m.id = t.id;
    m.box = t.detection.bbox;
    m.measured = t.misses == 0;
    m.hits = t.hits;
    m.range_m = t.range_m;
    m.smoothed_range_m = t.smoothed_range_m;
    m.time_to_collision_s = t.time_to_collision_s;
    out.push_back(m);
  }
  return out;
}

Result<TrackingRun> RunTracking(const RenderedScenario& rendered,
                                const pipeline::PipelineConfig& config) {
  TrackingRun run;
  run.algorithm = std::string(pipeline::AlgorithmName(config.algorithm));
  pipeline::Pipeline pipe;
  const pipeline::Snapshot snapshot{std::make_shared<const pipeline::PipelineConfig>(config),
                                    rendered.rig};
  MotAccumulator mot(MotOptions{.min_iou = kMinIoU, .min_ttc_hits = kMinTtcHits});
  run.frames.reserve(rendered.frames.size());
  for (size_t k = 0; k < rendered.frames.size(); ++k) {
    Result<pipeline::FrameResult> result = pipe.Process(rendered.frames[k], snapshot);
    if (!result.ok()) {
      return Error{result.error().code, rendered.scenario.name + " frame " + std::to_string(k) +
                                            ": " + result.error().message};
    }
    TrackedFrame frame;
    frame.detections = std::move(result->detections);
    frame.tracks = std::move(result->tracks);
    frame.truths = ScoringTruth(rendered.truths[k], rendered.scenario.options, *rendered.rig);
    frame.scored = mot.AddFrame(frame.truths, ScoringTracks(frame.tracks));
    run.frames.push_back(std::move(frame));
  }
  run.summary = mot.summary();
  return run;
}

}  // namespace stevi::testing
