// Calibration of a real stereo rig from its chessboard captures
// (../shared/data/calib_ximea_stereo): 25 pairs of 640x512 grey JPEGs, a board of 6x9 inner corners
// of 24 mm, the camera named left physically on the right.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "core/calibration/calibrate.h"
#include "core/geometry/stereo_rig.h"
#include "tests/testing/data.h"

namespace stevi::calibration {
namespace {

using ::testing::Contains;
using ::testing::HasSubstr;

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The rig owner's focal lengths (intrinsics.yml: M1, M2), if the file is there and readable.
std::optional<std::pair<double, double>> OwnerFocalLengths(const std::string& path) {
  try {
    cv::FileStorage fs(path, cv::FileStorage::READ);
    if (!fs.isOpened()) return std::nullopt;
    cv::Mat m1, m2;
    fs["M1"] >> m1;
    fs["M2"] >> m2;
    if (m1.size() != cv::Size(3, 3) || m2.size() != cv::Size(3, 3)) return std::nullopt;
    return std::make_pair(m1.at<double>(0, 0), m2.at<double>(0, 0));
  } catch (const cv::Exception&) {
    return std::nullopt;
  }
}

TEST(RealCaptures, CalibratesTheXimeaRig) {
  const std::optional<std::string> data = testing::DataDir();
  if (!data)
    GTEST_SKIP() << "reference data not found at " << testing::DataDirWanted()
                 << " (set STEVI_DATA_DIR)";
  const std::string dir = *data + "/calib_ximea_stereo";
  if (!std::filesystem::is_directory(dir)) GTEST_SKIP() << dir << " is missing";

  std::vector<ImagePair> pairs;
  for (int i = 1; i <= 25; ++i) {
    char left[32], right[32];
    std::snprintf(left, sizeof left, "left%02d.jpg", i);
    std::snprintf(right, sizeof right, "right%02d.jpg", i);
    pairs.push_back({ReadBytes(dir + "/" + left), ReadBytes(dir + "/" + right), left});
  }
  CalibrationOptions options;
  options.board = BoardSpec{6, 9, 0.024};

  const auto t0 = std::chrono::steady_clock::now();
  const Result<DetectedPairs> detected = DetectPairs(pairs, options);
  const auto t1 = std::chrono::steady_clock::now();
  ASSERT_TRUE(detected.ok()) << detected.error().message;
  const Result<CalibrationResult> result = CalibrateFromCorners(*detected, options);
  const auto t2 = std::chrono::steady_clock::now();
  ASSERT_TRUE(result.ok()) << result.error().message;
  const CalibrationReport& r = result->report;
  const geometry::StereoCalibration& c = result->calibration;
  std::printf("%s", FormatReportText(r).c_str());
  std::printf("detection %.2f s, calibration %.2f s\n",
              std::chrono::duration<double>(t1 - t0).count(),
              std::chrono::duration<double>(t2 - t1).count());

  // left10.jpg has no (complete) board; its right image does.
  EXPECT_EQ(r.pairs_given, 25);
  EXPECT_EQ(r.pairs_used, 24);
  ASSERT_EQ(r.rejected.size(), 1u);
  EXPECT_EQ(r.rejected[0].name, "left10.jpg");
  EXPECT_EQ(r.rejected[0].index, 9);
  EXPECT_EQ(r.rejected[0].reason, RejectReason::kNoBoardLeft);
  EXPECT_EQ(r.rejected[0].detail, "no board of 6x9 inner corners found in the left image");

  EXPECT_LE(r.rms_px, 0.25);
  EXPECT_LE(r.epipolar_mean_px, 0.25);
  EXPECT_NEAR(1000 * r.baseline_m, 92.5, 2.0);
  EXPECT_TRUE(r.passed);
  // The camera named left is on the right: detected, and the calibration returned with the roles
  // swapped so that the rig accepts it.
  EXPECT_TRUE(r.swap_left_right);
  EXPECT_THAT(r.warnings, Contains(HasSubstr("left and right swapped")));
  EXPECT_LT(c.T[0], 0);
  const Result<geometry::StereoRig> rig = geometry::StereoRig::FromCalibration(c);
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  std::printf("rig: rectified f %.2f px, baseline %.2f mm\n", rig->f_px(),
              1000 * rig->baseline_m());
  EXPECT_NEAR(1000 * rig->baseline_m(), 92.5, 2.0);

  // The owner's calibration (same focal length for both cameras, rational model): about 518 px.
  if (const auto owner = OwnerFocalLengths(dir + "/intrinsics.yml")) {
    // Camera 1 of the result is the owner's M2 (the images named right), camera 2 the owner's M1.
    std::printf("fx: %.2f / %.2f px; owner's intrinsics.yml: %.2f / %.2f px\n", c.M1(0, 0),
                c.M2(0, 0), owner->second, owner->first);
    EXPECT_NEAR(c.M1(0, 0), owner->second, 0.005 * owner->second);
    EXPECT_NEAR(c.M2(0, 0), owner->first, 0.005 * owner->first);
  } else {
    std::printf("intrinsics.yml not readable: no comparison with the owner's focal length\n");
  }

  // Named the right way round (left and right exchanged), nothing is swapped and the figures agree.
  DetectedPairs exchanged = *detected;
  for (PairCorners& p : exchanged.pairs) std::swap(p.left, p.right);
  const Result<CalibrationResult> straight = CalibrateFromCorners(exchanged, options);
  ASSERT_TRUE(straight.ok()) << straight.error().message;
  EXPECT_FALSE(straight->report.swap_left_right);
  EXPECT_NEAR(straight->report.rms_px, r.rms_px, 1e-3);
  EXPECT_NEAR(straight->calibration.M1(0, 0), c.M1(0, 0), 0.05);
  EXPECT_NEAR(cv::norm(straight->calibration.T - c.T), 0, 1e-4);
}

}  // namespace
}  // namespace stevi::calibration
