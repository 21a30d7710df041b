#include "core/calibration/calibrate.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/calibration/chessboard_render.h"
#include "core/geometry/stereo_rig.h"
#include "tests/core/calibration/synthetic_rig.h"

namespace stevi::calibration {
namespace {

using ::testing::AllOf;
using ::testing::Contains;
using ::testing::Field;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using testing::TestBoard;
using testing::TruthRig;

constexpr int kPairs = 18;

struct Dataset {
  std::vector<cv::Affine3d> poses;
  std::vector<RenderedPair> images;
  std::vector<ImagePair> pairs;  // PNG bytes
  DetectedPairs detected;
};

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

CalibrationOptions Options() {
  CalibrationOptions o;
  o.board = TestBoard();
  return o;
}

// 18 rendered views of the board, encoded as PNG, and their detection (built once).
const Dataset& Synthetic() {
  static const Dataset dataset = [] {
    Dataset d;
    const auto t0 = std::chrono::steady_clock::now();
    d.poses =
        GenerateBoardPoses(TruthRig(), TestBoard(), testing::kImageSize, kPairs, 2024).value();
    const ChessboardRenderer renderer =
        ChessboardRenderer::Create(TruthRig(), TestBoard(), testing::kImageSize).value();
    for (int i = 0; i < kPairs; ++i) {
      d.images.push_back(renderer.Render(d.poses[i]));
      d.pairs.push_back(
          {Png(d.images.back().left), Png(d.images.back().right), "view" + std::to_string(i)});
    }
    const auto t1 = std::chrono::steady_clock::now();
    d.detected = DetectPairs(d.pairs, Options()).value();
    const auto t2 = std::chrono::steady_clock::now();
    std::printf("rendered %d pairs in %.2f s, detected in %.2f s\n", kPairs,
                std::chrono::duration<double>(t1 - t0).count(),
                std::chrono::duration<double>(t2 - t1).count());
    return d;
  }();
  return dataset;
}

// Relative difference |a - b| / |b|.
double Rel(double a, double b) { return std::abs(a - b) / std::abs(b); }

// Mean |dy| after rectification, and the worst relative depth error (through Q), of random 3-D
// points that the truth rig sees in both cameras: an out-of-sample check of the calibration.
struct Holdout {
  double epipolar_mean_px = 0;
  double worst_depth_error = 0;
  int points = 0;
};

Holdout CheckOnRandomPoints(const geometry::StereoCalibration& truth,
                            const geometry::StereoCalibration& c) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1), depth(0.8, 4.0);
  std::vector<cv::Point3d> points;
  for (int i = 0; i < 400; ++i) {
    const double z = depth(rng);
    points.emplace_back(u(rng) * 0.5 * z, u(rng) * 0.4 * z, z);
  }
  std::vector<cv::Point2d> left, right;
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), truth.M1, truth.D1, left);
  cv::Vec3d rvec;
  cv::Rodrigues(truth.R, rvec);
  cv::projectPoints(points, rvec, truth.T, truth.M2, truth.D2, right);
  std::vector<cv::Point2d> l_in, r_in;
  std::vector<double> z_in;
  const cv::Rect2d image(5, 5, testing::kImageSize.width - 10, testing::kImageSize.height - 10);
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (image.contains(left[i]) && image.contains(right[i])) {
      l_in.push_back(left[i]);
      r_in.push_back(right[i]);
      z_in.push_back(points[i].z);
    }
  }
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-9);
  std::vector<cv::Point2d> l_rect, r_rect;
  cv::undistortPoints(l_in, l_rect, c.M1, c.D1, *c.R1, *c.P1, criteria);
  cv::undistortPoints(r_in, r_rect, c.M2, c.D2, *c.R2, *c.P2, criteria);
  Holdout h;
  h.points = static_cast<int>(l_in.size());
  for (std::size_t i = 0; i < l_in.size(); ++i) {
    h.epipolar_mean_px += std::abs(l_rect[i].y - r_rect[i].y) / h.points;
    const cv::Vec4d p = *c.Q * cv::Vec4d(l_rect[i].x, l_rect[i].y, l_rect[i].x - r_rect[i].x, 1);
    // Depth in the rectified left frame; the truth depth is in the raw left frame (R1 turns it).
    const cv::Vec3d in_rect(p[0] / p[3], p[1] / p[3], p[2] / p[3]);
    const cv::Vec3d in_raw = c.R1->t() * in_rect;
    h.worst_depth_error = std::max(h.worst_depth_error, Rel(in_raw[2], z_in[i]));
  }
  return h;
}

