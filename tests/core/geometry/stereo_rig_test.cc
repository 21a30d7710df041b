#include "core/geometry/stereo_rig.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/geometry/calibration_io.h"
#include "core/geometry/range.h"
#include "tests/core/geometry/calibration_fixtures.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::geometry {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

using fixtures::kIdealYaml;
using fixtures::MaxAbsDiff;
using fixtures::RawCalibration;
using fixtures::Replace;
using fixtures::WriteFile;

TEST(StereoRigIdeal, NeedsNoRemapAndRectifyConvertsToGrey) {
  const StereoRig rig = StereoRig::Ideal(cv::Size(64, 48), 100.0, 0.5, 31.5, 23.5);
  EXPECT_FALSE(rig.needs_remap());
  EXPECT_EQ(rig.f_px(), 100.0);
  EXPECT_EQ(rig.baseline_m(), 0.5);
  EXPECT_EQ(rig.calibration_id(), "ideal");
  cv::Mat3b left(48, 64), right(48, 64);
  cv::randu(left, 0, 256);
  cv::randu(right, 0, 256);
  cv::Mat rect_left, rect_right;
  ASSERT_TRUE(rig.Rectify(left, right, rect_left, rect_right).ok());
  cv::Mat expected;
  cv::cvtColor(left, expected, cv::COLOR_BGR2GRAY);
  ASSERT_EQ(rect_left.type(), CV_8UC1);
  EXPECT_EQ(cv::norm(rect_left, expected, cv::NORM_INF), 0.0);

  // Grey input is copied as it is, into the buffers already there.
  cv::Mat1b grey(48, 64);
  cv::randu(grey, 0, 256);
  const uchar* buffer = rect_left.data;
  ASSERT_TRUE(rig.Rectify(grey, grey, rect_left, rect_right).ok());
  EXPECT_EQ(rect_left.data, buffer);
  EXPECT_EQ(cv::norm(rect_left, grey, cv::NORM_INF), 0.0);
  EXPECT_NE(rect_right.data, grey.data);
}

TEST(StereoRigRectify, RejectsWrongTypeOrSizeNamingTheImage) {
  const StereoRig rig = StereoRig::Ideal(cv::Size(64, 48), 100.0, 0.5, 31.5, 23.5);
  cv::Mat out_left, out_right;
  const Status wrong_type =
      rig.Rectify(cv::Mat(48, 64, CV_16UC1, cv::Scalar(0)), cv::Mat1b(48, 64), out_left, out_right);
  ASSERT_FALSE(wrong_type.ok());
  EXPECT_THAT(wrong_type, IsError(ErrorCode::kInvalidArgument,
                                  AllOf(HasSubstr("left image"), HasSubstr("CV_16UC1"))));
  const Status wrong_size = rig.Rectify(cv::Mat1b(48, 64), cv::Mat1b(48, 63), out_left, out_right);
  ASSERT_FALSE(wrong_size.ok());
  EXPECT_THAT(wrong_size.error().message, AllOf(HasSubstr("right image"), HasSubstr("63x48")));
  const Status empty = rig.Rectify(cv::Mat(), cv::Mat1b(48, 64), out_left, out_right);
  EXPECT_FALSE(empty.ok());
}

TEST(StereoRigFromCalibration, IdealCalibrationNeedsNoRemap) {
  StereoCalibration c = IdealCalibration(cv::Size(640, 480), 615.0, 0.1, 320.0, 240.0);
  c.R1.reset();
  c.R2.reset();
  c.P1.reset();
  c.P2.reset();
  c.Q.reset();
  Result<StereoRig> rig = StereoRig::FromCalibration(c, "bench");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_FALSE(rig->needs_remap());
  EXPECT_DOUBLE_EQ(rig->f_px(), 615.0);
  EXPECT_DOUBLE_EQ(rig->baseline_m(), 0.1);
  EXPECT_DOUBLE_EQ(rig->cx(), 320.0);
  EXPECT_DOUBLE_EQ(rig->cy(), 240.0);
  EXPECT_EQ(rig->calibration_id(), "bench");
  EXPECT_EQ(
      MaxAbsDiff(cv::Mat(rig->Q()), cv::Mat(*IdealCalibration(c.image_size, 615, 0.1, 320, 240).Q)),
      0.0);
}

