#include "drivers/synthetic/synthetic_source.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/geometry/calibration_io.h"
#include "drivers/synthetic/chessboard_source.h"
#include "tests/testing/truth_match.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

using ::testing::HasSubstr;

// f B of the default rig, pixels x metres.
constexpr double kFB = 700.0 * 0.6;

// A scene with one big fronto-parallel textured box whose front face is at depth_m: it fills
// both views.
SyntheticOptions PlaneOptions(double depth_m, double noise_sigma) {
  SyntheticOptions o;
  o.noise_sigma = noise_sigma;
  o.scene = Scene{};
  Obstacle wall;
  wall.id = 1;
  wall.name = "wall";
  wall.size_m = {400.0, 400.0, 1.0};
  wall.path.start = {0.0, 0.0, depth_m + 0.5};
  wall.albedo = 0.5;
  wall.contrast = 0.45;
  wall.texture_cell_m = 0.15;
  o.scene.obstacles.push_back(wall);
  return o;
}

// Counts the pixels where two 8-bit images differ.
int CountDifferent(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  return cv::countNonZero(diff);
}

const ObstacleTruth* Find(const FrameTruth& truth, const std::string& name) {
  for (const ObstacleTruth& o : truth.obstacles) {
    if (o.name == name) return &o;
  }
  return nullptr;
}

TEST(Render, FrontoParallelPlaneHasExactTruthDisparity) {
  for (double depth_m : {20.0, 7.3}) {
    SCOPED_TRACE("depth " + std::to_string(depth_m) + " m");
    const SyntheticRenderer renderer(PlaneOptions(depth_m, 2.0));
    FrameTruth truth;
    const StereoFrame frame = renderer.Render(0, &truth);
    ASSERT_EQ(frame.left.type(), CV_8UC1);
    ASSERT_EQ(frame.left.size(), cv::Size(640, 480));
    const float expected = static_cast<float>(700.0 * 0.6 / depth_m);
    int wrong_disparity = 0, wrong_id = 0;
    for (int v = 0; v < truth.disparity_px.rows; ++v) {
      for (int u = 0; u < truth.disparity_px.cols; ++u) {
        if (truth.disparity_px(v, u) != expected) ++wrong_disparity;
        if (truth.object_id(v, u) != 1) ++wrong_id;
      }
    }
    EXPECT_EQ(wrong_disparity, 0) << "expected " << expected << " px everywhere";
    EXPECT_EQ(wrong_id, 0);
    ASSERT_EQ(truth.obstacles.size(), 1u);
    EXPECT_EQ(truth.obstacles[0].bbox, cv::Rect(0, 0, 640, 480));
    EXPECT_EQ(truth.obstacles[0].visible_px, 640 * 480);
    EXPECT_DOUBLE_EQ(truth.obstacles[0].depth_m, depth_m);
  }
}

TEST(Render, RightImageIsLeftShiftedByTheDisparity) {
  for (int d : {21, 60}) {
    SCOPED_TRACE("disparity " + std::to_string(d) + " px");
    const SyntheticRenderer renderer(PlaneOptions(kFB / d, 0.0));
    const StereoFrame frame = renderer.Render(3);
    const cv::Mat1b left = frame.left, right = frame.right;

    // The texture must be there, or the comparison proves nothing.
    cv::Scalar mean, stddev;
    cv::meanStdDev(left, mean, stddev);
    EXPECT_GT(stddev[0], 10.0) << "the wall is not textured";

    // right(v, u - d) == left(v, u), and a shift one pixel off is clearly worse.
    int worst = 0, worst_u = -1, worst_v = -1;
    double exact = 0, off_by_one = 0;
    int n = 0;
    for (int v = 0; v < left.rows; ++v) {
      for (int u = d + 1; u < left.cols; ++u) {
        const int diff = std::abs(int{right(v, u - d)} - int{left(v, u)});
        if (diff > worst) {
          worst = diff;
          worst_u = u;
          worst_v = v;
        }
        exact += diff;
        off_by_one += std::abs(int{right(v, u - d - 1)} - int{left(v, u)});
        ++n;
      }
    }
    EXPECT_LE(worst, 1) << "at left pixel (u=" << worst_u << ", v=" << worst_v << ")";
    EXPECT_LT(exact / n, 0.2) << "mean |difference| of the shift by d px";
    EXPECT_GT(off_by_one / n, 1.5) << "mean |difference| of the shift by d+1 px";
  }
}