void ExpectRecoversTruth(const geometry::StereoCalibration& c,
                         const geometry::StereoCalibration& truth) {
  for (int cam = 0; cam < 2; ++cam) {
    const cv::Matx33d& m = cam == 0 ? c.M1 : c.M2;
    const cv::Matx33d& t = cam == 0 ? truth.M1 : truth.M2;
    EXPECT_LT(Rel(m(0, 0), t(0, 0)), 0.005)
        << "camera " << cam + 1 << " fx " << m(0, 0) << " truth " << t(0, 0);
    EXPECT_LT(Rel(m(1, 1), t(1, 1)), 0.005)
        << "camera " << cam + 1 << " fy " << m(1, 1) << " truth " << t(1, 1);
    EXPECT_NEAR(m(0, 2), t(0, 2), 1.5) << "camera " << cam + 1 << " cx";
    EXPECT_NEAR(m(1, 2), t(1, 2), 1.5) << "camera " << cam + 1 << " cy";
  }
  EXPECT_LT(Rel(cv::norm(c.T), cv::norm(truth.T)), 0.005) << "baseline " << cv::norm(c.T);
  EXPECT_LT(cv::norm(c.T - truth.T), 0.001) << "T " << c.T;
  EXPECT_LT(testing::RotationAngleDeg(c.R, truth.R), 0.05);
}

TEST(CalibrateStereo, RecoversTheSyntheticRig) {
  const Dataset& d = Synthetic();
  const auto t0 = std::chrono::steady_clock::now();
  const Result<CalibrationResult> result = CalibrateFromCorners(d.detected, Options());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(result.ok()) << result.error().message;
  const geometry::StereoCalibration& c = result->calibration;
  const CalibrationReport& r = result->report;
  const geometry::StereoCalibration truth = TruthRig();
  std::printf("%s", FormatReportText(r).c_str());
  std::printf(
      "solved in %.2f s: fx %.3f / %.3f (truth 520 / 516), baseline %.3f mm (truth %.3f), k1 %.4f "
      "/ %.4f\n",
      seconds, c.M1(0, 0), c.M2(0, 0), 1000 * cv::norm(c.T), 1000 * cv::norm(truth.T),
      c.D1.at<double>(0), c.D2.at<double>(0));

  ExpectRecoversTruth(c, truth);
  EXPECT_NEAR(c.D1.at<double>(0), -0.20, 0.01);
  EXPECT_NEAR(c.D2.at<double>(0), -0.18, 0.01);
  EXPECT_LT(r.rms_px, 0.3);
  EXPECT_LT(r.rms_left_px, 0.3);
  EXPECT_LT(r.rms_right_px, 0.3);
  // The stereo RMS is the RMS over both cameras' corners.
  EXPECT_NEAR(r.rms_px,
              std::sqrt((r.rms_left_px * r.rms_left_px + r.rms_right_px * r.rms_right_px) / 2),
              0.01 * r.rms_px);
  EXPECT_LT(r.epipolar_mean_px, 0.3);
  EXPECT_GE(r.epipolar_max_px, r.epipolar_mean_px);

  // Out of sample: points the truth rig sees, rectified with the result.
  const Holdout holdout = CheckOnRandomPoints(truth, c);
  std::printf("hold-out: %d points, epipolar %.4f px, worst depth error %.3f %%\n", holdout.points,
              holdout.epipolar_mean_px, 100 * holdout.worst_depth_error);
  EXPECT_GT(holdout.points, 100);
  EXPECT_LT(holdout.epipolar_mean_px, 0.3);
  EXPECT_LT(holdout.worst_depth_error, 0.01);

  // The report: counts, figures and gates.
  EXPECT_EQ(r.pairs_given, kPairs);
  EXPECT_EQ(r.pairs_used, kPairs);
  EXPECT_EQ(static_cast<int>(r.pairs.size()), kPairs);
  EXPECT_THAT(r.rejected, IsEmpty());
  EXPECT_TRUE(r.passed);
  EXPECT_THAT(r.failures, IsEmpty());
  EXPECT_FALSE(r.swap_left_right);
  EXPECT_EQ(r.image_size, testing::kImageSize);
  EXPECT_EQ(r.detector, "sector_based_then_classic + saddle_point");
  EXPECT_EQ(r.fx_left_px, c.M1(0, 0));
  EXPECT_NEAR(r.baseline_m, cv::norm(c.T), 1e-12);
  EXPECT_EQ(r.rectified_f_px, (*c.P1)(0, 0));
  EXPECT_GT(r.created_unix_ms, 1'600'000'000'000);
  EXPECT_THAT(r.warnings, Contains(HasSubstr("18 pairs used; the thesis advises at least 20")));

  // Rectification terms are filled and StereoRig takes the result as it is.
  ASSERT_TRUE(c.R1 && c.R2 && c.P1 && c.P2 && c.Q && c.E && c.F);
  EXPECT_LT((*c.P2)(0, 3), 0);
  const Result<geometry::StereoRig> rig = geometry::StereoRig::FromCalibration(c);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_LT(Rel(rig->baseline_m(), cv::norm(truth.T)), 0.005);
}