TEST(StereoRigFromCalibration, LeftCameraOnTheRightIsAClearError) {
  StereoCalibration c = RawCalibration();
  c.T = cv::Vec3d(0.0925, 0.001, 0.0);
  Result<StereoRig> rig = StereoRig::FromCalibration(c);
  ASSERT_FALSE(rig.ok());
  EXPECT_THAT(rig, IsError(ErrorCode::kInvalidArgument,
                           AllOf(HasSubstr("T_x > 0"), HasSubstr("swap left and right"))));
}

TEST(StereoRigFromCalibration, InvalidCalibrationListsProblems) {
  StereoCalibration c = RawCalibration();
  c.M2(0, 0) = 0;
  c.R(0, 0) = 3;
  Result<StereoRig> rig = StereoRig::FromCalibration(c);
  ASSERT_FALSE(rig.ok());
  EXPECT_THAT(rig.error().message, AllOf(HasSubstr("M2"), HasSubstr("R: not a rotation")));
}

TEST(StereoRigFromCalibration, UsesRectificationTermsFromTheFile) {
  StereoCalibration c = RawCalibration();
  cv::Mat r1, r2, p1, p2, q;
  // alpha = 1 keeps every source pixel: a different (smaller) focal length than alpha = 0.
  cv::stereoRectify(cv::Mat(c.M1), c.D1, cv::Mat(c.M2), c.D2, c.image_size, cv::Mat(c.R),
                    cv::Mat(c.T), r1, r2, p1, p2, q, cv::CALIB_ZERO_DISPARITY, 1.0);
  c.R1 = cv::Matx33d(r1);
  c.R2 = cv::Matx33d(r2);
  c.P1 = cv::Matx34d(p1);
  c.P2 = cv::Matx34d(p2);
  c.Q = cv::Matx44d(q);
  Result<StereoRig> given = StereoRig::FromCalibration(c);
  c.R1.reset();
  c.R2.reset();
  c.P1.reset();
  c.P2.reset();
  c.Q.reset();
  Result<StereoRig> computed = StereoRig::FromCalibration(c);
  ASSERT_TRUE(given.ok() && computed.ok());
  EXPECT_DOUBLE_EQ(given->f_px(), p1.at<double>(0, 0));
  EXPECT_GT(computed->f_px(), given->f_px() * 1.01);
  EXPECT_TRUE(given->needs_remap());
}

// Projects points through the raw rig, rectifies the points with the rig's terms, and checks the
// epipolar rows agree and the disparity gives the true depth.
TEST(StereoRigFromCalibration, RawRigRectifiesPointsToEqualRowsAndTrueDepth) {
  const StereoCalibration raw = RawCalibration();
  Result<StereoRig> rig = StereoRig::FromCalibration(raw, "raw");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_TRUE(rig->needs_remap());
  const StereoCalibration& c = rig->calibration();
  ASSERT_TRUE(c.R1 && c.R2 && c.P1 && c.P2 && c.Q);
  EXPECT_NEAR(rig->baseline_m(), cv::norm(raw.T), 1e-9);

  std::vector<cv::Point3d> points;
  for (double z : {1.5, 4.0, 12.0, 40.0}) {
    for (double x = -0.35; x <= 0.35; x += 0.175) {
      for (double y = -0.25; y <= 0.25; y += 0.125) points.emplace_back(x * z, y * z, z);
    }
  }
  std::vector<cv::Point2d> left_raw, right_raw, left_rect, right_rect;
  cv::Mat rvec_right;
  cv::Rodrigues(cv::Mat(raw.R), rvec_right);
  cv::projectPoints(points, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), cv::Mat(raw.M1), raw.D1,
                    left_raw);
  cv::projectPoints(points, rvec_right, cv::Mat(raw.T), cv::Mat(raw.M2), raw.D2, right_raw);
  const cv::TermCriteria exact(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12);
  cv::undistortPoints(left_raw, left_rect, cv::Mat(raw.M1), raw.D1, cv::Mat(*c.R1), cv::Mat(*c.P1),
                      exact);
  cv::undistortPoints(right_raw, right_rect, cv::Mat(raw.M2), raw.D2, cv::Mat(*c.R2),
                      cv::Mat(*c.P2), exact);

  int checked = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const cv::Point2d& l = left_rect[i];
    const cv::Point2d& r = right_rect[i];
    if (l.x < 0 || l.x >= 640 || l.y < 0 || l.y >= 480) continue;  // outside the rectified view
    ++checked;
    EXPECT_LT(std::abs(l.y - r.y), 0.05) << "point " << i;
    const double d = l.x - r.x;
    ASSERT_GT(d, 0.0) << "point " << i;
    // True depth in the rectified left camera frame.
    const cv::Vec3d in_rect = (*c.R1) * cv::Vec3d(points[i].x, points[i].y, points[i].z);
    const double z = DepthFromDisparity(d, rig->f_px(), rig->baseline_m());
    EXPECT_NEAR(z, in_rect[2], 1e-3 * in_rect[2]) << "point " << i;
    const std::optional<cv::Vec3d> p = PointFromDisparity(l.x, l.y, d, rig->Q());
    ASSERT_TRUE(p.has_value());
    EXPECT_LT(cv::norm(*p - in_rect), 1e-3 * in_rect[2]) << "point " << i;
  }
  EXPECT_GT(checked, static_cast<int>(points.size()) / 2);
}