// Median of OpenCV's own SGBM disparity (not our wrapper) over the interior of a pair.
double SgbmMedianDisparity(const StereoFrame& frame) {
  const int block = 5, num_disparities = 64, margin = 10;
  cv::Ptr<cv::StereoSGBM> sgbm =
      cv::StereoSGBM::create(0, num_disparities, block, 8 * block * block, 32 * block * block, 1,
                             63, 10, 100, 2, cv::StereoSGBM::MODE_SGBM);
  cv::Mat disparity16;
  sgbm->compute(frame.left, frame.right, disparity16);
  std::vector<float> values;
  for (int v = margin; v < disparity16.rows - margin; ++v) {
    for (int u = num_disparities + margin; u < disparity16.cols - margin; ++u) {
      const int16_t raw = disparity16.at<int16_t>(v, u);
      if (raw > 0) values.push_back(raw / 16.0f);
    }
  }
  const size_t interior = static_cast<size_t>(disparity16.rows - 2 * margin) *
                          (disparity16.cols - num_disparities - 2 * margin);
  EXPECT_GT(values.size(), interior * 9 / 10) << "SGBM matched too few pixels";
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

TEST(Render, SemiGlobalMatcherMeasuresTheTruthDisparity) {
  // Planes at non-integer disparities 13.37 + k/8 px, on an awkward image size (non-integer
  // principal point). SGBM's parabola fit has a pixel-locking bias that depends on the
  // fractional disparity (measured up to ~0.26 px here, e.g. 13.37 -> 13.19): each median is
  // bounded by that, and the bias cancels over the sub-pixel phases, so the mean error checks
  // the renderer's sub-pixel geometry tightly.
  double sum_error = 0;
  const int phases = 8;
  for (int k = 0; k < phases; ++k) {
    const double d = 13.37 + k / 8.0;
    SCOPED_TRACE("disparity " + std::to_string(d) + " px");
    SyntheticOptions o = PlaneOptions(kFB / d, 1.0);
    o.width = 331;
    o.height = 247;
    const SyntheticRenderer renderer(o);
    FrameTruth truth;
    const StereoFrame frame = renderer.Render(k, &truth);
    EXPECT_FLOAT_EQ(truth.disparity_px(100, 200), static_cast<float>(d));
    const double median = SgbmMedianDisparity(frame);
    EXPECT_NEAR(median, d, 0.3);
    sum_error += median - d;
  }
  EXPECT_NEAR(sum_error / phases, 0.0, 0.05) << "mean SGBM error over the sub-pixel phases";
}

TEST(Render, IsDeterministic) {
  const SyntheticRenderer renderer{SyntheticOptions{}};
  FrameTruth truth_a, truth_b;
  const StereoFrame a = renderer.Render(17, &truth_a);
  const StereoFrame b = renderer.Render(17, &truth_b);
  EXPECT_EQ(CountDifferent(a.left, b.left), 0);
  EXPECT_EQ(CountDifferent(a.right, b.right), 0);
  EXPECT_EQ(cv::countNonZero(truth_a.object_id != truth_b.object_id), 0);
  EXPECT_EQ(cv::countNonZero(truth_a.disparity_px != truth_b.disparity_px), 0);

  // The number of threads does not change the result.
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  const StereoFrame single = renderer.Render(17);
  cv::setNumThreads(threads);
  EXPECT_EQ(CountDifferent(a.left, single.left), 0);
  EXPECT_EQ(CountDifferent(a.right, single.right), 0);

  // Frame metadata.
  EXPECT_EQ(a.index, 17);
  EXPECT_EQ(a.t_ns, 1'700'000'000);
  EXPECT_EQ(a.unix_time_ns, 0);
  EXPECT_TRUE(a.rectified);
}

TEST(Render, SeedChangesTheNoise) {
  SyntheticOptions other;
  other.seed = 2;
  const StereoFrame a = SyntheticRenderer(SyntheticOptions{}).Render(4);
  const StereoFrame b = SyntheticRenderer(other).Render(4);
  const int pixels = a.left.rows * a.left.cols;
  EXPECT_GT(CountDifferent(a.left, b.left), pixels / 2);
  EXPECT_GT(CountDifferent(a.right, b.right), pixels / 2);
  // The noise of the left and right views is independent, too.
  SyntheticOptions flat = PlaneOptions(20.0, 2.0);
  flat.scene.obstacles.clear();
  const StereoFrame sky = SyntheticRenderer(flat).Render(0);
  EXPECT_GT(CountDifferent(sky.left, sky.right), pixels / 2);
  // Without noise the sky and the ground are the same in both views.
  flat.noise_sigma = 0.0;
  const StereoFrame clean = SyntheticRenderer(flat).Render(0);
  EXPECT_EQ(
      CountDifferent(clean.left(cv::Rect(0, 0, 640, 240)), clean.right(cv::Rect(0, 0, 640, 240))),
      0);
}

TEST(Render, MovingObstaclesMoveAndStaticOnesStay) {
  const SyntheticRenderer renderer{SyntheticOptions{}};
  FrameTruth t0, t1;
  const StereoFrame f0 = renderer.Render(0, &t0);
  const StereoFrame f1 = renderer.Render(10, &t1);
  EXPECT_GT(CountDifferent(f0.left, f1.left), 1000);
  const Scene& scene = renderer.options().scene;
  ASSERT_EQ(t0.obstacles.size(), scene.obstacles.size());
  for (size_t i = 0; i < scene.obstacles.size(); ++i) {
    SCOPED_TRACE(scene.obstacles[i].name);
    const double moved = cv::norm(t1.obstacles[i].position_cam_m - t0.obstacles[i].position_cam_m);
    if (scene.obstacles[i].path.kind == Path::Kind::kStatic) {
      EXPECT_EQ(moved, 0.0);
    } else {
      EXPECT_GT(moved, 0.5);
      EXPECT_NE(t0.obstacles[i].bbox, t1.obstacles[i].bbox);
    }
  }
}

TEST(Path, PositionAtFollowsEachKind) {
  Path linear;
  linear.kind = Path::Kind::kLinear;
  linear.start = {1, 2, 3};
  linear.velocity_mps = {2, 0, -1};
  linear.period_s = 10;
  EXPECT_LT(cv::norm(linear.PositionAt(2.5) - cv::Vec3d(6, 2, 0.5)), 1e-12);
  EXPECT_LT(cv::norm(linear.PositionAt(12.5) - cv::Vec3d(6, 2, 0.5)), 1e-12);  // wrapped
  linear.period_s = 0;
  EXPECT_LT(cv::norm(linear.PositionAt(12.5) - cv::Vec3d(26, 2, -9.5)), 1e-12);

  Path circle;
  circle.kind = Path::Kind::kCircle;
  circle.start = {0, -3, 30};
  circle.radius_m = 5;
  circle.angular_rate_rad_s = M_PI / 2;
  circle.phase_rad = 0;
  EXPECT_LT(cv::norm(circle.PositionAt(0) - cv::Vec3d(5, -3, 30)), 1e-12);
  EXPECT_LT(cv::norm(circle.PositionAt(1) - cv::Vec3d(0, -3, 35)), 1e-12);

  Path fixed;
  fixed.start = {4, 5, 6};
  EXPECT_EQ(fixed.PositionAt(100), cv::Vec3d(4, 5, 6));
}

TEST(Truth, MatchesTheObjectIdMapAndTheDisparityMap) {
  const SyntheticRenderer renderer{SyntheticOptions{}};
  const double f = 700.0, cx = 320.0, cy = 240.0;
  int centres_checked = 0;
  for (int64_t index : {0, 37, 60, 95, 120, 155, 190}) {
    SCOPED_TRACE("frame " + std::to_string(index));
    FrameTruth truth;
    (void)renderer.Render(index, &truth);
    EXPECT_EQ(truth.index, index);
    EXPECT_DOUBLE_EQ(truth.t_s, index / 10.0);
    for (const ObstacleTruth& o : truth.obstacles) {
      SCOPED_TRACE(o.name);
      const cv::Mat mask = truth.object_id == o.id;
      EXPECT_EQ(cv::countNonZero(mask), o.visible_px);
      EXPECT_EQ(cv::boundingRect(mask), o.bbox);
      EXPECT_DOUBLE_EQ(o.depth_m, o.position_cam_m[2]);
      EXPECT_NEAR(o.range_m, cv::norm(o.position_cam_m), 1e-9);
      // The centre of the front face: its pixel shows the face at depth_m, unless occluded.
      const int u = static_cast<int>(std::lround(cx + f * o.position_cam_m[0] / o.depth_m));
      const int v = static_cast<int>(std::lround(cy + f * o.position_cam_m[1] / o.depth_m));
      if (u < 0 || v < 0 || u >= 640 || v >= 480 || truth.object_id(v, u) != o.id) continue;
      EXPECT_EQ(truth.disparity_px(v, u), static_cast<float>(kFB / o.depth_m));
      ++centres_checked;
    }
    // The cheap truth-only path agrees with Render's.
    const FrameTruth alone = renderer.Truth(index);
    EXPECT_EQ(cv::countNonZero(alone.object_id != truth.object_id), 0);
    EXPECT_EQ(cv::countNonZero(alone.disparity_px != truth.disparity_px), 0);
    ASSERT_EQ(alone.obstacles.size(), truth.obstacles.size());
    for (size_t i = 0; i < alone.obstacles.size(); ++i) {
      EXPECT_EQ(alone.obstacles[i].bbox, truth.obstacles[i].bbox);
    }
  }
  EXPECT_GT(centres_checked, 20);
}

TEST(Validate, ListsEveryProblem) {
  SyntheticOptions o;
  o.width = 8;
  o.baseline_m = -0.6;
  o.fps = 0;
  o.noise_sigma = -1;
  o.scene.camera_height_m = 0;
  o.scene.obstacles[2].size_m = {1.0, 0.0, 1.0};
  o.scene.obstacles[3].id = o.scene.obstacles[1].id;
  o.scene.obstacles[4].id = 0;
  const std::vector<std::string> problems = o.Validate();
  EXPECT_THAT(
      problems,
      ::testing::UnorderedElementsAre(
          "width: must be in [16, 8192] pixels (got 8)", "baseline_m: must be > 0 m (got -0.6)",
          "fps: must be > 0", "noise_sigma: must be >= 0 grey levels (got -1)",
          "scene.camera_height_m: must be > 0", "scene.obstacles[2].size_m: every side must be > 0",
          HasSubstr("scene.obstacles[3].id: duplicate id"),
          HasSubstr("scene.obstacles[4].id: must be > 0")));

  const auto source = OpenSyntheticSource(o);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument, HasSubstr("width")));
  EXPECT_THAT(source.error().message, HasSubstr("baseline_m"));
  EXPECT_THAT(source.error().message, HasSubstr("scene.obstacles[2].size_m"));

  EXPECT_THAT(SyntheticOptions{}.Validate(), ::testing::IsEmpty());
}