TEST(CalibrateStereo, ReportsCoverageOfTheTrueBoards) {
  const Dataset& d = Synthetic();
  const Result<CalibrationResult> result = CalibrateFromCorners(d.detected, Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  const cv::Size grid = r.coverage_grid;
  ASSERT_EQ(grid, cv::Size(10, 8));

  // Independently, from the true corners: per view the area of their hull; for the union, the cells
  // whose centre lies more than 0.5 px inside some true hull must be counted, and those more than
  // 0.5 px outside every one must not (the detected corners are within a tenth of a pixel).
  std::vector<std::vector<cv::Point2f>> hulls_left, hulls_right;
  double mean = 0;
  ASSERT_EQ(r.pairs.size(), d.poses.size());
  for (std::size_t i = 0; i < d.poses.size(); ++i) {
    const ProjectedBoard truth =
        ProjectChessboard(TruthRig(), TestBoard(), d.poses[r.pairs[i].index]);
    for (int cam = 0; cam < 2; ++cam) {
      std::vector<cv::Point2f> hull;
      cv::convexHull(cam == 0 ? truth.left : truth.right, hull);
      const double area = cv::contourArea(hull) / testing::kImageSize.area();
      EXPECT_NEAR(cam == 0 ? r.pairs[i].coverage_left : r.pairs[i].coverage_right, area, 0.002)
          << "pair " << i;
      mean += area / (2.0 * d.poses.size());
      (cam == 0 ? hulls_left : hulls_right).push_back(hull);
    }
  }
  EXPECT_NEAR(r.coverage_mean_view, mean, 0.002);
  for (int cam = 0; cam < 2; ++cam) {
    int surely_in = 0, maybe_in = 0;
    for (int gy = 0; gy < grid.height; ++gy) {
      for (int gx = 0; gx < grid.width; ++gx) {
        const cv::Point2f centre((gx + 0.5f) * testing::kImageSize.width / grid.width,
                                 (gy + 0.5f) * testing::kImageSize.height / grid.height);
        double inside = -1e9;  // signed distance into the nearest hull
        for (const auto& hull : cam == 0 ? hulls_left : hulls_right) {
          inside = std::max(inside, cv::pointPolygonTest(hull, centre, true));
        }
        surely_in += inside > 0.5;
        maybe_in += inside > -0.5;
      }
    }
    const double reported = cam == 0 ? r.coverage_union_left : r.coverage_union_right;
    EXPECT_GE(reported * grid.area(), surely_in - 1e-9) << "camera " << cam;
    EXPECT_LE(reported * grid.area(), maybe_in + 1e-9) << "camera " << cam;
    EXPECT_LE(maybe_in - surely_in, 3);
  }
  std::printf("coverage: per view mean %.1f %% (min %.1f %%), union %.1f %% / %.1f %%\n",
              100 * r.coverage_mean_view, 100 * r.coverage_min_view, 100 * r.coverage_union_left,
              100 * r.coverage_union_right);
  // A board with its margin fully in both views keeps its inner corners about two squares from the
  // edges, and out of the strip only one camera sees: the outer ring of cells stays empty.
  EXPECT_GT(r.coverage_union_left, 0.3);
  EXPECT_GT(r.coverage_union_right, 0.3);
}

TEST(CalibrateStereo, SwapsCamerasNamedTheWrongWayRound) {
  const Dataset& d = Synthetic();
  DetectedPairs swapped = d.detected;
  for (PairCorners& p : swapped.pairs) std::swap(p.left, p.right);
  const Result<CalibrationResult> result = CalibrateFromCorners(swapped, Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  EXPECT_TRUE(r.swap_left_right);
  EXPECT_THAT(
      r.warnings,
      Contains(HasSubstr("left and right swapped: the camera named left sits to the right")));
  EXPECT_THAT(FormatReportText(r), HasSubstr("LEFT AND RIGHT SWAPPED"));
  // The returned calibration has the roles swapped back: it is the truth rig again.
  const geometry::StereoCalibration& c = result->calibration;
  EXPECT_LT(c.T[0], 0);
  ExpectRecoversTruth(c, TruthRig());
  EXPECT_LT(r.rms_px, 0.3);
  EXPECT_LT(r.epipolar_mean_px, 0.3);
  const Result<geometry::StereoRig> rig = geometry::StereoRig::FromCalibration(c);
  EXPECT_TRUE(rig.ok()) << rig.error().message;

  // Same result as calibrating the correctly named pairs.
  const Result<CalibrationResult> normal = CalibrateFromCorners(d.detected, Options());
  ASSERT_TRUE(normal.ok());
  EXPECT_LT(Rel(c.M1(0, 0), normal->calibration.M1(0, 0)), 1e-4);
  EXPECT_LT(Rel(c.M2(0, 0), normal->calibration.M2(0, 0)), 1e-4);
  EXPECT_LT(cv::norm(c.T - normal->calibration.T), 1e-5);
  EXPECT_NEAR(r.rms_px, normal->report.rms_px, 1e-4);
  // Per pair, camera 1 of the result is the input's right images.
  for (std::size_t i = 0; i < r.pairs.size(); ++i) {
    EXPECT_NEAR(r.pairs[i].rms_left_px, normal->report.pairs[i].rms_left_px, 1e-3);
    EXPECT_NEAR(r.pairs[i].coverage_left, normal->report.pairs[i].coverage_left, 1e-9);
  }
}

DetectedPairs FirstPairs(const DetectedPairs& d, int n) {
  DetectedPairs out = d;
  out.pairs.resize(static_cast<std::size_t>(n));
  out.pairs_given = n;
  return out;
}

TEST(CalibrateStereo, GateOnTooFewPairs) {
  const Result<CalibrationResult> result =
      CalibrateFromCorners(FirstPairs(Synthetic().detected, 5), Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  EXPECT_FALSE(r.passed);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_EQ(r.failures[0].gate, "min_pairs");
  EXPECT_EQ(r.failures[0].measured, 5);
  EXPECT_EQ(r.failures[0].limit, 10);
  EXPECT_EQ(r.failures[0].message, "5 pairs used < 10 (min_pairs)");
  EXPECT_THAT(FormatReportText(r), HasSubstr("Stereo calibration: FAILED (min_pairs)"));

  CalibrationOptions lenient = Options();
  lenient.gates.min_pairs = 5;
  EXPECT_TRUE(CalibrateFromCorners(FirstPairs(Synthetic().detected, 5), lenient)->report.passed);
}

TEST(CalibrateStereo, GateOnRmsWithNoisyCorners) {
  DetectedPairs noisy = Synthetic().detected;
  std::mt19937 rng(9);
  std::normal_distribution<float> noise(0.0f, 1.5f);
  for (PairCorners& p : noisy.pairs) {
    for (auto* view : {&p.left, &p.right}) {
      for (cv::Point2f& q : *view) q += cv::Point2f(noise(rng), noise(rng));
    }
  }
  const Result<CalibrationResult> result = CalibrateFromCorners(noisy, Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  std::printf("noisy corners (1.5 px): rms %.3f px, epipolar %.3f px\n", r.rms_px,
              r.epipolar_mean_px);
  EXPECT_FALSE(r.passed);
  EXPECT_GT(r.rms_px, 1.0);
  EXPECT_THAT(r.failures, Contains(AllOf(Field(&GateFailure::gate, "max_rms_px"),
                                         Field(&GateFailure::measured, r.rms_px),
                                         Field(&GateFailure::limit, 1.0))));
}

TEST(CalibrateStereo, LeavesOutAPairNumberedBackwards) {
  // Pair 3's right corners numbered from the other end: each camera alone still fits (a board
  // turned by half a turn), but the two views of pair 3 disagree about the rig.
  DetectedPairs reversed = Synthetic().detected;
  std::reverse(reversed.pairs[3].right.begin(), reversed.pairs[3].right.end());
  const Result<CalibrationResult> result = CalibrateFromCorners(reversed, Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  EXPECT_TRUE(r.passed);
  EXPECT_EQ(r.pairs_used, kPairs - 1);
  ASSERT_EQ(r.rejected.size(), 1u);
  EXPECT_EQ(r.rejected[0].index, 3);
  EXPECT_EQ(r.rejected[0].reason, RejectReason::kOutlier);
  EXPECT_THAT(r.rejected[0].detail, HasSubstr("times the median pair's"));
  std::printf("pair #3 numbered backwards: %s; rms %.3f px\n", r.rejected[0].detail.c_str(),
              r.rms_px);
  ExpectRecoversTruth(result->calibration, TruthRig());

  // Without outlier rejection the solve is ruined: the RMS gate fails, or the result is not even a
  // valid rig, and either way the message points at pair 3.
  CalibrationOptions keep_all = Options();
  keep_all.outlier_factor = 0;
  const Result<CalibrationResult> ruined = CalibrateFromCorners(reversed, keep_all);
  if (ruined.ok()) {
    std::printf("kept: rms %.3f px\n", ruined->report.rms_px);
    EXPECT_FALSE(ruined->report.passed);
    EXPECT_THAT(ruined->report.failures, Contains(Field(&GateFailure::gate, "max_rms_px")));
    EXPECT_THAT(ruined->report.warnings,
                Contains(HasSubstr("pair #3 (view3) has an RMS error of")));
  } else {
    std::printf("kept: %s\n", ruined.error().message.c_str());
    EXPECT_THAT(ruined.error().message, HasSubstr("worst pairs: #3 (view3)"));
  }
}

TEST(CalibrateStereo, GateOnEpipolarError) {
  CalibrationOptions strict = Options();
  strict.gates.max_epipolar_px = 0.001;
  const Result<CalibrationResult> result = CalibrateFromCorners(Synthetic().detected, strict);
  ASSERT_TRUE(result.ok());
  const CalibrationReport& r = result->report;
  EXPECT_FALSE(r.passed);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_EQ(r.failures[0].gate, "max_epipolar_px");
  EXPECT_EQ(r.failures[0].measured, r.epipolar_mean_px);
  EXPECT_THAT(r.failures[0].message, HasSubstr("mean epipolar error after rectification"));
}

// A PNG signature and IHDR announcing a huge image, and nothing else.
std::string HugePngHeader() {
  std::string s = std::string(
      "\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR\x00\x00\x13\x88\x00\x00\x13\x88\x08\x00\x00\x00\x00",
      29);
  return s;
}

TEST(CalibrateStereo, RejectsBadPairsWithTheReason) {
  const Dataset& d = Synthetic();
  const cv::Mat blank(testing::kImageSize, CV_8UC1, cv::Scalar(128));
  cv::Mat small_left, small_right, bgr_left, bgr_right;
  cv::resize(d.images[1].left, small_left, {320, 240});
  cv::resize(d.images[1].right, small_right, {320, 240});
  std::vector<ImagePair> pairs;
  // Good pairs, as decoded BGR images and as byte vectors.
  for (int i = 0; i < 4; ++i) {
    cv::cvtColor(d.images[i].left, bgr_left, cv::COLOR_GRAY2BGR);
    cv::cvtColor(d.images[i].right, bgr_right, cv::COLOR_GRAY2BGR);
    pairs.push_back({bgr_left.clone(), bgr_right.clone(), "good" + std::to_string(i)});
  }
  const std::string& png = std::get<std::string>(d.pairs[4].left);
  pairs.push_back({std::vector<uint8_t>(png.begin(), png.end()), d.pairs[4].right, "good4"});
  // Bad pairs.
  pairs.push_back({std::string("GIF89a garbage"), d.pairs[5].right, "garbage"});  // 5
  pairs.push_back({d.pairs[5].left, Png(small_right), "mismatch"});               // 6
  pairs.push_back({Png(small_left), Png(small_right), "smaller"});                // 7
  pairs.push_back({d.pairs[6].left, HugePngHeader(), "huge"});                    // 8
  pairs.push_back(
      {cv::Mat(testing::kImageSize, CV_32FC1, cv::Scalar(0)), d.pairs[6].right, "float"});  // 9
  pairs.push_back({d.pairs[7].left, Png(blank), "no board right"});                         // 10
  pairs.push_back({Png(blank), d.pairs[7].right, "no board left"});                         // 11
  pairs.push_back({Png(blank), Png(blank), "no board"});                                    // 12
  std::string truncated = std::get<std::string>(d.pairs[8].left);
  truncated.resize(truncated.size() / 3);
  pairs.push_back({truncated, d.pairs[8].right, "truncated"});  // 13

  const Result<CalibrationResult> result = CalibrateStereo(pairs, Options());
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  EXPECT_EQ(r.pairs_given, 14);
  EXPECT_EQ(r.pairs_used, 5);
  EXPECT_LT(r.rms_px, 0.3);
  const struct {
    int index;
    RejectReason reason;
    std::string detail;
  } expected[] = {
      {5, RejectReason::kUndecodable,
       "left image: not a PNG or JPEG image (starts with 47 49 46 38)"},
      {6, RejectReason::kSizeMismatch, "left image is 640x480, right image is 320x240"},
      {7, RejectReason::kSizeDiffers, "images of 320x240, while 9 pairs are 640x480"},
      {8, RejectReason::kTooLarge,
       "right image: image of 5000x5000 pixels exceeds the maximum of 4096x4096; not decoded"},
      {9, RejectReason::kUndecodable,
       "left image: unsupported image type CV_32FC1 (expected 8-bit grey, BGR or BGRA)"},
      {10, RejectReason::kNoBoardRight, "no board of 9x6 inner corners found in the right image"},
      {11, RejectReason::kNoBoardLeft, "no board of 9x6 inner corners found in the left image"},
      {12, RejectReason::kNoBoard, "no board of 9x6 inner corners found in either image"},
      {13, RejectReason::kUndecodable, "left image: cannot decode the image"},
  };
  ASSERT_EQ(r.rejected.size(), std::size(expected));
  for (std::size_t i = 0; i < r.rejected.size(); ++i) {
    EXPECT_EQ(r.rejected[i].index, expected[i].index);
    EXPECT_EQ(r.rejected[i].name, pairs[expected[i].index].name);
    EXPECT_EQ(r.rejected[i].reason, expected[i].reason) << r.rejected[i].detail;
    EXPECT_THAT(r.rejected[i].detail, HasSubstr(expected[i].detail));
  }
  const std::string text = FormatReportText(r);
  EXPECT_THAT(text, HasSubstr("#8 huge: too_large: right image: image of 5000x5000"));
  EXPECT_THAT(text, HasSubstr("pairs: 5 used of 14 given, 9 rejected"));
}

TEST(CalibrateStereo, ClearErrorsForUnusableInput) {
  const Dataset& d = Synthetic();
  const std::string blank = Png(cv::Mat(testing::kImageSize, CV_8UC1, cv::Scalar(128)));
  auto error_of = [](const std::vector<ImagePair>& pairs, const CalibrationOptions& options) {
    const Result<CalibrationResult> result = CalibrateStereo(pairs, options);
    EXPECT_FALSE(result.ok());
    return result.ok() ? Error{} : result.error();
  };

  Error e = error_of({}, Options());
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(e.message, "no image pairs given");

  e = error_of({{std::string("junk"), std::string("junk"), "a"}, {std::string(), blank, "b"}},
               Options());
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message,
              HasSubstr("no usable pair: every one of the 2 pairs was rejected before detection"));
  EXPECT_THAT(e.message, HasSubstr("#1 (b): left image: empty image data"));

  e = error_of({{blank, blank, ""}, {blank, blank, ""}, {blank, blank, ""}}, Options());
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message,
              HasSubstr("no board of 9x6 inner corners found in any pair; check the board size"));

  // The board is there but the size given is wrong.
  const std::vector<ImagePair> three(d.pairs.begin(), d.pairs.begin() + 3);
  CalibrationOptions wrong = Options();
  wrong.board = BoardSpec{10, 7, 0.03};
  e = error_of(three, wrong);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message,
              HasSubstr("no board of 10x7 inner corners found in any pair; check the board size"));

  e = error_of({d.pairs[0], d.pairs[1], {d.pairs[2].left, blank, "right blank"}}, Options());
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(
      e.message,
      HasSubstr("too few pairs: 2 of 3 have the board in both images, at least 3 are needed"));
  EXPECT_THAT(
      e.message,
      HasSubstr("#2 (right blank): no board of 9x6 inner corners found in the right image"));

  e = error_of({{d.pairs[0].left, blank, ""}, {blank, d.pairs[1].right, ""}}, Options());
  EXPECT_THAT(e.message, HasSubstr("no pair has the board of 9x6 inner corners in both images"));

  CalibrationOptions invalid = Options();
  invalid.board.inner_cols = 1;
  invalid.gates.max_rms_px = 0;
  invalid.rectify_alpha = 2;
  invalid.max_image_size = {0, 0};
  e = error_of(three, invalid);
  EXPECT_EQ(e.code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(e.message, HasSubstr("board.columns: must be in [3, 100] (got 1)"));
  EXPECT_THAT(e.message, HasSubstr("gates.max_rms_px: must be > 0 pixels (got 0)"));
  EXPECT_THAT(e.message, HasSubstr("alpha: must be -1 (OpenCV's choice) or in [0, 1] (got 2)"));
  EXPECT_THAT(e.message,
              HasSubstr("max_image_size: each side must be in [16, 65535] pixels (got 0x0)"));

  // Corners that do not fit the board.
  DetectedPairs bad = FirstPairs(d.detected, 4);
  bad.pairs[2].right.pop_back();
  const Result<CalibrationResult> from_corners = CalibrateFromCorners(bad, Options());
  ASSERT_FALSE(from_corners.ok());
  EXPECT_THAT(from_corners.error().message,
              HasSubstr("54 and 53 corners, the board of 9x6 has 54"));
}

// Fuzz regressions (tests/fuzz/corpus/calibration_yaml/regression-report-text-*): texts that
// FileStorage's `fs << text` takes for a structure ('[', '{', ']', '}' first), writes unquoted
// so that they read back different (framed by quotes, trailing spaces), or cannot write (over
// 4 KiB). Pair names come from the client, so any text must survive the store.
TEST(CalibrationReport, AnyTextRoundTripsThroughYaml) {
  const std::vector<std::string> texts = {"[left]",
                                          "{x",
                                          "]",
                                          "}",
                                          "\\[x]",
                                          "'quoted'",
                                          "\"quoted\"",
                                          "trailing  ",
                                          " leading",
                                          "",
                                          "tab\tnew\nline\rreturn",
                                          "back\\slash",
                                          "12",
                                          "-3",
                                          "é ü ✓",
                                          "a: b, [c]"};
  for (const std::string& text : texts) {
    CalibrationReport r;
    r.detector = text;
    r.warnings = {text, text + text};
    r.failures.push_back({text, 1.5, 1.0, text});
    r.rejected.push_back({3, text, RejectReason::kNoBoard, text});
    r.pairs.push_back({0, text, 0.1, 0.2, 0.3, 0.4, 0.5});
    r.pairs_used = 1;
    const Result<std::string> yaml = ReportToYaml(r);
    ASSERT_TRUE(yaml.ok()) << text << ": " << yaml.error().message;
    const Result<CalibrationReport> back = ParseReportYaml(*yaml);
    ASSERT_TRUE(back.ok()) << text << ": " << back.error().message << "\n" << *yaml;
    EXPECT_EQ(back->detector, text);
    EXPECT_EQ(back->warnings, r.warnings);
    EXPECT_EQ(back->failures.at(0).gate, text);
    EXPECT_EQ(back->failures.at(0).message, text);
    EXPECT_EQ(back->rejected.at(0).name, text);
    EXPECT_EQ(back->rejected.at(0).detail, text);
    EXPECT_EQ(back->pairs.at(0).name, text);
  }
  // Control characters the format cannot carry become '?'; a text is kept to 1 KiB (whole UTF-8
  // characters), when written and when read alike.
  CalibrationReport r;
  r.detector = std::string("a\x01z\x1f", 4);
  r.warnings = {std::string(1023, 'x') + "é" + std::string(3000, 'y')};
  const Result<std::string> yaml = ReportToYaml(r);
  ASSERT_TRUE(yaml.ok()) << yaml.error().message;
  const Result<CalibrationReport> back = ParseReportYaml(*yaml);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_EQ(back->detector, "a?z?");
  EXPECT_EQ(back->warnings.at(0), std::string(1023, 'x'));
  std::string long_yaml = *yaml;
  const std::string detector = "detector: \"a?z?\"";
  ASSERT_NE(long_yaml.find(detector), std::string::npos) << long_yaml;
  long_yaml.replace(long_yaml.find(detector), detector.size(),
                    "detector: " + std::string(5000, 'd'));
  const Result<CalibrationReport> long_text = ParseReportYaml(long_yaml);
  ASSERT_TRUE(long_text.ok()) << long_text.error().message;
  EXPECT_EQ(long_text->detector, std::string(1024, 'd'));
}

TEST(CalibrationReport, RoundTripsThroughYaml) {
  const Dataset& d = Synthetic();
  DetectedPairs detected = d.detected;
  detected.pairs_given += 2;
  detected.rejected.push_back({18, "", RejectReason::kNoBoardLeft,
                               "no board of 9x6 inner corners found in the left image"});
  detected.rejected.push_back(
      {19, "odd: name \"quoted\"", RejectReason::kTooLarge, "right image: too large"});
  CalibrationOptions options = Options();
  options.gates.min_pairs = 30;
  const Result<CalibrationResult> result = CalibrateFromCorners(detected, options);
  ASSERT_TRUE(result.ok());
  const CalibrationReport& r = result->report;
  ASSERT_FALSE(r.passed);
  const Result<std::string> yaml = ReportToYaml(r);
  ASSERT_TRUE(yaml.ok()) << yaml.error().message;
  const Result<CalibrationReport> back = ParseReportYaml(*yaml);
  ASSERT_TRUE(back.ok()) << back.error().message << "\n" << *yaml;
  const CalibrationReport& b = *back;
  EXPECT_EQ(b.created_unix_ms, r.created_unix_ms);
  EXPECT_EQ(b.passed, r.passed);
  EXPECT_EQ(b.swap_left_right, r.swap_left_right);
  EXPECT_EQ(b.image_size, r.image_size);
  EXPECT_EQ(b.board.Name(), r.board.Name());
  EXPECT_EQ(b.board.square_size_m, r.board.square_size_m);
  EXPECT_EQ(b.detector, r.detector);
  EXPECT_EQ(b.pairs_given, r.pairs_given);
  EXPECT_EQ(b.pairs_used, r.pairs_used);
  EXPECT_DOUBLE_EQ(b.rms_px, r.rms_px);
  EXPECT_DOUBLE_EQ(b.rms_left_px, r.rms_left_px);
  EXPECT_DOUBLE_EQ(b.epipolar_mean_px, r.epipolar_mean_px);
  EXPECT_DOUBLE_EQ(b.epipolar_max_px, r.epipolar_max_px);
  EXPECT_EQ(b.coverage_grid, r.coverage_grid);
  EXPECT_DOUBLE_EQ(b.coverage_union_right, r.coverage_union_right);
  EXPECT_DOUBLE_EQ(b.baseline_m, r.baseline_m);
  EXPECT_DOUBLE_EQ(b.rectified_f_px, r.rectified_f_px);
  ASSERT_EQ(b.failures.size(), r.failures.size());
  EXPECT_EQ(b.failures[0].gate, "min_pairs");
  EXPECT_EQ(b.failures[0].message, r.failures[0].message);
  EXPECT_EQ(b.failures[0].limit, 30);
  EXPECT_EQ(b.warnings, r.warnings);
  ASSERT_EQ(b.rejected.size(), 2u);
  EXPECT_EQ(b.rejected[0].name, "");
  EXPECT_EQ(b.rejected[1].name, "odd: name \"quoted\"");
  EXPECT_EQ(b.rejected[1].reason, RejectReason::kTooLarge);
  EXPECT_EQ(b.rejected[0].detail, r.rejected[0].detail);
  ASSERT_EQ(b.pairs.size(), r.pairs.size());
  for (std::size_t i = 0; i < b.pairs.size(); ++i) {
    EXPECT_EQ(b.pairs[i].index, r.pairs[i].index);
    EXPECT_EQ(b.pairs[i].name, r.pairs[i].name);
    EXPECT_DOUBLE_EQ(b.pairs[i].rms_right_px, r.pairs[i].rms_right_px);
    EXPECT_DOUBLE_EQ(b.pairs[i].coverage_left, r.pairs[i].coverage_left);
    EXPECT_DOUBLE_EQ(b.pairs[i].epipolar_mean_px, r.pairs[i].epipolar_mean_px);
  }
  EXPECT_EQ(FormatReportText(b), FormatReportText(r));

  // Damaged reports name what is wrong.
  std::string damaged = *yaml;
  damaged.replace(damaged.find("rms_px:"), 7, "rms_xx:");
  damaged.replace(damaged.find("reason: no_board_left"), 21, "reason: lost_it");
  const Result<CalibrationReport> bad = ParseReportYaml(damaged);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, HasSubstr("rms_px: missing"));
  EXPECT_THAT(bad.error().message, HasSubstr("rejected[0].reason: unknown value \"lost_it\""));
  EXPECT_THAT(ParseReportYaml("{ not: [yaml").error().message,
              HasSubstr("calibration report: not valid YAML"));
  EXPECT_EQ(ParseReportYaml("- a list").error().code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace stevi::calibration