TEST(BinningFactor, IsTheSmallestWholeFactorThatFitsTheWidth) {
  EXPECT_EQ(BinningFactor(640, 800), 1);
  EXPECT_EQ(BinningFactor(800, 800), 1);
  EXPECT_EQ(BinningFactor(801, 800), 2);
  EXPECT_EQ(BinningFactor(1280, 800), 2);
  EXPECT_EQ(BinningFactor(1920, 800), 3);
  EXPECT_EQ(BinningFactor(4096, 800), 6);
  EXPECT_EQ(BinningFactor(4096, 0), 1);  // 0: never bin
  // No further than keeps the disparity floor (camera pixels) at 1.25 px or more when binned.
  EXPECT_EQ(BinningFactor(1920, 800, 2.5), 2);
  EXPECT_EQ(BinningFactor(1920, 800, 5.0), 3);
  EXPECT_EQ(BinningFactor(1280, 800, 2.0), 1);
  EXPECT_EQ(BinningFactor(1280, 800, 0.0), 2);
}

// BinImage against a plain average of each block, rounded to nearest, on noise whose size is not a
// multiple of the factor (the incomplete last columns and rows are dropped).
TEST(BinImage, AveragesEachWholeBlockLikeAPlainLoop) {
  cv::Mat1b in(77, 131);
  cv::randu(in, 0, 256);
  for (int factor : {1, 2, 3, 4}) {
    cv::Mat out;
    BinImage(in, factor, out);
    ASSERT_EQ(out.type(), CV_8UC1);
    ASSERT_EQ(out.size(), cv::Size(131 / factor, 77 / factor)) << "factor " << factor;
    int worst = 0;
    for (int y = 0; y < out.rows; ++y) {
      for (int x = 0; x < out.cols; ++x) {
        int sum = 0;
        for (int dy = 0; dy < factor; ++dy) {
          for (int dx = 0; dx < factor; ++dx) sum += in(y * factor + dy, x * factor + dx);
        }
        const int n = factor * factor;
        const int expected = (2 * sum + n) / (2 * n);  // rounded to nearest, halves up
        worst = std::max(worst, std::abs(out.at<uchar>(y, x) - expected));
      }
    }
    // OpenCV's area resampling rounds its fixed-point mean: a half may go either way.
    EXPECT_LE(worst, 1) << "factor " << factor;
  }
}