TEST(Validate, ListsEveryTerrainProblem) {
  SyntheticOptions o;
  o.scene.camera_height_m = 3.0;
  Hill good;
  good.centre_m = {0.0, 4.0, 80.0};
  good.radii_m = {20.0, 10.0, 15.0};
  o.scene.hills = {good, good, good, good};
  o.scene.hills[1].radii_m = {20.0, 0.0, 15.0};
  o.scene.hills[1].albedo = 1.5;
  o.scene.hills[2].contrast = -0.1;
  o.scene.hills[2].texture_cell_m = 0.0;
  o.scene.hills[3].centre_m = {0.0, 2.0, 5.0};  // above the ground, and around the camera
  GroundMark mark;
  mark.area_xz_m = cv::Rect2d(-1.0, 10.0, 2.0, 30.0);
  o.scene.marks = {mark, mark};
  o.scene.marks[1].area_xz_m.width = 0.0;
  o.scene.marks[1].albedo = 2.0;
  DashedLine line;
  o.scene.dashed_lines = {line, line};
  o.scene.dashed_lines[1].dash_m = 0.0;
  o.scene.dashed_lines[1].z_end_m = o.scene.dashed_lines[1].z_start_m;
  o.scene.dashed_lines[1].width_m = -1.0;
  EXPECT_THAT(
      o.Validate(),
      ::testing::UnorderedElementsAre(
          "scene.hills[1].radii_m: every radius must be > 0",
          "scene.hills[1].albedo: must be in 0..1", "scene.hills[2].contrast: must be in 0..1",
          "scene.hills[2].texture_cell_m: must be > 0",
          "scene.hills[3].centre_m: must be on or below the ground (y >= camera_height_m)",
          "scene.hills[3].centre_m: the camera (0, 0, 0) must be outside the hill",
          "scene.marks[1].area_xz_m: must be finite with width and height > 0",
          "scene.marks[1].albedo: must be in 0..1", "scene.dashed_lines[1].width_m: must be > 0",
          "scene.dashed_lines[1].z_end_m: must be > z_start_m (may be infinite)",
          "scene.dashed_lines[1].dash_m: must be > 0"));
  o.scene.hills.resize(1);
  o.scene.marks.resize(1);
  o.scene.dashed_lines.resize(1);
  o.scene.dashed_lines[0].z_end_m = std::numeric_limits<double>::infinity();
  EXPECT_THAT(o.Validate(), ::testing::IsEmpty());
}

