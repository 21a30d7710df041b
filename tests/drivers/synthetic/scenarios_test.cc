// The evaluation scenarios of the synthetic renderer and its terrain (hills, ground marks): every
// scenario is usable (valid, obstacles resolvable and in frame), the hard parts are really there,
// the terrain's truth is exact, and the default scene still renders as before.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/core/utility.hpp>

#include "drivers/synthetic/synthetic_source.h"
#include "tests/drivers/synthetic/frame_hash.h"

namespace stevi::drivers {
namespace {

// The default rig of every scenario.
constexpr double kF = 700.0;
constexpr double kFB = 700.0 * 0.6;
constexpr double kCx = 320.0;
constexpr double kCy = 240.0;

// The scenario of that name (a copy: EvaluationScenarios() returns a temporary).
Scenario Get(const std::string& name) {
  for (Scenario& s : EvaluationScenarios()) {
    if (s.name == name) return std::move(s);
  }
  ADD_FAILURE() << "no scenario " << name;
  return Scenario{};
}

using fixtures::HashFrame;
using fixtures::kFnvOffset;

// The disparity of the flat ground on row v (0 above the horizon), as the renderer stores it.
float GroundDisparity(double camera_height_m, int v) {
  if (v <= kCy) return 0.0f;
  const double b = (v - kCy) / kF;
  return static_cast<float>(kFB / (camera_height_m / b));
}

// Terrain pixels that are hills: object_id 0 and nearer than the flat ground of their row.
cv::Mat1b HillMask(const FrameTruth& truth, double camera_height_m) {
  cv::Mat1b mask(truth.object_id.size(), uint8_t{0});
  for (int v = 0; v < mask.rows; ++v) {
    const float ground = GroundDisparity(camera_height_m, v);
    for (int u = 0; u < mask.cols; ++u) {
      if (truth.object_id(v, u) == 0 && truth.disparity_px(v, u) > ground + 1e-4f) {
        mask(v, u) = 255;
      }
    }
  }
  return mask;
}

// Independent ray-ellipsoid test (plain quadratic in long double): depth of the nearest hit of
// the left ray through pixel (u, v) with any hill, infinity when none.
double NearestHillDepth(const Scene& scene, int u, int v) {
  const long double a = (u - kCx) / kF, b = (v - kCy) / kF;
  long double best = std::numeric_limits<long double>::infinity();
  for (const Hill& hill : scene.hills) {
    const long double dx = a / hill.radii_m[0], dy = b / hill.radii_m[1],
                      dz = 1.0L / hill.radii_m[2];
    const long double ox = -hill.centre_m[0] / hill.radii_m[0],
                      oy = -hill.centre_m[1] / hill.radii_m[1],
                      oz = -hill.centre_m[2] / hill.radii_m[2];
    const long double qa = dx * dx + dy * dy + dz * dz;
    const long double qb = 2.0L * (ox * dx + oy * dy + oz * dz);
    const long double qc = ox * ox + oy * oy + oz * oz - 1.0L;
    const long double disc = qb * qb - 4.0L * qa * qc;
    if (disc < 0) continue;
    const long double t = (-qb - std::sqrt(disc)) / (2.0L * qa);
    if (t > 0.01L && t < best) best = t;
  }
  return static_cast<double>(best);
}

// Pixels between two boxes: the larger of the horizontal and vertical gaps (<= 0: they touch or
// overlap in both directions).
int BoxGap(const cv::Rect& a, const cv::Rect& b) {
  const int gap_u = std::max(a.x, b.x) - std::min(a.x + a.width, b.x + b.width);
  const int gap_v = std::max(a.y, b.y) - std::min(a.y + a.height, b.y + b.height);
  return std::max(gap_u, gap_v);
}

TEST(EvaluationScenarios, AreNamedValidAndDescribed) {
  const std::vector<Scenario> scenarios = EvaluationScenarios();
  std::set<std::string> names;
  for (const Scenario& s : scenarios) {
    SCOPED_TRACE(s.name);
    names.insert(s.name);
    EXPECT_TRUE(s.options.Validate().empty()) << s.options.Validate().front();
    EXPECT_GT(s.description.size(), 100u);
    EXPECT_GE(s.frames, 40);
    EXPECT_LE(s.frames, 80);
    EXPECT_EQ(s.options.fps, 10.0);
    EXPECT_EQ(s.options.f_px, kF);
    EXPECT_EQ(s.options.baseline_m, 0.6);
    EXPECT_FALSE(s.options.scene.obstacles.empty());
  }
  EXPECT_EQ(names.size(), scenarios.size()) << "names must be unique";
  for (const char* name : {"clear_sky", "low_over_ground", "small_far", "close_pair",
                           "low_contrast", "tower_on_ground"}) {
    EXPECT_EQ(names.count(name), 1u) << name;
  }
  // Seeded differently: no two scenarios share their noise.
  std::set<uint64_t> seeds;
  for (const Scenario& s : scenarios) seeds.insert(s.options.seed);
  EXPECT_EQ(seeds.size(), scenarios.size());
}

// Over every frame: each obstacle is resolvable (every visible pixel has >= 8 px of disparity),
// mostly in frame, and the camera heights are as described.
TEST(EvaluationScenarios, ObstaclesAreResolvableAndInFrame) {
  for (const Scenario& s : EvaluationScenarios()) {
    SCOPED_TRACE(s.name);
    const SyntheticRenderer renderer(s.options);
    std::map<int, int> visible_frames;
    for (int64_t k = 0; k < s.frames; ++k) {
      const FrameTruth truth = renderer.Truth(k);
      ASSERT_EQ(truth.obstacles.size(), s.options.scene.obstacles.size());
      for (const ObstacleTruth& o : truth.obstacles) {
        if (o.visible_px == 0) continue;
        ++visible_frames[o.id];
        double min_disparity = 0;
        cv::minMaxLoc(truth.disparity_px, &min_disparity, nullptr, nullptr, nullptr,
                      truth.object_id == o.id);
        EXPECT_GE(min_disparity, 8.0) << o.name << " at frame " << k;
        EXPECT_GE(kFB / o.depth_m, 8.0) << o.name << " at frame " << k;
      }
    }
    for (const Obstacle& ob : s.options.scene.obstacles) {
      // Mostly in frame: visible in at least 90 % of the frames.
      EXPECT_GE(visible_frames[ob.id], s.frames * 9 / 10) << ob.name;
    }
  }
  EXPECT_GE(Get("clear_sky").options.scene.camera_height_m, 100.0);
  EXPECT_NEAR(Get("low_over_ground").options.scene.camera_height_m, 3.0, 1.0);
  EXPECT_NEAR(Get("tower_on_ground").options.scene.camera_height_m, 5.0, 0.5);
}

TEST(EvaluationScenarios, RenderEveryFrameKind) {
  for (const Scenario& s : EvaluationScenarios()) {
    SCOPED_TRACE(s.name);
    const SyntheticRenderer renderer(s.options);
    for (int64_t k : {int64_t{0}, int64_t{s.frames - 1}}) {
      FrameTruth truth;
      const StereoFrame frame = renderer.Render(k, &truth);
      ASSERT_EQ(frame.left.size(), cv::Size(640, 480));
      ASSERT_EQ(frame.right.size(), cv::Size(640, 480));
      cv::Scalar mean, stddev;
      cv::meanStdDev(frame.left, mean, stddev);
      EXPECT_GT(stddev[0], 10.0) << "frame " << k << " looks blank";
      // The cheap truth agrees with Render's.
      const FrameTruth alone = renderer.Truth(k);
      EXPECT_EQ(cv::countNonZero(alone.object_id != truth.object_id), 0);
      EXPECT_EQ(cv::countNonZero(alone.disparity_px != truth.disparity_px), 0);
    }
  }
}

TEST(EvaluationScenarios, RenderTheSameOnAnyNumberOfThreads) {
  const SyntheticRenderer renderer(Get("low_over_ground").options);
  const StereoFrame a = renderer.Render(5);
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const StereoFrame b = renderer.Render(5);
  cv::setNumThreads(threads);
  EXPECT_EQ(cv::countNonZero(a.left != b.left), 0);
  EXPECT_EQ(cv::countNonZero(a.right != b.right), 0);
}

TEST(ClearSky, EveryObstacleIsAgainstTheSky) {
  const Scenario s = Get("clear_sky");
  const SyntheticRenderer renderer(s.options);
  EXPECT_GE(s.options.scene.obstacles.size(), 3u);
  EXPECT_LE(s.options.scene.obstacles.size(), 5u);
  for (int64_t k = 0; k < s.frames; k += 10) {
    const FrameTruth truth = renderer.Truth(k);
    for (const ObstacleTruth& o : truth.obstacles) {
      if (o.visible_px == 0) continue;
      SCOPED_TRACE(o.name + " at frame " + std::to_string(k));
      EXPECT_GE(o.depth_m, 15.0);
      EXPECT_LE(o.depth_m, 50.0);
      // Entirely above the horizon row, so the sky is all around it.
      EXPECT_LT(o.bbox.y + o.bbox.height, kCy);
    }
  }
}

// Ground, hills and marks cover much of the image; the near hill has obstacle-like disparities;
// the runway paint is there.
TEST(LowOverGround, TerrainIsLargeAndAsNearAsTheObstacles) {
  const Scenario s = Get("low_over_ground");
  const Scene& scene = s.options.scene;
  EXPECT_GE(scene.hills.size(), 3u);
  EXPECT_FALSE(scene.marks.empty());
  EXPECT_FALSE(scene.dashed_lines.empty());
  const SyntheticRenderer renderer(s.options);
  FrameTruth truth;
  const StereoFrame frame = renderer.Render(0, &truth);

  const int pixels = truth.object_id.rows * truth.object_id.cols;
  const int terrain = cv::countNonZero(truth.object_id == 0);
  EXPECT_GE(terrain, pixels * 2 / 5) << "ground + hills + marks";

  double min_obstacle = std::numeric_limits<double>::infinity(), max_obstacle = 0;
  for (const ObstacleTruth& o : truth.obstacles) {
    ASSERT_GT(o.visible_px, 0) << o.name;
    double lo = 0, hi = 0;
    cv::minMaxLoc(truth.disparity_px, &lo, &hi, nullptr, nullptr, truth.object_id == o.id);
    min_obstacle = std::min(min_obstacle, lo);
    max_obstacle = std::max(max_obstacle, hi);
  }
  const cv::Mat1b hills = HillMask(truth, scene.camera_height_m);
  const int hill_px = cv::countNonZero(hills);
  EXPECT_GT(hill_px, pixels / 10);
  const cv::Mat obstacle_like =
      (truth.disparity_px >= min_obstacle) & (truth.disparity_px <= max_obstacle) & hills;
  EXPECT_GT(cv::countNonZero(obstacle_like), 1000)
      << "hill pixels with disparity within the obstacles' " << min_obstacle << ".." << max_obstacle
      << " px";

  // One aircraft flies low: just above the horizon, in front of terrain (not the sky).
  const ObstacleTruth* low = nullptr;
  for (const ObstacleTruth& o : truth.obstacles) {
    if (o.bbox.y + o.bbox.height <= kCy && o.bbox.y + o.bbox.height > kCy - 20) low = &o;
  }
  ASSERT_NE(low, nullptr) << "no obstacle just above the horizon";
  const cv::Rect above(low->bbox.x, low->bbox.y - 3, low->bbox.width, 3);
  EXPECT_GT(cv::countNonZero(hills(above)), above.area() / 2)
      << low->name << " should have the ridge behind it";

  // The marks: bright (albedo ~0.9) terrain pixels below the horizon, which no other terrain
  // reaches: without the marks there are none.
  auto bright_ground = [&](const StereoFrame& f, const FrameTruth& t) {
    const cv::Rect below(0, 241, 640, 239);
    return cv::countNonZero((f.left(below) >= 220) & (t.object_id(below) == 0));
  };
  EXPECT_GT(bright_ground(frame, truth), 2000);
  SyntheticOptions unmarked = s.options;
  unmarked.scene.marks.clear();
  unmarked.scene.dashed_lines.clear();
  FrameTruth unmarked_truth;
  const StereoFrame unmarked_frame = SyntheticRenderer(unmarked).Render(0, &unmarked_truth);
  EXPECT_EQ(bright_ground(unmarked_frame, unmarked_truth), 0);
  // Marks change the images only, never the truth.
  EXPECT_EQ(cv::countNonZero(unmarked_truth.disparity_px != truth.disparity_px), 0);
  EXPECT_EQ(cv::countNonZero(unmarked_truth.object_id != truth.object_id), 0);
}

// Every terrain pixel's truth against an independent intersection of the left ray with the hills
// and the ground plane.
TEST(Hills, TruthDisparityIsTheRayEllipsoidHit) {
  for (const char* name : {"low_over_ground", "tower_on_ground"}) {
    SCOPED_TRACE(name);
    const Scenario s = Get(name);
    const Scene& scene = s.options.scene;
    const FrameTruth truth = SyntheticRenderer(s.options).Truth(7);
    int hill_checked = 0, ground_checked = 0;
    double worst = 0;
    for (int v = 0; v < 480; v += 3) {
      for (int u = 0; u < 640; u += 3) {
        const double hill_t = NearestHillDepth(scene, u, v);
        const double ground_t = v > kCy ? scene.camera_height_m / ((v - kCy) / kF)
                                        : std::numeric_limits<double>::infinity();
        const double t = std::min(hill_t, ground_t);
        if (truth.object_id(v, u) > 0) {
          // An obstacle in front of the terrain.
          EXPECT_LE(kFB / truth.disparity_px(v, u), t * (1 + 1e-6)) << u << "," << v;
          continue;
        }
        if (!std::isfinite(t)) {
          EXPECT_EQ(truth.object_id(v, u), -1) << u << "," << v;
          continue;
        }
        ASSERT_EQ(truth.object_id(v, u), 0) << u << "," << v;
        const double error = std::abs(truth.disparity_px(v, u) - kFB / t);
        worst = std::max(worst, error);
        EXPECT_LT(error, 1e-4) << "pixel (" << u << ", " << v << ")";
        ++(hill_t < ground_t ? hill_checked : ground_checked);
      }
    }
    EXPECT_GT(hill_checked, 3000);
    EXPECT_GT(ground_checked, 3000);
    RecordProperty(std::string(name) + "_worst_px", std::to_string(worst));
  }
}

// The hills' texture is attached to the world: a hill pixel's grey shows at the right image's
// pixel shifted by its disparity (up to the sub-pixel phase), which stereo needs.
TEST(Hills, RightImageMatchesTheLeftAtTheTruthDisparity) {
  SyntheticOptions o = Get("low_over_ground").options;
  o.noise_sigma = 0.0;
  o.scene.obstacles.clear();
  FrameTruth truth;
  const StereoFrame frame = SyntheticRenderer(o).Render(0, &truth);
  const cv::Mat1b left = frame.left, right = frame.right;
  const cv::Mat1b hills = HillMask(truth, o.scene.camera_height_m);
  double exact = 0, off = 0;
  int n = 0;
  for (int v = 0; v < 480; ++v) {
    for (int u = 80; u < 640; ++u) {
      if (hills(v, u) == 0) continue;
      const float d = truth.disparity_px(v, u);
      const double ur = u - d;
      const int u0 = static_cast<int>(std::floor(ur));
      if (u0 < 2) continue;
      // Only interior hill pixels (the hill on both sides), away from silhouettes.
      if (hills(v, u - 2) == 0 || hills(v, std::min(u + 2, 639)) == 0) continue;
      const double w = ur - u0;
      const double interpolated = (1 - w) * right(v, u0) + w * right(v, u0 + 1);
      exact += std::abs(interpolated - left(v, u));
      off += std::abs(int{right(v, u0 - 2)} - int{left(v, u)});
      ++n;
    }
  }
  ASSERT_GT(n, 10000);
  EXPECT_LT(exact / n, 1.0) << "mean |difference| at the truth disparity";
  EXPECT_GT(off / n, 2.0 * exact / n) << "a 2 px error must be clearly worse";
}

// On the flat marked ground the right image is the left shifted by the (row-constant) truth
// disparity, marks included: rows where that disparity is a whole number of pixels, noise 0.
TEST(GroundMarks, RightImageIsLeftShiftedByTheTruthDisparity) {
  SyntheticOptions o = Get("low_over_ground").options;
  o.noise_sigma = 0.0;
  o.scene.obstacles.clear();
  o.scene.hills.clear();
  ASSERT_EQ(o.scene.camera_height_m, 3.0);  // disparity 0.2 (v - 240) px: whole every 5 rows
  FrameTruth truth;
  const StereoFrame frame = SyntheticRenderer(o).Render(0, &truth);
  const cv::Mat1b left = frame.left, right = frame.right;
  int rows = 0, bright = 0, worst = 0, n = 0;
  double exact = 0, off_by_one = 0;
  for (int v = 245; v < 480; v += 5) {
    const float d_truth = truth.disparity_px(v, 320);
    const int d = static_cast<int>(std::lround(d_truth));
    ASSERT_NEAR(d_truth, d, 1e-4) << "row " << v;
    ++rows;
    for (int u = d + 1; u < 640; ++u) {
      ASSERT_EQ(truth.object_id(v, u), 0);
      if (left(v, u) >= 220) ++bright;
      const int diff = std::abs(int{right(v, u - d)} - int{left(v, u)});
      worst = std::max(worst, diff);
      exact += diff;
      off_by_one += std::abs(int{right(v, u - d - 1)} - int{left(v, u)});
      ++n;
    }
  }
  EXPECT_EQ(rows, 47);
  EXPECT_GT(bright, 500) << "the compared rows must contain paint";
  EXPECT_LE(worst, 1);
  EXPECT_LT(exact / n, 0.05);
  EXPECT_GT(off_by_one / n, 0.5);
}

// The default scene (the server's demo) renders byte-identically to before hills and ground
// marks were added.
TEST(DefaultScene, RendersAsBeforeTheTerrainFeatures) {
  // FNV-1a of left, right, truth disparity and truth ids, computed on the renderer before the
  // terrain change (RelWithDebInfo, g++ 12, x86-64).
  const std::map<int64_t, uint64_t> expected = {
      {0, 0xED624F7FCFB69EE7ull}, {37, 0xF3E01F837B1DC76Dull}, {150, 0xDF0A14DD81ED2CB0ull}};
  const SyntheticRenderer renderer{SyntheticOptions{}};
  EXPECT_TRUE(renderer.options().scene.hills.empty());
  EXPECT_TRUE(renderer.options().scene.marks.empty());
  EXPECT_TRUE(renderer.options().scene.dashed_lines.empty());
  for (const auto& [index, hash] : expected) {
    FrameTruth truth;
    const StereoFrame f = renderer.Render(index, &truth);
    const uint64_t h = HashFrame(kFnvOffset, f, truth);
    EXPECT_EQ(h, hash) << "frame " << index;
  }
}

TEST(ClosePair, ObstaclesAreCloseInTheImageAtDifferentDepths) {
  const Scenario s = Get("close_pair");
  ASSERT_EQ(s.options.scene.obstacles.size(), 2u);
  const SyntheticRenderer renderer(s.options);
  int close = 0, overlapping = 0;
  for (int64_t k = 0; k < s.frames; ++k) {
    const FrameTruth truth = renderer.Truth(k);
    const ObstacleTruth& a = truth.obstacles[0];
    const ObstacleTruth& b = truth.obstacles[1];
    if (a.visible_px == 0 || b.visible_px == 0) continue;
    const int gap = BoxGap(a.bbox, b.bbox);
    close += gap <= 8 ? 1 : 0;
    overlapping += (a.bbox & b.bbox).area() > 0 ? 1 : 0;
    const double nearer = std::min(a.depth_m, b.depth_m), farther = std::max(a.depth_m, b.depth_m);
    EXPECT_GT(farther, 1.3 * nearer) << "frame " << k;
  }
  EXPECT_GE(close, s.frames / 2);
  EXPECT_GT(overlapping, 0);
  EXPECT_LT(overlapping, s.frames) << "the gap case must be there too";
}

TEST(SmallFar, TheFarAircraftIsSmallWithEightToTenPixelsOfDisparity) {
  const Scenario s = Get("small_far");
  const SyntheticRenderer renderer(s.options);
  for (int64_t k = 0; k < s.frames; k += 5) {
    const FrameTruth truth = renderer.Truth(k);
    ASSERT_EQ(truth.obstacles.size(), 2u);
    const ObstacleTruth& small = truth.obstacles[0];
    const ObstacleTruth& near = truth.obstacles[1];
    SCOPED_TRACE("frame " + std::to_string(k));
    EXPECT_GE(kFB / small.depth_m, 8.0);
    EXPECT_LE(kFB / small.depth_m, 10.0);
    EXPECT_NEAR(small.bbox.width, 20, 3);
    EXPECT_NEAR(small.bbox.height, 8, 2);
    EXPECT_LT(near.depth_m, 20.0);
  }
}

// The pale obstacle differs from the sky around it by ~0.05..0.08 in mean grey, but its texture
// has enough contrast for stereo.
TEST(LowContrast, ObstaclesAreCloseToTheSkyButTextured) {
  const Scenario s = Get("low_contrast");
  FrameTruth truth;
  const StereoFrame frame = SyntheticRenderer(s.options).Render(20, &truth);
  for (const ObstacleTruth& o : truth.obstacles) {
    SCOPED_TRACE(o.name);
    ASSERT_GT(o.visible_px, 0);
    cv::Scalar mean, stddev;
    cv::meanStdDev(frame.left, mean, stddev, truth.object_id == o.id);
    // The sky beside it: the same rows, 10 px either side.
    const cv::Rect left_band(o.bbox.x - 10, o.bbox.y, 10, o.bbox.height);
    const cv::Rect right_band(o.bbox.x + o.bbox.width, o.bbox.y, 10, o.bbox.height);
    const double sky =
        (cv::mean(frame.left(left_band))[0] + cv::mean(frame.left(right_band))[0]) / 2.0;
    const double difference = std::abs(mean[0] - sky) / 255.0;
    EXPECT_GT(difference, 0.04);
    EXPECT_LT(difference, 0.085);
    EXPECT_GT(stddev[0] / 255.0, 0.03) << "texture for stereo";
  }
}

TEST(TowerOnGround, TheTowerStandsOnTheGround) {
  const Scenario s = Get("tower_on_ground");
  const Scene& scene = s.options.scene;
  FrameTruth truth;
  (void)SyntheticRenderer(s.options).Render(0, &truth);
  EXPECT_FALSE(scene.marks.empty());
  const Obstacle* tower = nullptr;
  const ObstacleTruth* tower_truth = nullptr;
  for (size_t i = 0; i < scene.obstacles.size(); ++i) {
    if (scene.obstacles[i].name == "tower") {
      tower = &scene.obstacles[i];
      tower_truth = &truth.obstacles[i];
    }
  }
  ASSERT_NE(tower, nullptr);
  // Its bottom is on the ground plane, 30..45 m away.
  EXPECT_DOUBLE_EQ(tower->path.start[1] + tower->size_m[1] / 2, scene.camera_height_m);
  EXPECT_GE(tower_truth->depth_m, 30.0);
  EXPECT_LE(tower_truth->depth_m, 45.0);
  // Below its foot is ground at about its depth.
  const int foot = tower_truth->bbox.y + tower_truth->bbox.height;
  const int u = tower_truth->bbox.x + tower_truth->bbox.width / 2;
  EXPECT_EQ(truth.object_id(foot, u), 0);
  EXPECT_NEAR(truth.disparity_px(foot, u), kFB / tower_truth->depth_m, 0.5);
  EXPECT_GT(tower_truth->bbox.height, 200);
}

}  // namespace
}  // namespace stevi::drivers