// A point seen by the full rig at (u, v) with disparity d is seen by the rig binned by k at the
// binned pixel whose centre is there: ((u - (k - 1) / 2) / k, ...) with disparity d / k; the
// range from the binned rig is the same.
TEST(StereoRigBinned, ProjectsPointsOntoTheBinnedGrid) {
  const StereoRig full = StereoRig::Ideal({1280, 1024}, 1400.0, 0.6, 641.3, 509.7, "big");
  for (int k : {2, 3}) {
    const StereoRig binned = full.Binned(k);
    EXPECT_EQ(binned.image_size(), cv::Size(1280 / k, 1024 / k));
    EXPECT_EQ(binned.calibration_id(), "big");
    EXPECT_FALSE(binned.needs_remap());
    EXPECT_DOUBLE_EQ(binned.baseline_m(), 0.6);
    for (const cv::Vec3d& p : {cv::Vec3d(1.5, -2.0, 12.0), cv::Vec3d(-7.0, 3.0, 45.0)}) {
      const double u = full.f_px() * p[0] / p[2] + full.cx();
      const double v = full.f_px() * p[1] / p[2] + full.cy();
      const double d = full.f_px() * full.baseline_m() / p[2];
      const double ub = binned.f_px() * p[0] / p[2] + binned.cx();
      const double vb = binned.f_px() * p[1] / p[2] + binned.cy();
      EXPECT_NEAR(ub, (u - (k - 1) / 2.0) / k, 1e-9);
      EXPECT_NEAR(vb, (v - (k - 1) / 2.0) / k, 1e-9);
      const std::optional<cv::Vec3d> back = PointFromDisparity(ub, vb, d / k, binned.Q());
      ASSERT_TRUE(back.has_value());
      EXPECT_LT(cv::norm(*back - p), 1e-9 * p[2]);
    }
  }
}

// Renders Gaussian dots at known raw positions, rectifies the image and finds each dot where the
// rectification of its raw position predicts.
TEST(StereoRigRectify, MovesRawDotsToTheirPredictedRectifiedPositions) {
  const StereoCalibration raw = RawCalibration();
  Result<StereoRig> rig = StereoRig::FromCalibration(raw);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  const StereoCalibration& c = rig->calibration();

  std::vector<cv::Point2d> dots;
  for (double y = 60.5; y < 480; y += 90) {
    for (double x = 50.25; x < 640; x += 90) dots.emplace_back(x, y);
  }
  auto render = [&](cv::Mat1b& image) {
    image.create(480, 640);
    for (int v = 0; v < image.rows; ++v) {
      for (int u = 0; u < image.cols; ++u) {
        double value = 0;
        for (const cv::Point2d& p : dots) {
          const double r2 = (u - p.x) * (u - p.x) + (v - p.y) * (v - p.y);
          if (r2 < 100) value += 250.0 * std::exp(-r2 / (2 * 2.0 * 2.0));
        }
        image(v, u) = cv::saturate_cast<uchar>(value);
      }
    }
  };
  cv::Mat1b raw_image;
  render(raw_image);
  cv::Mat3b raw_colour;
  cv::cvtColor(raw_image, raw_colour, cv::COLOR_GRAY2BGR);
  cv::Mat rect_left, rect_right;
  ASSERT_TRUE(rig->Rectify(raw_image, raw_colour, rect_left, rect_right).ok());
  ASSERT_EQ(rect_left.type(), CV_8UC1);
  ASSERT_EQ(rect_left.size(), cv::Size(640, 480));

  auto check = [&](const cv::Mat& rect, const cv::Matx33d& M, const cv::Mat& D,
                   const cv::Matx33d& R, const cv::Matx34d& P, const char* side) {
    std::vector<cv::Point2d> predicted;
    cv::undistortPoints(
        dots, predicted, cv::Mat(M), D, cv::Mat(R), cv::Mat(P),
        cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-12));
    int found = 0;
    for (std::size_t i = 0; i < dots.size(); ++i) {
      const cv::Point2d& q = predicted[i];
      if (q.x < 12 || q.x > 627 || q.y < 12 || q.y > 467) continue;
      const cv::Rect window(cvRound(q.x) - 8, cvRound(q.y) - 8, 17, 17);
      const cv::Moments m = cv::moments(rect(window));
      ASSERT_GT(m.m00, 1000.0) << side << " dot " << i << " not found near " << q;
      const cv::Point2d centroid(window.x + m.m10 / m.m00, window.y + m.m01 / m.m00);
      EXPECT_LT(cv::norm(centroid - q), 0.5) << side << " dot " << i << " raw " << dots[i];
      ++found;
    }
    EXPECT_GE(found, 20) << side;
  };
  check(rect_left, raw.M1, raw.D1, *c.R1, *c.P1, "left");
  check(rect_right, raw.M2, raw.D2, *c.R2, *c.P2, "right");
}