// A hill is terrain (object_id 0) and hides the ground and the obstacles behind it; an obstacle
// in front of it hides it.
TEST(Render, HillsAreTerrainAndHideWhatIsBehindThem) {
  SyntheticOptions o;
  o.scene = Scene{};
  o.scene.camera_height_m = 3.0;
  Hill hill;
  hill.centre_m = {0.0, 3.0, 60.0};
  hill.radii_m = {20.0, 10.0, 10.0};  // 10 m high, its front foot at 50 m
  o.scene.hills.push_back(hill);
  Obstacle behind;
  behind.id = 1;
  behind.name = "behind";
  behind.size_m = {2.0, 1.0, 1.0};
  behind.path.start = {0.0, -2.0, 80.5};  // the line of sight passes through the hill
  Obstacle front = behind;
  front.id = 2;
  front.name = "front";
  front.path.start = {0.0, -2.0, 30.5};
  o.scene.obstacles = {behind, front};
  FrameTruth truth;
  const StereoFrame frame = SyntheticRenderer(o).Render(0, &truth);
  ASSERT_EQ(truth.obstacles.size(), 2u);
  EXPECT_EQ(truth.obstacles[0].visible_px, 0);
  EXPECT_TRUE(truth.obstacles[0].bbox.empty());
  EXPECT_GT(truth.obstacles[1].visible_px, 1000);
  // The hill's top (7 m above the camera at z = 60 m) shows above the horizon as terrain, seen
  // on its front half (50..60 m); the sky is just above it.
  const int top_row = static_cast<int>(std::ceil(240.0 - 700.0 * 7.0 / 60.0));
  EXPECT_EQ(truth.object_id(top_row + 1, 320), 0);
  EXPECT_GT(truth.disparity_px(top_row + 1, 320), kFB / 60.0);
  EXPECT_LT(truth.disparity_px(top_row + 1, 320), kFB / 50.0);
  EXPECT_EQ(truth.object_id(top_row - 2, 320), -1);
  // Every pixel is sky, terrain or the front obstacle.
  EXPECT_EQ(cv::countNonZero(truth.object_id == 1), 0);
  EXPECT_EQ(cv::countNonZero(truth.object_id < -1) + cv::countNonZero(truth.object_id > 2), 0);
  // The hill is shaded and textured.
  cv::Scalar mean, stddev;
  cv::meanStdDev(
      frame.left, mean, stddev,
      (truth.object_id == 0) & (truth.disparity_px > 6.0f) & (truth.disparity_px < 8.0f));
  EXPECT_GT(stddev[0], 8.0);
}

TEST(SyntheticSource, ProducesAnEndlessSequenceWithTruth) {
  auto source = OpenSyntheticSource(SyntheticOptions{});
  ASSERT_TRUE(source.ok()) << source.error().message;
  SyntheticSource& s = **source;
  EXPECT_EQ(s.Describe(), "synthetic 640x480 f=700px B=0.6m");
  EXPECT_EQ(s.NominalFps(), 10.0);
  ASSERT_NE(s.Rig(), nullptr);
  EXPECT_EQ(s.Rig()->f_px(), 700.0);
  EXPECT_EQ(s.Rig()->baseline_m(), 0.6);
  EXPECT_EQ(s.Rig()->cx(), 320.0);
  EXPECT_EQ(s.Rig()->cy(), 240.0);
  EXPECT_EQ(s.Rig()->image_size(), cv::Size(640, 480));
  for (int64_t k = 0; k < 3; ++k) {
    auto frame = s.Next();
    ASSERT_TRUE(frame.ok());
    EXPECT_EQ(frame->index, k);
    EXPECT_EQ(frame->t_ns, k * 100'000'000);
    EXPECT_TRUE(frame->rectified);
    EXPECT_EQ(frame->left.type(), CV_8UC1);
    EXPECT_EQ(frame->right.size(), cv::Size(640, 480));
    EXPECT_EQ(s.last_truth().index, k);
  }
}

