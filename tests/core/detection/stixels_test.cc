// The stixel world on disparity maps whose truth is known by construction: a level rig 2 m above
// flat ground (d(v) = 0.3 (v - 240) at f = 700 px, B = 0.6 m), boxes standing on it or floating
// against the sky, holes, outliers and layers.
#include "core/detection/stixels.h"

#include <random>

#include <opencv2/imgproc.hpp>

#include <gtest/gtest.h>

#include "core/detection/ground_plane.h"

namespace stevi::detection {
namespace {

constexpr int kWidth = 640, kHeight = 480;
constexpr double kF = 700, kBase = 0.6, kHeightM = 2.0;
constexpr double kSlope = kBase / kHeightM;  // disparity per row below the horizon

geometry::StereoRig Rig() {
  return geometry::StereoRig::Ideal({kWidth, kHeight}, kF, kBase, kWidth / 2.0, kHeight / 2.0);
}

// Ground below the horizon (row 240), unmatched sky above, every matched pixel 90 % sure.
struct Scene {
  stereo::DisparityMap map;
  Scene() {
    map.fixed = cv::Mat1s(kHeight, kWidth, stereo::DisparityMap::kInvalid);
    map.confidence = cv::Mat1b(kHeight, kWidth, uchar{0});
    map.min_disparity = 0;
    map.num_disparities = 128;
    map.block_size = 5;
    for (int y = 241; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) Set(x, y, kSlope * (y - 240));
    }
  }
  void Set(int x, int y, double d, uchar conf = 230) {
    map.fixed(y, x) = static_cast<int16_t>(std::lround(d * stereo::DisparityMap::kScale));
    map.confidence(y, x) = conf;
  }
  void Clear(int x, int y) {
    map.fixed(y, x) = stereo::DisparityMap::kInvalid;
    map.confidence(y, x) = 0;
  }
  // A fronto-parallel box at disparity d.
  void Box(const cv::Rect& r, double d) {
    for (int y = r.y; y < r.y + r.height; ++y) {
      for (int x = r.x; x < r.x + r.width; ++x) Set(x, y, d);
    }
  }
  // The box standing on the ground at depth z, height h_m and the given columns.
  cv::Rect Standing(double z, double h_m, int x0, int x1) {
    const double d = kF * kBase / z;
    const int foot = static_cast<int>(std::lround(240 + d / kSlope));
    const int top = static_cast<int>(std::lround(foot - kF * h_m / z));
    const cv::Rect r(x0, top, x1 - x0, foot - top + 1);
    Box(r, d);
    return r;
  }
};

GroundPlane TrueGround() {
  GroundPlane g;
  g.a = 0;
  g.b = kSlope;
  g.c = -kSlope * 240;
  g.height_m = kHeightM;
  return g;
}

geometry::RangeOptions Range() {
  geometry::RangeOptions r;
  r.disparity_sigma_px = 0.25;
  return r;
}

std::vector<Detection> Obstacles(const Scene& scene, const StixelOptions& options = {},
                                 std::optional<GroundPlane> ground = TrueGround()) {
  const StixelWorld world = ComputeStixels(scene.map, Rig(), ground, Range(), options);
  return ObstaclesFromStixels(world, scene.map, cv::Mat(), Rig(), ground, Range(), options);
}

double IoU(const cv::Rect& a, const cv::Rect& b) {
  const double inter = (a & b).area();
  return inter / (a.area() + b.area() - inter);
}

TEST(Stixels, ValidateListsEveryProblem) {
  StixelOptions o;
  o.column_width_fraction = 0;
  o.min_cells = 0;
  o.join_sigmas = -1;
  const std::vector<std::string> problems = o.Validate();
  ASSERT_EQ(problems.size(), 3u) << ::testing::PrintToString(problems);
  EXPECT_NE(problems[0].find("column_width_fraction"), std::string::npos);
  EXPECT_TRUE(StixelOptions{}.Validate().empty());
}

TEST(Stixels, HeightAboveGroundIsTheAnalyticHeight) {
  const GroundPlane g = TrueGround();
  const geometry::StereoRig rig = Rig();
  // A point on the ground: 0 m; a point 1.5 m up at 10 m (row 240 + 700 * 0.5 / 10).
  EXPECT_NEAR(HeightAboveGround(g, rig, 100, 300, kSlope * 60), 0.0, 1e-9);
  const double d = kF * kBase / 10;
  EXPECT_NEAR(HeightAboveGround(g, rig, 400, 240 + kF * 0.5 / 10, d), 1.5, 1e-9);
  // The camera's own height, at the horizon row far away.
  EXPECT_NEAR(HeightAboveGround(g, rig, 320, 240, 1e-6), kHeightM, 1e-3);
}

TEST(Stixels, ColumnsAreLabelledGroundObjectSky) {
  Scene scene;
  const cv::Rect car = scene.Standing(14, 2.0, 200, 300);
  const StixelWorld world = ComputeStixels(scene.map, Rig(), TrueGround(), Range(), {});
  ASSERT_EQ(world.column_width, 8);
  ASSERT_EQ(world.cell_height, 4);
  for (const Stixel& s : world.stixels) {
    const bool in_car = s.x0 < car.x + car.width && s.x0 + s.width > car.x;
    if (s.label == StixelClass::kObject) {
      EXPECT_TRUE(in_car) << "object stixel in column " << s.column << " rows " << s.top_row << ".."
                          << s.bottom_row << " d " << s.disparity_px;
      EXPECT_NEAR(s.disparity_px, 30.0, 0.1);
      EXPECT_NEAR(s.top_row, car.y, 4);
      EXPECT_NEAR(s.bottom_row, car.y + car.height - 1, 4);
    }
    if (s.label == StixelClass::kGround) {
      EXPECT_GE(s.top_row, 236);
    }
    if (s.label == StixelClass::kSky) {
      EXPECT_LE(s.bottom_row, car.y + 3);
    }
  }
}

TEST(Stixels, OneObstaclePerObjectWithItsRange) {
  Scene scene;
  const cv::Rect car = scene.Standing(14, 1.5, 200, 300);
  const cv::Rect pole = scene.Standing(8, 4.0, 500, 510);
  const std::vector<Detection> found = Obstacles(scene);
  ASSERT_EQ(found.size(), 2u);
  // Nearest first.
  EXPECT_GT(IoU(found[0].bbox, pole), 0.6);
  EXPECT_NEAR(found[0].depth_m, 8.0, 0.05);
  EXPECT_GT(IoU(found[1].bbox, car), 0.85);
  EXPECT_NEAR(found[1].depth_m, 14.0, 0.05);
  EXPECT_EQ(found[1].extractor, "stixels");
  EXPECT_GT(found[1].range_sigma_m, 0.0);
}

TEST(Stixels, NothingOnBareGround) {
  Scene scene;
  EXPECT_TRUE(Obstacles(scene).empty());
  // Nor with 10 % outliers of low confidence scattered over it.
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> x(0, kWidth - 1), y(241, kHeight - 1);
  std::uniform_real_distribution<double> d(0, 100);
  for (int i = 0; i < kWidth * 240 / 10; ++i) scene.Set(x(rng), y(rng), d(rng), 40);
  EXPECT_TRUE(Obstacles(scene).empty());
}

TEST(Stixels, ObjectAgainstTheSkyAboveTheHorizon) {
  Scene scene;
  // A drone 40 m away, 20 m above the rig: above the horizon, sky all around it.
  const double d = kF * kBase / 40;
  const cv::Rect drone(300, 60, 24, 12);
  scene.Box(drone, d);
  const std::vector<Detection> found = Obstacles(scene);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_GT(IoU(found[0].bbox, drone), 0.5);
  EXPECT_NEAR(found[0].depth_m, 40.0, 0.5);
}

TEST(Stixels, CarInFrontOfAHouseIsTwoObstacles) {
  Scene scene;
  const cv::Rect house = scene.Standing(30, 8.0, 100, 500);
  const cv::Rect car = scene.Standing(12, 1.5, 250, 350);
  const std::vector<Detection> found = Obstacles(scene);
  ASSERT_EQ(found.size(), 2u);
  EXPECT_NEAR(found[0].depth_m, 12.0, 0.1);
  EXPECT_GT(IoU(found[0].bbox, car), 0.85);
  EXPECT_NEAR(found[1].depth_m, 30.0, 0.3);
  EXPECT_GT(IoU(found[1].bbox, house), 0.85);
}

TEST(Stixels, AHoleInAPanelDoesNotSplitIt) {
  Scene scene;
  const cv::Rect car = scene.Standing(10, 1.5, 200, 320);
  // A textureless door: the middle third unmatched.
  for (int y = car.y + 10; y < car.y + car.height - 10; ++y) {
    for (int x = 240; x < 280; ++x) scene.Clear(x, y);
  }
  const std::vector<Detection> found = Obstacles(scene);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_GT(IoU(found[0].bbox, car), 0.85);
}

TEST(Stixels, NothingSeenBetweenADroneAndAHangarAtItsRangeKeepsThemApart) {
  Scene scene;
  // A hangar 48 m away and a drone 10 m above it at the same range, unmatched sky between them:
  // one segment would bridge them at no cost; the cut at the unmeasured run keeps them apart.
  const cv::Rect hangar = scene.Standing(48, 6.0, 300, 460);
  const double d = kF * kBase / 48;
  const cv::Rect drone(360, hangar.y - 150, 30, 12);
  scene.Box(drone, d);
  const std::vector<Detection> found = Obstacles(scene);
  ASSERT_EQ(found.size(), 2u);
  const bool drone_first = found[0].bbox.y < found[1].bbox.y;
  EXPECT_GT(IoU(found[drone_first ? 0 : 1].bbox, drone), 0.5);
  EXPECT_GT(IoU(found[drone_first ? 1 : 0].bbox, hangar), 0.85);
  // A gap shorter than max_gap_m (a 0.5 m unmatched band across a car at 10 m) is no cut.
  Scene car_scene;
  const cv::Rect car = car_scene.Standing(10, 1.5, 200, 320);
  for (int y = car.y + 30; y < car.y + 30 + 35; ++y) {
    for (int x = car.x; x < car.x + car.width; ++x) car_scene.Clear(x, y);
  }
  const std::vector<Detection> one = Obstacles(car_scene);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_GT(IoU(one[0].bbox, car), 0.85);
}

TEST(Stixels, FittedGroundGivesTheSameObstacles) {
  Scene scene;
  const cv::Rect car = scene.Standing(14, 1.5, 200, 300);
  const std::optional<GroundPlane> fitted =
      FitGroundPlane(scene.map, Rig(), Eigen::Vector3d::UnitY(), 2.5, GroundPlaneOptions{});
  ASSERT_TRUE(fitted.has_value());
  EXPECT_NEAR(fitted->height_m, kHeightM, 0.1);
  const std::vector<Detection> found = Obstacles(scene, {}, fitted);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_GT(IoU(found[0].bbox, car), 0.85);
}

TEST(Stixels, EdgesSplitTwoTouchingObjectsAndNeverCreateOne) {
  // Two vans side by side at 10.0 and 10.3 m: their disparities (42, 40.8) lie within the depth gap
  // a receding surface may leave, so the geometry alone joins them. A dark and a bright panel meet
  // at column 320: SteViE's edge runs down the boundary.
  Scene scene;
  const cv::Rect left_van = scene.Standing(10.0, 2.0, 224, 320);
  const cv::Rect right_van = scene.Standing(10.3, 2.0, 320, 416);
  cv::Mat1b image(kHeight, kWidth, uchar{128});
  image(left_van).setTo(60);
  image(right_van).setTo(200);
  StixelOptions options;
  const StixelWorld world = ComputeStixels(scene.map, Rig(), TrueGround(), Range(), options);
  const std::vector<Detection> joined =
      ObstaclesFromStixels(world, scene.map, image, Rig(), TrueGround(), Range(), options);
  ASSERT_EQ(joined.size(), 1u);
  options.split = StixelOptions::Split::kEdges;
  const std::vector<Detection> split =
      ObstaclesFromStixels(world, scene.map, image, Rig(), TrueGround(), Range(), options);
  ASSERT_EQ(split.size(), 2u);
  EXPECT_GT(IoU(split[0].bbox, left_van), 0.8);
  EXPECT_GT(IoU(split[1].bbox, right_van), 0.8);
  // An edge inside one object at one disparity (a door's outline) splits nothing, and edges where
  // the geometry has nothing create nothing.
  Scene one;
  const cv::Rect van = one.Standing(10.0, 2.0, 224, 416);
  cv::Mat1b doors(kHeight, kWidth, uchar{128});
  doors(cv::Rect(320, van.y, 96, van.height)).setTo(220);
  cv::rectangle(doors, cv::Rect(40, 60, 100, 120), cv::Scalar(255), cv::FILLED);
  const StixelWorld world_one = ComputeStixels(one.map, Rig(), TrueGround(), Range(), options);
  EXPECT_EQ(
      ObstaclesFromStixels(world_one, one.map, doors, Rig(), TrueGround(), Range(), options).size(),
      1u);
}

}  // namespace
}  // namespace stevi::detection