TEST(StereoRigFromFile, DefaultsCalibrationIdToTheFileStem) {
  const std::string dir = testing::MakeTempDir("stevi_rig");
  const std::string path = WriteFile(dir, "bench_rig_2024.yaml", kIdealYaml);
  Result<StereoRig> rig = StereoRig::FromFile(path);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_EQ(rig->calibration_id(), "bench_rig_2024");
  EXPECT_FALSE(rig->needs_remap());
  EXPECT_DOUBLE_EQ(rig->baseline_m(), 0.12);

  Result<StereoRig> missing = StereoRig::FromFile(dir + "/absent.yaml");
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing, IsError(ErrorCode::kNotFound));

  const std::string swapped =
      WriteFile(dir, "swapped.yaml", Replace(kIdealYaml, "[ -0.12, 0., 0. ]", "[ 0.12, 0., 0. ]"));
  Result<StereoRig> bad = StereoRig::FromFile(swapped);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message, AllOf(HasSubstr(swapped), HasSubstr("T_x > 0")));
}

// The XIMEA rig of the shared data: its owner's calibration names "left" the camera that sits
// physically on the right (T_x > 0). The owner's files split intrinsics and extrinsics, omit the
// image size (640x512) and give T in millimetres. nullopt when the data is absent (`why` says).
std::optional<StereoCalibration> XimeaOwnerCalibration(std::string& dir, std::string& why) {
  const std::optional<std::string> data = testing::DataDir();
  if (!data) {
    why = "reference data folder not found: " + testing::DataDirWanted();
    return std::nullopt;
  }
  dir = *data + "/calib_ximea_stereo/";
  if (!std::filesystem::exists(dir + "intrinsics.yml") ||
      !std::filesystem::exists(dir + "extrinsics.yml")) {
    why = "XIMEA calibration not found in " + dir;
    return std::nullopt;
  }
  cv::FileStorage intrinsics(dir + "intrinsics.yml", cv::FileStorage::READ);
  cv::FileStorage extrinsics(dir + "extrinsics.yml", cv::FileStorage::READ);
  cv::Mat m1, d1, m2, d2, r, t;
  intrinsics["M1"] >> m1;
  intrinsics["D1"] >> d1;
  intrinsics["M2"] >> m2;
  intrinsics["D2"] >> d2;
  extrinsics["R"] >> r;
  extrinsics["T"] >> t;
  StereoCalibration owner;
  owner.image_size = cv::Size(640, 512);
  owner.M1 = cv::Matx33d(m1);
  owner.M2 = cv::Matx33d(m2);
  owner.D1 = d1.reshape(1, 1).clone();
  owner.D2 = d2.reshape(1, 1).clone();
  owner.R = cv::Matx33d(r);
  owner.T = cv::Vec3d(t.reshape(1, 3)) * 1e-3;
  return owner;
}

// The camera named "right" becomes the left one: x_left' = R^T x_right' - R^T T.
StereoCalibration SwapLeftAndRight(const StereoCalibration& c) {
  StereoCalibration swapped = c;
  swapped.M1 = c.M2;
  swapped.D1 = c.D2;
  swapped.M2 = c.M1;
  swapped.D2 = c.D1;
  swapped.R = c.R.t();
  swapped.T = -(c.R.t() * c.T);
  return swapped;
}