// loop_frames: the first lap is rendered, later laps replay it pixel for pixel (against the
// renderer's own frame), with index and t_ns still counting up; out-of-range values are refused.
TEST(SyntheticSource, LoopFramesReplaysTheFirstLapExactlyWithTimeGoingOn) {
  SyntheticOptions options;
  options.loop_frames = 3;
  Result<std::unique_ptr<SyntheticSource>> source = OpenSyntheticSource(options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  const SyntheticRenderer reference{SyntheticOptions{}};
  for (int64_t k = 0; k < 8; ++k) {
    Result<StereoFrame> frame = (*source)->Next();
    ASSERT_TRUE(frame.ok());
    EXPECT_EQ(frame->index, k);
    EXPECT_EQ(frame->t_ns, k * 100'000'000);
    const StereoFrame expected = reference.Render(k % 3);
    EXPECT_EQ(cv::norm(frame->left, expected.left, cv::NORM_INF), 0.0) << "frame " << k;
    EXPECT_EQ(cv::norm(frame->right, expected.right, cv::NORM_INF), 0.0) << "frame " << k;
  }
  for (int bad : {-1, kMaxLoopFrames + 1}) {
    options.loop_frames = bad;
    const std::vector<std::string> problems = options.Validate();
    ASSERT_EQ(problems.size(), 1u);
    EXPECT_THAT(problems[0], ::testing::HasSubstr("loop_frames: must be in [0, 600] frames"));
  }
}

// The demo scene over one 20 s loop: every moving obstacle is mostly in view, within the range
// the default rig resolves, big enough to detect; some overlap in the image; the static ones show.
TEST(DefaultScene, KeepsEveryObstacleUsableOverOneLoop) {
  const SyntheticRenderer renderer{SyntheticOptions{}};
  const Scene& scene = renderer.options().scene;
  ASSERT_TRUE(scene.Validate().empty());
  const int frames = 200;  // 20 s at 10 fps
  std::map<std::string, int> visible_frames;
  int overlapping_frames = 0, occluded_frames = 0, hidden_frames = 0;
  for (int64_t k = 0; k < frames; ++k) {
    const FrameTruth truth = renderer.Truth(k);
    std::vector<cv::Rect> boxes;
    for (size_t i = 0; i < truth.obstacles.size(); ++i) {
      const ObstacleTruth& o = truth.obstacles[i];
      const Obstacle& ob = scene.obstacles[i];
      const bool moving = ob.path.kind != Path::Kind::kStatic;
      if (moving) {
        // Hidden behind a nearer one: less than half of the front face shows although the
        // face is inside the image.
        const double w = 700.0 * ob.size_m[0] / o.depth_m;
        const double h = 700.0 * ob.size_m[1] / o.depth_m;
        const double u = 320.0 + 700.0 * o.position_cam_m[0] / o.depth_m;
        const double v = 240.0 + 700.0 * o.position_cam_m[1] / o.depth_m;
        const bool in_image = u - w / 2 > 0 && u + w / 2 < 640 && v - h / 2 > 0 && v + h / 2 < 480;
        if (in_image && o.visible_px < 0.5 * w * h) ++occluded_frames;
        if (in_image && o.visible_px == 0) ++hidden_frames;
      }
      if (o.visible_px == 0) continue;
      ++visible_frames[o.name];
      boxes.push_back(o.bbox);
      if (!moving) continue;
      SCOPED_TRACE(o.name + " at frame " + std::to_string(k));
      EXPECT_GE(kFB / o.depth_m, 8.0);
      EXPECT_LE(o.depth_m, 50.0);
      EXPECT_GE(o.depth_m, 15.0);
      // The projected front face is at least 25 x 12 px.
      EXPECT_GE(700.0 * ob.size_m[0] / o.depth_m, 25.0);
      EXPECT_GE(700.0 * ob.size_m[1] / o.depth_m, 12.0);
      // In the sky: the centre is above the horizon row.
      EXPECT_LT(o.position_cam_m[1], 0.0);
    }
    bool overlap = false;
    for (size_t i = 0; i < boxes.size(); ++i) {
      for (size_t j = i + 1; j < boxes.size(); ++j) overlap |= (boxes[i] & boxes[j]).area() > 0;
    }
    overlapping_frames += overlap ? 1 : 0;
  }
  int moving = 0;
  for (const Obstacle& o : scene.obstacles) {
    SCOPED_TRACE(o.name);
    if (o.path.kind == Path::Kind::kStatic) {
      EXPECT_EQ(visible_frames[o.name], frames);
    } else {
      ++moving;
      EXPECT_GT(visible_frames[o.name], frames * 3 / 4);
    }
  }
  EXPECT_GE(moving, 4);
  ASSERT_NE(Find(renderer.Truth(0), "tower"), nullptr);
  ASSERT_NE(Find(renderer.Truth(0), "hangar"), nullptr);
  EXPECT_GT(Find(renderer.Truth(0), "tower")->visible_px, 5000);
  EXPECT_GT(Find(renderer.Truth(0), "hangar")->visible_px, 20000);
  EXPECT_GT(overlapping_frames, 10);
  EXPECT_GT(occluded_frames, 20);
  EXPECT_GT(hidden_frames, 10);  // drone-3 behind aircraft-1
}

TEST(Render, AMovingRigSeesStandingObstaclesComeNearer) {
  SyntheticOptions options;
  options.scene.rig_velocity_mps = cv::Vec3d(0.5, 0.0, 3.0);
  options.scene.rig_period_s = 10.0;
  ASSERT_TRUE(options.Validate().empty());
  const SyntheticRenderer still{SyntheticOptions{}};
  const SyntheticRenderer moving(options);
  // Frame 20 at 10 fps: 2 s of flight, the rig 1 m right and 6 m forward. The tower stands still
  // in the world, so in the camera frame it is 1 m further left and 6 m nearer.
  const FrameTruth a = still.Truth(20), b = moving.Truth(20);
  ASSERT_EQ(a.obstacles[0].name, "tower");
  EXPECT_NEAR(b.obstacles[0].position_cam_m[0], a.obstacles[0].position_cam_m[0] - 1.0, 1e-9);
  EXPECT_NEAR(b.obstacles[0].depth_m, a.obstacles[0].depth_m - 6.0, 1e-9);
  // The flight repeats: at 10 s the rig is back where it started.
  EXPECT_NEAR(moving.Truth(100).obstacles[0].depth_m, still.Truth(100).obstacles[0].depth_m, 1e-9);
  // A moving rig with hills (or marks) is refused, by name.
  SyntheticOptions hilly = options;
  hilly.scene.hills.push_back(Hill{{0.0, 45.0, 200.0}, {20.0, 10.0, 20.0}});
  bool named = false;
  for (const std::string& p : hilly.Validate())
    named |= p.find("rig_velocity_mps") != std::string::npos;
  EXPECT_TRUE(named);
}

}  // namespace
}  // namespace stevi::drivers