namespace stevi::drivers {
namespace {

// Every evaluation and tracking scenario, and the flight, renders byte-identically to the renderer
// before the pitch, composite obstacles, clouds and sensor effects were added (all of them default
// to off). Frames 0 and 7 of each.
TEST(EveryScenario, RendersAsBeforeTheRendererExtensions) {
  // FNV-1a of left, right, truth disparity and truth ids, computed on the renderer before the
  // extensions (RelWithDebInfo, g++ 12, x86-64).
  const std::map<std::string, uint64_t> expected = {
      {"clear_sky", 0x39BB9675D81BBF9Full},
      {"low_over_ground", 0x64D00D860775A25Bull},
      {"small_far", 0x3404099C835268CEull},
      {"close_pair", 0xCD986D06B4B22478ull},
      {"low_contrast", 0x5A366E621ACB004Full},
      {"tower_on_ground", 0xE0390A2A7C8DC611ull},
      {"crossing_occlusion", 0x7736AFE06846E8C1ull},
      {"entries_exits", 0x787510FD6DE6FB81ull},
      {"head_on", 0x9FBEA25253A5941ull},
      {"departing", 0xD64FEFFC0AAD457Dull},
      {"flight", 0x3941B1F4CE493CB6ull},
      // Scenes added after the renderer extensions: pinned as first rendered.
      {"crossing", 0x9266D5D67AA7CDDDull},
      {"occlusion", 0xE9102887032340DAull},
  };
  std::vector<Scenario> all = EvaluationScenarios();
  for (Scenario& s : TrackingScenarios()) all.push_back(std::move(s));
  all.push_back(FlightScenario());
  for (const Scenario& s : all) {
    const SyntheticRenderer renderer(s.options);
    uint64_t h = kFnvOffset;
    for (int64_t index : {0, 7}) {
      FrameTruth truth;
      const StereoFrame f = renderer.Render(index, &truth);
      h = HashFrame(h, f, truth);
    }
    const auto it = expected.find(s.name);
    if (it == expected.end()) {
      ADD_FAILURE() << "no expected hash for " << s.name << ": {\"" << s.name << "\", 0x"
                    << std::hex << std::uppercase << h << "ull},";
      continue;
    }
    EXPECT_EQ(h, it->second) << s.name;
  }
}

}  // namespace
}  // namespace stevi::drivers