TEST(StereoRigRealData, XimeaRigIsRefusedUntilSwapped) {
  std::string dir, why;
  const std::optional<StereoCalibration> owner = XimeaOwnerCalibration(dir, why);
  if (!owner) GTEST_SKIP() << why;
  ASSERT_THAT(owner->Validate(), IsEmpty());
  EXPECT_GT(owner->T[0], 0.0);
  Result<StereoRig> refused = StereoRig::FromCalibration(*owner);
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.error().message,
              AllOf(HasSubstr("T_x > 0"), HasSubstr("swap left and right")));

  Result<StereoRig> rig = StereoRig::FromCalibration(SwapLeftAndRight(*owner), "ximea");
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  EXPECT_TRUE(rig->needs_remap());
  EXPECT_NEAR(rig->baseline_m(), 0.0925, 0.002);  // data README: about 92.5 mm
}

// The swapped XIMEA rig on its real chessboard views: the rectified corners of both views lie on
// the same rows, and the corners re-projected through Q measure the board's 24 mm squares.
// (Measured: mean row error 0.08-0.13 px, squares 24.00-24.02 mm.)
TEST(StereoRigRealData, XimeaChessboardRectifiesOntoEqualRows) {
  std::string dir, why;
  const std::optional<StereoCalibration> owner = XimeaOwnerCalibration(dir, why);
  if (!owner) GTEST_SKIP() << why;
  Result<StereoRig> rig = StereoRig::FromCalibration(SwapLeftAndRight(*owner), "ximea");
  ASSERT_TRUE(rig.ok()) << rig.error().message;

  const cv::Size pattern(9, 6);
  int pairs_checked = 0;
  for (const char* index : {"01", "05", "12"}) {
    const cv::Mat raw_left = cv::imread(dir + "right" + index + ".jpg", cv::IMREAD_GRAYSCALE);
    const cv::Mat raw_right = cv::imread(dir + "left" + index + ".jpg", cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(raw_left.empty() || raw_right.empty()) << index;
    cv::Mat rect_left, rect_right;
    ASSERT_TRUE(rig->Rectify(raw_left, raw_right, rect_left, rect_right).ok());
    std::vector<cv::Point2f> corners_left, corners_right;
    if (!cv::findChessboardCorners(rect_left, pattern, corners_left) ||
        !cv::findChessboardCorners(rect_right, pattern, corners_right)) {
      continue;
    }
    const cv::TermCriteria criteria(cv::TermCriteria::EPS | cv::TermCriteria::COUNT, 40, 0.01);
    cv::cornerSubPix(rect_left, corners_left, cv::Size(5, 5), cv::Size(-1, -1), criteria);
    cv::cornerSubPix(rect_right, corners_right, cv::Size(5, 5), cv::Size(-1, -1), criteria);
    // The detector may order the corners from either end; take the ordering that matches.
    if (cv::norm(corners_left.front() - corners_right.front()) >
        cv::norm(corners_left.front() - corners_right.back())) {
      std::reverse(corners_right.begin(), corners_right.end());
    }
    double row_error = 0, square_sum = 0;
    int squares = 0;
    std::vector<cv::Vec3d> points;
    for (std::size_t i = 0; i < corners_left.size(); ++i) {
      row_error += std::abs(corners_left[i].y - corners_right[i].y) / corners_left.size();
      const double d = corners_left[i].x - corners_right[i].x;
      ASSERT_GT(d, 0.0) << index;
      points.push_back(*PointFromDisparity(corners_left[i].x, corners_left[i].y, d, rig->Q()));
    }
    for (int row = 0; row < pattern.height; ++row) {
      for (int col = 0; col + 1 < pattern.width; ++col) {
        square_sum +=
            cv::norm(points[row * pattern.width + col + 1] - points[row * pattern.width + col]);
        ++squares;
      }
    }
    const double square_m = square_sum / squares;
    std::printf("ximea pair %s: mean |v_l - v_r| = %.3f px, square = %.2f mm, depth %.2f m\n",
                index, row_error, square_m * 1e3, points.front()[2]);
    EXPECT_LT(row_error, 0.5) << index;
    EXPECT_NEAR(square_m, 0.024, 0.024 * 0.03) << index;
    ++pairs_checked;
  }
  EXPECT_GE(pairs_checked, 2);
}

}  // namespace
}  // namespace stevi::geometry