// ---- Renderer extensions: pitch, composite obstacles, clouds, sensor effects. ----

namespace stevi::drivers {
namespace {

// A plain scene: uniform sky of grey `sky`, flat untextured ground, no obstacles, no noise.
SyntheticOptions PlainOptions(double sky) {
  SyntheticOptions o;
  o.noise_sigma = 0.0;
  o.scene = Scene{};
  o.scene.sky_top = sky;
  o.scene.sky_horizon = sky;
  o.scene.camera_height_m = 10.0;
  return o;
}

TEST(Pitch, HorizonIsAtTheRowTheGeometryPredictsAndTheGroundDisparityIsExact) {
  for (double pitch_deg : {7.0, -4.0}) {
    SCOPED_TRACE("pitch " + std::to_string(pitch_deg));
    SyntheticOptions o = PlainOptions(0.7);
    o.scene.camera_pitch_deg = pitch_deg;
    const SyntheticRenderer renderer(o);
    const FrameTruth truth = renderer.Truth(0);
    const double th = pitch_deg * 3.14159265358979323846 / 180.0;
    const double horizon = 240.0 + 700.0 * std::tan(th);  // the row where the ray is level
    // Every column: sky (id -1, disparity 0) above the horizon, ground below it, and the
    // ground's disparity is f B / Z with Z the depth of the plane y = h along the pitched ray.
    int wrong = 0;
    double worst = 0;
    for (int v = 0; v < 480; ++v) {
      const double b = (v - 240.0) / 700.0;
      const double down = b * std::cos(th) - std::sin(th);  // world y of the ray (a, b, 1)
      for (int u = 0; u < 640; u += 37) {
        const int id = truth.object_id(v, u);
        if (v < horizon) {
          if (id != -1 || truth.disparity_px(v, u) != 0.0f) ++wrong;
        } else {
          if (id != 0) {
            ++wrong;
            continue;
          }
          const double z = 10.0 / down;
          worst = std::max(worst, std::abs(truth.disparity_px(v, u) - kFB / z));
        }
      }
    }
    EXPECT_EQ(wrong, 0);
    EXPECT_LT(worst, 1e-4);
    // The first ground row is the first row below the horizon.
    const int first_ground = static_cast<int>(std::ceil(horizon));
    EXPECT_EQ(truth.object_id(first_ground, 320), 0);
    EXPECT_EQ(truth.object_id(first_ground - 1, 320), -1);
  }
}

TEST(Pitch, ABoxFaceHasDisparityFBOverTheCameraDepthOfEachPixel) {
  SyntheticOptions o = PlaneOptions(30.0, 0.0);
  o.scene.camera_pitch_deg = 6.0;
  o.scene.camera_height_m = 1000.0;
  const SyntheticRenderer renderer(o);
  const FrameTruth truth = renderer.Truth(0);
  // The face is the world plane z = 30: the ray (a, b, 1) reaches it at camera depth
  // t = 30 / (b sin + cos).
  const double th = 6.0 * 3.14159265358979323846 / 180.0;
  double worst = 0;
  for (int v = 0; v < 480; v += 7) {
    const double dz = (v - 240.0) / 700.0 * std::sin(th) + std::cos(th);
    for (int u = 0; u < 640; u += 11) {
      ASSERT_EQ(truth.object_id(v, u), 1);
      worst = std::max(worst, std::abs(truth.disparity_px(v, u) - kFB * dz / 30.0));
    }
  }
  EXPECT_LT(worst, 1e-4);
  // The reference point (the face's centre, straight ahead in the world) in the pitched camera.
  EXPECT_NEAR(truth.obstacles[0].depth_m, 30.0 * std::cos(th), 1e-9);
}

TEST(Composite, AnEllipsoidHasTheAnalyticDiscAndDepth) {
  SyntheticOptions o = PlainOptions(0.8);
  o.scene.camera_height_m = 1000.0;
  Obstacle balloon;
  balloon.id = 3;
  balloon.kind = "balloon";
  balloon.albedo = 0.3;
  ObstaclePart sphere;
  sphere.shape = ObstaclePart::Shape::kEllipsoid;
  sphere.size_m = {4.0, 4.0, 4.0};  // radius 2 m
  balloon.parts.push_back(sphere);
  balloon.path.start = {0.0, 0.0, 40.0};
  o.scene.obstacles.push_back(balloon);
  const SyntheticRenderer renderer(o);
  const FrameTruth truth = renderer.Truth(0);
  ASSERT_EQ(truth.obstacles.size(), 1u);
  const ObstacleTruth& t = truth.obstacles[0];
  EXPECT_EQ(t.kind, "balloon");
  // The ray through the principal point hits the sphere at z = 40 - 2.
  EXPECT_NEAR(truth.disparity_px(240, 320), kFB / 38.0, 1e-4);
  // Its outline is the circle of angular radius asin(r / Z): pi R^2 pixels.
  const double radius_px = 700.0 * std::tan(std::asin(2.0 / 40.0));
  EXPECT_NEAR(t.visible_px, 3.14159265358979323846 * radius_px * radius_px, 0.02 * t.visible_px);
  EXPECT_NEAR(t.bbox.width, 2 * radius_px, 2.0);
  // The median over the disc: the depth of the sphere's surface at the disc's median radius.
  EXPECT_DOUBLE_EQ(t.median_disparity_px,
                   testing::MedianOverId(truth.object_id, truth.disparity_px, 3));
  EXPECT_GT(t.median_disparity_px, kFB / 40.0);
  EXPECT_LT(t.median_disparity_px, kFB / 38.0);
}

TEST(Composite, PartsShareOneIdAndOneBoundingBox) {
  SyntheticOptions o = PlainOptions(0.8);
  o.scene.camera_height_m = 1000.0;
  Obstacle drone;
  drone.id = 5;
  drone.kind = "drone";
  ObstaclePart body, arm;
  body.size_m = {1.0, 0.4, 1.0};
  arm.size_m = {4.0, 0.1, 0.2};
  arm.offset_m = {0.0, -0.25, 0.0};
  drone.parts = {body, arm};
  drone.path.start = {0.0, 0.0, 20.0};
  o.scene.obstacles.push_back(drone);
  const SyntheticRenderer renderer(o);
  const FrameTruth truth = renderer.Truth(0);
  const ObstacleTruth& t = truth.obstacles[0];
  // The arm is 4 m wide at a depth of 19.9 m (its front face): 140.7 px; the body 0.4 m tall
  // below the arm's top at -0.3 m.
  EXPECT_NEAR(t.bbox.width, 700.0 * 4.0 / 19.9, 2.0);
  EXPECT_EQ(truth.object_id(240, 320), 5);                                         // the body
  EXPECT_EQ(truth.object_id(240 + static_cast<int>(700 * -0.25 / 19.9), 300), 5);  // the arm
  // One id only: every obstacle pixel carries it.
  int others = 0;
  for (int v = 0; v < 480; ++v) {
    for (int u = 0; u < 640; ++u) {
      const int id = truth.object_id(v, u);
      if (id > 0 && id != 5) ++others;
    }
  }
  EXPECT_EQ(others, 0);
}

TEST(Clouds, AreAtInfinityAndShowInTheSkyGrey) {
  SyntheticOptions o = PlainOptions(0.6);
  o.scene.cloud_cover = 0.5;
  o.scene.cloud_grey = 0.3;
  o.scene.cloud_scale = 0.08;
  o.scene.camera_height_m = 1000.0;
  const SyntheticRenderer renderer(o);
  FrameTruth truth;
  const StereoFrame f = renderer.Render(0, &truth);
  const cv::Rect sky(0, 0, 640, 200);
  // Truth: sky, at infinity.
  EXPECT_EQ(cv::countNonZero(truth.object_id(sky) != -1), 0);
  EXPECT_EQ(cv::countNonZero(truth.disparity_px(sky)), 0);
  // The clouds brighten part of the sky by up to 0.3 of the scale, the rest stays 0.6.
  double lo = 0, hi = 0;
  cv::minMaxLoc(f.left(sky), &lo, &hi);
  EXPECT_NEAR(lo, 0.6 * 255, 1.0);
  EXPECT_GT(hi, 0.8 * 255);
  const double clear = cv::countNonZero(f.left(sky) <= 0.6 * 255 + 1) / double(sky.area());
  EXPECT_GT(clear, 0.1);
  EXPECT_LT(clear, 0.9);
  // Zero disparity: both views see the same clouds (no noise, no misalignment).
  EXPECT_EQ(CountDifferent(f.left(sky), f.right(sky)), 0);
}

TEST(SensorEffects, NoiseSigmaGainAndVignettingAreAsRequested) {
  for (double sigma : {1.0, 6.0}) {
    SyntheticOptions o = PlainOptions(0.5);
    o.scene.camera_height_m = 1000.0;
    o.noise_sigma = sigma;
    o.right_gain = 1.12;
    o.blur_sigma_px = 1.0;  // optics: before the noise, so it does not change the noise
    const SyntheticRenderer renderer(o);
    const StereoFrame f = renderer.Render(3);
    const cv::Rect flat(0, 0, 640, 200);  // uniform sky of grey 127.5
    cv::Scalar mean_l, sd_l, mean_r, sd_r;
    cv::meanStdDev(f.left(flat), mean_l, sd_l);
    cv::meanStdDev(f.right(flat), mean_r, sd_r);
    // The 8-bit rounding adds 1/12 grey level^2 of variance.
    const double expected = std::sqrt(sigma * sigma + 1.0 / 12.0);
    EXPECT_NEAR(sd_l[0], expected, 0.1 * sigma) << "sigma " << sigma;
    EXPECT_NEAR(sd_r[0], expected, 0.1 * sigma) << "sigma " << sigma;
    EXPECT_NEAR(mean_r[0] / mean_l[0], 1.12, 0.005) << "sigma " << sigma;
  }
  SyntheticOptions o = PlainOptions(0.8);
  o.scene.camera_height_m = 1000.0;
  o.scene.camera_pitch_deg = 40.0;  // sky everywhere
  o.vignetting = 0.3;
  const StereoFrame f = SyntheticRenderer(o).Render(0);
  const double centre = cv::mean(f.left(cv::Rect(310, 230, 20, 20)))[0];
  const double corner = cv::mean(f.left(cv::Rect(0, 0, 4, 4)))[0];
  EXPECT_NEAR(centre, 0.8 * 255, 1.0);
  EXPECT_NEAR(corner / centre, 0.7, 0.02);  // 30 % at the corners
}

TEST(SensorEffects, VerticalMisalignmentMovesTheRightImageBySubPixelAmounts) {
  // A textured wall at 25 m (a smooth texture, cells of 28 px, that cubic interpolation follows).
  SyntheticOptions o = PlaneOptions(25.0, 0.0);
  o.scene.obstacles[0].texture_cell_m = 1.0;
  const StereoFrame aligned = SyntheticRenderer(o).Render(0);
  cv::Mat1f a;
  aligned.right.convertTo(a, CV_32F);
  for (double shift : {0.3, -0.45}) {
    o.right_vertical_shift_px = shift;
    FrameTruth truth;
    const StereoFrame moved = SyntheticRenderer(o).Render(0, &truth);
    // The left image does not move (up to the rounding of the sensor-effects path), nor the
    // truth.
    cv::Mat diff;
    cv::absdiff(moved.left, aligned.left, diff);
    double max_diff = 0;
    cv::minMaxLoc(diff, nullptr, &max_diff);
    EXPECT_LE(max_diff, 1.0);
    EXPECT_FLOAT_EQ(truth.disparity_px(240, 320), static_cast<float>(kFB / 25.0));
    cv::Mat1f b;
    moved.right.convertTo(b, CV_32F);
    // Correlation: the vertical shift of the aligned right image (cubic interpolation) that
    // best matches the moved one, searched in 0.01 px steps, refined by a parabola.
    const cv::Rect inner(64, 64, 512, 352);
    // The aligned image moved down by s: a(u, v - s), Lanczos-4 interpolated along v (in
    // double; cv::warpAffine quantises the sub-pixel position).
    auto ssd = [&](double s) {
      double sum = 0;
      for (int v = inner.y; v < inner.y + inner.height; ++v) {
        const double y = v - s;
        const int y0 = static_cast<int>(std::floor(y));
        double w[8], w_sum = 0;
        for (int k = 0; k < 8; ++k) {
          const double x = y - (y0 - 3 + k);
          const double px = 3.14159265358979323846 * x;
          w[k] = std::abs(x) < 1e-12 ? 1.0 : 4.0 * std::sin(px) * std::sin(px / 4.0) / (px * px);
          w_sum += w[k];
        }
        for (int u = inner.x; u < inner.x + inner.width; ++u) {
          double value = 0;
          for (int k = 0; k < 8; ++k) value += w[k] * a(y0 - 3 + k, u);
          const double e = value / w_sum - b(v, u);
          sum += e * e;
        }
      }
      return sum;
    };
    double best_s = 0, best = std::numeric_limits<double>::infinity();
    for (int k = -60; k <= 60; ++k) {
      const double e = ssd(k * 0.01);
      if (e < best) {
        best = e;
        best_s = k * 0.01;
      }
    }
    const double em = ssd(best_s - 0.01), ep = ssd(best_s + 0.01);
    const double measured = best_s + 0.01 * 0.5 * (em - ep) / (em - 2 * best + ep);
    EXPECT_NEAR(measured, shift, 0.02) << "shift " << shift;
  }
}

}  // namespace
}  // namespace stevi::drivers

namespace stevi::drivers {
namespace {

// The chessboard scene renders each pose once and hands every frame its own copy: the frames of a
// held pose are the renderer's image of that pose (noise aside), the next pose's differ, and
// writing to one frame leaves the next untouched.
ChessboardSourceOptions SmallBoardScene(int hold_frames) {
  ChessboardSourceOptions options;
  options.width = 320;
  options.height = 240;
  options.f_px = 350;
  options.hold_frames = hold_frames;
  return options;
}

TEST(ChessboardSource, EveryFrameIsThePoseItHoldsAndItsOwnCopy) {
  ChessboardSourceOptions options = SmallBoardScene(3);
  options.poses = 2;
  options.noise_sigma = 0;
  Result<std::unique_ptr<ChessboardSource>> source = ChessboardSource::Open(options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  const cv::Size size(options.width, options.height);
  Result<calibration::ChessboardRenderer> renderer = calibration::ChessboardRenderer::Create(
      geometry::IdealCalibration(size, options.f_px, options.baseline_m, options.width / 2.0,
                                 options.height / 2.0),
      options.board, size);
  ASSERT_TRUE(renderer.ok()) << renderer.error().message;
  for (int64_t i = 0; i < 8; ++i) {
    Result<StereoFrame> frame = (*source)->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    const calibration::RenderedPair truth = renderer->Render((*source)->PoseAt(i));
    EXPECT_EQ(cv::norm(frame->left, truth.left, cv::NORM_INF), 0) << "frame " << i;
    EXPECT_EQ(cv::norm(frame->right, truth.right, cv::NORM_INF), 0) << "frame " << i;
    if (i == 2) {
      const calibration::RenderedPair next = renderer->Render((*source)->PoseAt(3));
      EXPECT_GT(cv::norm(truth.left, next.left, cv::NORM_L1), 0) << "the poses differ";
    }
    frame->left.setTo(0);  // the consumer writes to its frame: the next frame must not see it
    frame->right.setTo(0);
  }
}

// With noise, the frames of one pose differ from each other (noise drawn per frame).
TEST(ChessboardSource, NoiseIsDrawnAnewForEachFrameOfAHeldPose) {
  Result<std::unique_ptr<ChessboardSource>> source = ChessboardSource::Open(SmallBoardScene(5));
  ASSERT_TRUE(source.ok()) << source.error().message;
  Result<StereoFrame> a = (*source)->Next();
  Result<StereoFrame> b = (*source)->Next();
  ASSERT_TRUE(a.ok() && b.ok());
  const double mean_abs = cv::norm(a->left, b->left, cv::NORM_L1) / a->left.total();
  EXPECT_GT(mean_abs, 0.5) << "noise_sigma 2: two draws differ by about 2.3 grey levels a pixel";
  EXPECT_LT(mean_abs, 4.0);
}

}  // namespace
}  // namespace stevi::drivers
