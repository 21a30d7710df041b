// Calibration files (core/geometry/calibration_io.h): the round trip through the YAML format
// against an ideal rig's analytic values, both matrix spellings, and the errors for a missing,
// unreadable or malformed file, missing keys, wrong matrix sizes and each check of Validate(),
// every one naming the file and the key at fault.
#include "core/geometry/calibration_io.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "core/geometry/range.h"
#include "core/geometry/stereo_rig.h"
#include "tests/core/geometry/calibration_fixtures.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::geometry {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::IsEmpty;
using ::testing::Not;
using ::testing::StartsWith;

using fixtures::kIdealYaml;
using fixtures::MaxAbsDiff;
using fixtures::RawCalibration;
using fixtures::Replace;
using fixtures::WriteFile;

TEST(ParseCalibrationYaml, ReadsTransposedVectors) {
  Result<StereoCalibration> c = ParseCalibrationYaml(kIdealYaml);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->image_size, cv::Size(640, 480));
  EXPECT_EQ(c->M1(0, 0), 500.0);
  EXPECT_EQ(c->T, cv::Vec3d(-0.12, 0, 0));  // given as 1x3
  EXPECT_EQ(c->D2.size(), cv::Size(5, 1));  // given as 5x1, stored as one row
  EXPECT_EQ(c->D2.type(), CV_64FC1);
  EXPECT_FALSE(c->Q.has_value());
}

TEST(ParseCalibrationYaml, AcceptsTextWithoutYamlHeader) {
  const std::string text = Replace(kIdealYaml, "%YAML:1.0\n---\n", "");
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->M2(1, 2), 240.0);
}

TEST(ParseCalibrationYaml, MissingKeyIsNamed) {
  std::string text = kIdealYaml;
  const std::size_t from = text.find("M2:");
  const std::size_t to = text.find("D2:");
  text.erase(from, to - from);
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(
      c, IsError(ErrorCode::kInvalidArgument, HasSubstr("M2: missing (expected a 3x3 matrix)")));
}

TEST(ParseCalibrationYaml, MalformedMatrixIsNamedWithItsShape) {
  const std::string text = Replace(
      kIdealYaml, "   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]",
      "   cols: 2\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240. ]");
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(
      c, IsError(ErrorCode::kInvalidArgument, HasSubstr("M1: expected a 3x3 matrix, got 3x2")));
}

// Fuzz regression (tests/fuzz/corpus/calibration_yaml/regression-huge-matrix): OpenCV allocates
// the announced rows x cols before it checks the data, so the shape is checked before reading.
TEST(ParseCalibrationYaml, AHugeAnnouncedMatrixIsRefusedBeforeItIsAllocated) {
  const std::string text = Replace(
      kIdealYaml,
      "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]",
      "   rows: 100000\n   cols: 100000\n   dt: d\n   data: [ 1. ]");
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument,
                         HasSubstr("M1: expected a 3x3 matrix, got 100000x100000")));

  // A size OpenCV would read from something else than an integer is not handed over either
  // (regression-huge-matrix-text-cols).
  const std::string text_cols = Replace(
      kIdealYaml,
      "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]",
      "   rows: 30000\n   cols: ____30000\n   dt: d\n   data: [ 1. ]");
  Result<StereoCalibration> t = ParseCalibrationYaml(text_cols);
  ASSERT_FALSE(t.ok());
  EXPECT_THAT(t.error().message, HasSubstr("M1: expected a 3x3 matrix (an !!opencv-matrix"));
}

// Fuzz regression (tests/fuzz/corpus/calibration_yaml/regression-empty-key): OpenCV's parser
// reads a line starting with ':' backwards past its buffer and throws std::length_error, which
// escaped the parser; such text is refused before OpenCV sees it.
TEST(ParseCalibrationYaml, AnEmptyKeyIsRefusedBeforeOpenCvParsesIt) {
  for (const std::string& line :
       {std::string(":dt d"), std::string("   :dt d"), std::string(": 3")}) {
    const std::string text = Replace(kIdealYaml, "   dt: d", line);
    Result<StereoCalibration> c = ParseCalibrationYaml(text);
    ASSERT_FALSE(c.ok()) << line;
    EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument));
    EXPECT_THAT(c.error().message, HasSubstr("line 8: an empty key")) << line;
  }
  EXPECT_THAT(YamlTextProblem("a: 1\n  b: 2\n  :c: 3\n"), HasSubstr("line 3: an empty key"));
  EXPECT_EQ(YamlTextProblem("a: \":x\"\nb: [1, 2]\n"), "");
  const std::string path = WriteFile(testing::MakeTempDir("stevi_rig"), "empty-key.yaml",
                                     Replace(kIdealYaml, "   dt: d", "   : d"));
  Result<StereoCalibration> loaded = LoadCalibrationYaml(path);
  ASSERT_FALSE(loaded.ok());
  EXPECT_THAT(loaded.error().message, AllOf(HasSubstr(path), HasSubstr("an empty key")));
}

// Fuzz regression (tests/fuzz/corpus/calibration_yaml/regression-parser-hang-after-dedent):
// OpenCV's parser looped forever on text after the first document's top-level map; only one
// top-level map is handed over.
TEST(ParseCalibrationYaml, TextBeyondTheTopLevelMapIsRefusedBeforeOpenCvLoopsOnIt) {
  const std::string hang = "%YAML:1.0\n---\n \n   rows: 1\nM2v-matrix\n   rowsM";
  Result<StereoCalibration> c = ParseCalibrationYaml(hang);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.error().message, HasSubstr("line 5: indented less than the first line"));
  EXPECT_THAT(YamlTextProblem("a: 1\n...\n-x\n"), HasSubstr("line 2: '...'"));
  EXPECT_THAT(YamlTextProblem("{a: 1}\n-x\n"), HasSubstr("line 1: expected a map"));
  EXPECT_THAT(YamlTextProblem("--- a: 1\n"), HasSubstr("line 1: content on the '---' line"));
  // What the format needs stays accepted: directives, comments, an indented top level.
  EXPECT_EQ(YamlTextProblem("%YAML:1.0\n---\n# c\n  a: 1\n  b:\n     - 2\n# d\n"), "");
  EXPECT_TRUE(ParseCalibrationYaml(kIdealYaml).ok());
}

TEST(ParseCalibrationYaml, ReportsEveryKeyProblemAtOnce) {
  std::string text = Replace(kIdealYaml, "image_width: 640", "image_width: wide");
  text = Replace(text, "rows: 1\n   cols: 5", "rows: 1\n   cols: 6");  // D1 of 6 is not allowed
  text = Replace(text, "data: [ 0., 0., 0., 0., 0. ]", "data: [ 0., 0., 0., 0., 0., 0. ]");
  const std::size_t from = text.find("R:");
  const std::size_t to = text.find("T:");
  text.erase(from, to - from);
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(
      c.error().message,
      AllOf(HasSubstr("image_width: expected a positive integer"),
            HasSubstr("D1: expected a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}, got 1x6"),
            HasSubstr("R: missing"), Not(HasSubstr("M1")), Not(HasSubstr("T:"))));
}

TEST(ParseCalibrationYaml, ScalarWhereMatrixExpectedIsNamed) {
  const std::string text = std::string(kIdealYaml) + "Q: 7\n";
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.error().message, HasSubstr("Q: expected a 4x4 matrix"));
}

TEST(ParseCalibrationYaml, UnparsableTextIsInvalidArgumentWithTheLine) {
  Result<StereoCalibration> c = ParseCalibrationYaml("image_width: 5\nM1: [ 1, 2\n  : : {\n");
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument,
                         AllOf(HasSubstr("not valid YAML"), HasSubstr("line 3"))));
}

TEST(ParseCalibrationYaml, AcceptsPlainListsOfNumbers) {
  std::string text =
      Replace(kIdealYaml,
              "T: !!opencv-matrix\n   rows: 1\n   cols: 3\n   dt: d\n   data: [ -0.12, 0., 0. ]",
              "T: [ -0.25, 0, 0.001 ]");
  text = Replace(text, "M2: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data:", "M2:");
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->T, cv::Vec3d(-0.25, 0, 0.001));
  EXPECT_EQ(c->M2(0, 2), 320.0);
  EXPECT_EQ(c->M2(1, 1), 500.0);

  const std::string wrong_length = Replace(text, "T: [ -0.25, 0, 0.001 ]", "T: [ -0.25, 0 ]");
  Result<StereoCalibration> bad = ParseCalibrationYaml(wrong_length);
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(bad.error().message,
              HasSubstr("T: expected a 3x1 or 1x3 matrix, got a list of 2 numbers"));
}

TEST(ParseCalibrationYaml, TopLevelMustBeAMap) {
  Result<StereoCalibration> c = ParseCalibrationYaml("[ 1, 2, 3 ]\n");
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.error().message, HasSubstr("expected a map"));
}

TEST(ParseCalibrationYaml, InvalidValuesAreReported) {
  std::string text = Replace(kIdealYaml, "data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]",
                             "data: [ 1., 0., 0., 0., 2., 0., 0., 0., 1. ]");
  text = Replace(text, "data: [ -0.12, 0., 0. ]", "data: [ 0., 0., 0. ]");
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c.error().message,
              AllOf(HasSubstr("R: not a rotation"), HasSubstr("T: the baseline")));
}

TEST(LoadCalibrationYaml, MissingFileIsNotFoundAndNamesThePath) {
  const std::string path = testing::MakeTempDir("stevi_rig") + "/nope.yaml";
  Result<StereoCalibration> c = LoadCalibrationYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kNotFound, HasSubstr(path)));
}

TEST(LoadCalibrationYaml, BrokenFileNamesFileAndKey) {
  const std::string dir = testing::MakeTempDir("stevi_rig");
  std::string text = kIdealYaml;
  text.erase(text.find("M2:"), text.find("D2:") - text.find("M2:"));
  const std::string path = WriteFile(dir, "broken.yaml", text);
  Result<StereoCalibration> c = LoadCalibrationYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument, AllOf(HasSubstr(path), HasSubstr("M2"))));

  const std::string garbage = WriteFile(dir, "garbage.yaml", "%YAML:1.0\n---\n[ {: ]]] x\n");
  Result<StereoCalibration> g = LoadCalibrationYaml(garbage);
  ASSERT_FALSE(g.ok());
  EXPECT_THAT(g, IsError(ErrorCode::kInvalidArgument, HasSubstr(garbage)));
}

TEST(SaveCalibrationYaml, RoundTripsEveryField) {
  const std::string dir = testing::MakeTempDir("stevi_rig");
  // A raw calibration with its rectification terms, E and F filled by the rig.
  Result<StereoRig> rig = StereoRig::FromCalibration(RawCalibration());
  ASSERT_TRUE(rig.ok()) << rig.error().message;
  StereoCalibration original = rig->calibration();
  original.E = cv::Matx33d(0, 1, 2, 3, 4, 5, 6, 7, 8.125);
  original.F = cv::Matx33d(1e-7, 2e-6, 3, 4, 5, 6, 7, 8, 1);
  const std::string path = dir + "/rig.yaml";
  ASSERT_TRUE(SaveCalibrationYaml(original, path).ok());

  Result<StereoCalibration> loaded = LoadCalibrationYaml(path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->image_size, original.image_size);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(loaded->M1), cv::Mat(original.M1)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(loaded->M2), cv::Mat(original.M2)), 0.0);
  EXPECT_EQ(MaxAbsDiff(loaded->D1, original.D1), 0.0);
  EXPECT_EQ(MaxAbsDiff(loaded->D2, original.D2), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(loaded->R), cv::Mat(original.R)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(loaded->T), cv::Mat(original.T)), 0.0);
  ASSERT_TRUE(loaded->R1 && loaded->R2 && loaded->P1 && loaded->P2 && loaded->Q && loaded->E &&
              loaded->F);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->R1), cv::Mat(*original.R1)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->R2), cv::Mat(*original.R2)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->P1), cv::Mat(*original.P1)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->P2), cv::Mat(*original.P2)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->Q), cv::Mat(*original.Q)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->E), cv::Mat(*original.E)), 0.0);
  EXPECT_EQ(MaxAbsDiff(cv::Mat(*loaded->F), cv::Mat(*original.F)), 0.0);

  // No temporary file is left beside it.
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    names.push_back(entry.path().filename().string());
  }
  EXPECT_EQ(names, std::vector<std::string>{"rig.yaml"});
}

TEST(SaveCalibrationYaml, OverwritesAndKeepsOptionalTermsAbsent) {
  const std::string dir = testing::MakeTempDir("stevi_rig");
  const std::string path = dir + "/raw.yaml";
  StereoCalibration first = RawCalibration();
  ASSERT_TRUE(SaveCalibrationYaml(IdealCalibration(cv::Size(10, 10), 5, 1, 5, 5), path).ok());
  ASSERT_TRUE(SaveCalibrationYaml(first, path).ok());
  Result<StereoCalibration> loaded = LoadCalibrationYaml(path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->image_size, cv::Size(640, 480));
  EXPECT_FALSE(loaded->R1 || loaded->R2 || loaded->P1 || loaded->P2 || loaded->Q || loaded->E ||
               loaded->F);
}

TEST(SaveCalibrationYaml, RefusesInvalidCalibrationAndLeavesFileAlone) {
  const std::string dir = testing::MakeTempDir("stevi_rig");
  const std::string path = WriteFile(dir, "keep.yaml", kIdealYaml);
  StereoCalibration bad = RawCalibration();
  bad.T = cv::Vec3d(0, 0, 0);
  const Status s = SaveCalibrationYaml(bad, path);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.error().message, HasSubstr("T:"));
  EXPECT_TRUE(LoadCalibrationYaml(path).ok());
}

TEST(StereoCalibrationValidate, ListsEveryProblem) {
  StereoCalibration c = RawCalibration();
  c.image_size = cv::Size(0, 480);
  c.M1(0, 0) = -1;
  c.M2(1, 2) = std::numeric_limits<double>::quiet_NaN();
  c.D2 = cv::Mat::zeros(1, 6, CV_64F);
  c.R = cv::Matx33d(1, 0, 0, 0, 1, 0, 0, 0, -1);  // a reflection
  c.T = cv::Vec3d(0, 0, 0);
  c.Q = cv::Matx44d::eye();
  const std::vector<std::string> problems = c.Validate();
  const std::string all = ::testing::PrintToString(problems);
  EXPECT_THAT(all, AllOf(HasSubstr("image_width, image_height"), HasSubstr("M1: focal"),
                         HasSubstr("M2: has non-finite"), HasSubstr("D2: expected"),
                         HasSubstr("R: not a rotation"), HasSubstr("T: the baseline"),
                         HasSubstr("give all five")));
  EXPECT_EQ(problems.size(), 7u) << all;
  EXPECT_THAT(RawCalibration().Validate(), IsEmpty());
}

TEST(IdealCalibration, MatchesOpenCvStereoRectify) {
  const StereoCalibration ideal = IdealCalibration(cv::Size(640, 480), 600.0, 0.25, 320.0, 240.0);
  cv::Mat r1, r2, p1, p2, q;
  cv::stereoRectify(cv::Mat(ideal.M1), ideal.D1, cv::Mat(ideal.M2), ideal.D2, ideal.image_size,
                    cv::Mat(ideal.R), cv::Mat(ideal.T), r1, r2, p1, p2, q, cv::CALIB_ZERO_DISPARITY,
                    0.0);
  EXPECT_LT(MaxAbsDiff(cv::Mat(*ideal.R1), r1), 1e-9);
  EXPECT_LT(MaxAbsDiff(cv::Mat(*ideal.R2), r2), 1e-9);
  EXPECT_LT(MaxAbsDiff(cv::Mat(*ideal.P1), p1), 1e-6);
  EXPECT_LT(MaxAbsDiff(cv::Mat(*ideal.P2), p2), 1e-6);
  EXPECT_LT(MaxAbsDiff(cv::Mat(*ideal.Q), q), 1e-9);
  EXPECT_THAT(ideal.Validate(), IsEmpty());
}

TEST(IdealCalibration, QGivesDepthFocalBaselineOverDisparity) {
  const double f = 600.0, baseline = 0.25;
  const StereoCalibration ideal = IdealCalibration(cv::Size(640, 480), f, baseline, 310.0, 250.0);
  for (double d : {1.0, 7.5, 40.0}) {
    const std::optional<cv::Vec3d> p = PointFromDisparity(100.0, 300.0, d, *ideal.Q);
    ASSERT_TRUE(p.has_value());
    EXPECT_NEAR((*p)[2], f * baseline / d, 1e-9);
    EXPECT_GT((*p)[2], 0.0);
  }
}

// ---------------------------------------------------------------------------------------------
// The ideal rig of the synthetic scenes (f 700 px, baseline 0.6 m, principal point at the
// centre of a 640x480 image) as the analytic reference.

constexpr double kF = 700.0;
constexpr double kB = 0.6;
constexpr double kCx = 319.5;
constexpr double kCy = 239.5;
const cv::Size kSize(640, 480);

StereoCalibration IdealRig() { return IdealCalibration(kSize, kF, kB, kCx, kCy); }

// Every term of the ideal rig written out by hand: K = [f 0 cx; 0 f cy; 0 0 1] for both
// cameras, R = I, T = (-B, 0, 0); rectification leaves the images as they are (R1 = R2 = I,
// P1 = [K | 0], P2 = [K | (-f B, 0, 0)]), Q maps (x, y, d) to depth f B / d, E = [T]x and
// F = K^-T E K^-1 = [0 0 0; 0 0 B/f; 0 -B/f 0].
struct AnalyticRig {
  cv::Matx33d K{kF, 0, kCx, 0, kF, kCy, 0, 0, 1};
  cv::Vec3d T{-kB, 0, 0};
  cv::Matx34d P1{kF, 0, kCx, 0, 0, kF, kCy, 0, 0, 0, 1, 0};
  cv::Matx34d P2{kF, 0, kCx, -kF* kB, 0, kF, kCy, 0, 0, 0, 1, 0};
  cv::Matx44d Q{1, 0, 0, -kCx, 0, 1, 0, -kCy, 0, 0, 0, kF, 0, 0, 1 / kB, 0};
  cv::Matx33d E{0, 0, 0, 0, 0, kB, 0, -kB, 0};
  cv::Matx33d F{0, 0, 0, 0, 0, kB / kF, 0, -kB / kF, 0};
};

// Expects `c` to be the analytic ideal rig, every element within `tol` (relative to 1).
void ExpectAnalyticIdealRig(const StereoCalibration& c, double tol) {
  const AnalyticRig a;
  EXPECT_EQ(c.image_size, kSize);
  EXPECT_LE(MaxAbsDiff(cv::Mat(c.M1), cv::Mat(a.K)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(c.M2), cv::Mat(a.K)), tol);
  EXPECT_LE(MaxAbsDiff(c.D1, cv::Mat::zeros(1, 5, CV_64F)), tol);
  EXPECT_LE(MaxAbsDiff(c.D2, cv::Mat::zeros(1, 5, CV_64F)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(c.R), cv::Mat(cv::Matx33d::eye())), tol);
  EXPECT_LE(cv::norm(c.T - a.T), tol);
  ASSERT_TRUE(c.R1 && c.R2 && c.P1 && c.P2 && c.Q && c.E && c.F);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.R1), cv::Mat(cv::Matx33d::eye())), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.R2), cv::Mat(cv::Matx33d::eye())), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.P1), cv::Mat(a.P1)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.P2), cv::Mat(a.P2)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.Q), cv::Mat(a.Q)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.E), cv::Mat(a.E)), tol);
  EXPECT_LE(MaxAbsDiff(cv::Mat(*c.F), cv::Mat(a.F)), tol);
}

// One key of a calibration YAML and its node text.
struct Entry {
  std::string key;
  std::string node;
};

// "%YAML:1.0\n---\n" and `key: node` per entry.
std::string Yaml(const std::vector<Entry>& entries) {
  std::string text = "%YAML:1.0\n---\n";
  for (const Entry& e : entries) text += e.key + ": " + e.node + "\n";
  return text;
}

std::string Numbers(const std::vector<double>& values) {
  std::string out = "[ ";
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (i > 0) out += ", ";
    std::ostringstream s;
    s.precision(17);
    s << values[i];
    out += s.str();
  }
  return out + " ]";
}

// An !!opencv-matrix node of doubles (row-major `values`).
std::string MatrixNode(int rows, int cols, const std::vector<double>& values) {
  return "!!opencv-matrix\n   rows: " + std::to_string(rows) +
         "\n   cols: " + std::to_string(cols) + "\n   dt: d\n   data: " + Numbers(values);
}

// A rows x cols matrix node of zeros with a 1 on the diagonal.
std::string EyeNode(int rows, int cols) {
  std::vector<double> values(rows * cols, 0.0);
  for (int i = 0; i < std::min(rows, cols); ++i) values[i * cols + i] = 1.0;
  return MatrixNode(rows, cols, values);
}

template <int R, int C>
std::vector<double> Values(const cv::Matx<double, R, C>& m) {
  return std::vector<double>(m.val, m.val + R * C);
}

// The ideal rig written by hand from AnalyticRig: T as a 3x1 matrix, D1 as a plain list, every
// other matrix as an !!opencv-matrix.
std::vector<Entry> AnalyticEntries() {
  const AnalyticRig a;
  return {{"image_width", "640"},
          {"image_height", "480"},
          {"M1", MatrixNode(3, 3, Values(a.K))},
          {"D1", "[ 0, 0, 0, 0, 0 ]"},
          {"M2", MatrixNode(3, 3, Values(a.K))},
          {"D2", MatrixNode(1, 5, {0, 0, 0, 0, 0})},
          {"R", EyeNode(3, 3)},
          {"T", MatrixNode(3, 1, {a.T[0], a.T[1], a.T[2]})},
          {"R1", EyeNode(3, 3)},
          {"R2", EyeNode(3, 3)},
          {"P1", MatrixNode(3, 4, Values(a.P1))},
          {"P2", MatrixNode(3, 4, Values(a.P2))},
          {"Q", MatrixNode(4, 4, Values(a.Q))},
          {"E", MatrixNode(3, 3, Values(a.E))},
          {"F", MatrixNode(3, 3, Values(a.F))}};
}

// The entries with `key`'s node replaced (or, with nullopt, the key left out).
std::vector<Entry> With(std::vector<Entry> entries, const std::string& key,
                        const std::optional<std::string>& node) {
  std::vector<Entry> out;
  bool found = false;
  for (Entry& e : entries) {
    if (e.key != key) {
      out.push_back(std::move(e));
      continue;
    }
    found = true;
    if (node) out.push_back({key, *node});
  }
  EXPECT_TRUE(found) << key;
  return out;
}

// The error of parsing `text`, which must fail with kInvalidArgument.
std::string ParseError(const std::string& text) {
  Result<StereoCalibration> c = ParseCalibrationYaml(text);
  if (c.ok()) {
    ADD_FAILURE() << "parsed although it should not:\n" << text;
    return "";
  }
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument));
  return c.error().message;
}

// One fresh folder per test, removed at the end.
class CalibrationFileTest : public ::testing::Test {
 protected:
  void SetUp() override { dir_ = testing::MakeTempDir("stevi_calibration_io"); }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  std::string dir_;
};

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// ---------------------------------------------------------------------------------------------
// Round trips.

TEST_F(CalibrationFileTest, IdealRigRoundTripsThroughAFileToItsAnalyticValues) {
  const std::string path = Path("ideal.yaml");
  const Status saved = SaveCalibrationYaml(IdealRig(), path);
  ASSERT_TRUE(saved.ok()) << saved.error().message;
  Result<StereoCalibration> loaded = LoadCalibrationYaml(path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ExpectAnalyticIdealRig(*loaded, 1e-12);
  EXPECT_THAT(loaded->Validate(), IsEmpty());
  // The file holds exactly the text CalibrationYamlText gives, an OpenCV YAML document.
  Result<std::string> text = CalibrationYamlText(IdealRig());
  ASSERT_TRUE(text.ok()) << text.error().message;
  EXPECT_EQ(ReadAll(path), *text);
  EXPECT_THAT(*text, StartsWith("%YAML:1.0\n"));
}

TEST(IdealCalibration, IsTheAnalyticRig) { ExpectAnalyticIdealRig(IdealRig(), 1e-12); }

TEST(CalibrationYamlText, HandWrittenIdealRigParsesToTheAnalyticValues) {
  Result<StereoCalibration> c = ParseCalibrationYaml(Yaml(AnalyticEntries()));
  ASSERT_TRUE(c.ok()) << c.error().message;
  ExpectAnalyticIdealRig(*c, 1e-12);
  // D1 was a plain list and T a column: stored as one row and a vector.
  EXPECT_EQ(c->D1.size(), cv::Size(5, 1));
  EXPECT_EQ(c->D1.type(), CV_64FC1);
}

TEST(CalibrationYamlText, RawRigWithEveryDistortionLengthRoundTripsExactly) {
  for (int n : {4, 5, 8, 12, 14}) {
    StereoCalibration original = RawCalibration();
    original.D1 = cv::Mat(1, n, CV_64F);
    original.D2 = cv::Mat(1, n, CV_64F);
    for (int i = 0; i < n; ++i) {
      original.D1.at<double>(i) = 0.1 / (i + 1) - 0.03;  // not exact in binary
      original.D2.at<double>(i) = -1e-5 * (i + 1) / 3.0;
    }
    Result<std::string> text = CalibrationYamlText(original);
    ASSERT_TRUE(text.ok()) << n << ": " << text.error().message;
    Result<StereoCalibration> parsed = ParseCalibrationYaml(*text);
    ASSERT_TRUE(parsed.ok()) << n << ": " << parsed.error().message;
    // Written with 17 significant digits: every double comes back bit for bit.
    EXPECT_EQ(parsed->image_size, original.image_size);
    EXPECT_EQ(MaxAbsDiff(cv::Mat(parsed->M1), cv::Mat(original.M1)), 0.0) << n;
    EXPECT_EQ(MaxAbsDiff(cv::Mat(parsed->M2), cv::Mat(original.M2)), 0.0) << n;
    EXPECT_EQ(parsed->D1.size(), cv::Size(n, 1));
    EXPECT_EQ(MaxAbsDiff(parsed->D1, original.D1), 0.0) << n;
    EXPECT_EQ(MaxAbsDiff(parsed->D2, original.D2), 0.0) << n;
    EXPECT_EQ(MaxAbsDiff(cv::Mat(parsed->R), cv::Mat(original.R)), 0.0) << n;
    EXPECT_EQ(parsed->T, original.T) << n;
    EXPECT_FALSE(parsed->R1 || parsed->R2 || parsed->P1 || parsed->P2 || parsed->Q || parsed->E ||
                 parsed->F);
  }
}

TEST(CalibrationYamlText, RefusesAnInvalidCalibrationNamingTheProblem) {
  StereoCalibration bad = IdealRig();
  bad.M2(1, 1) = 0;
  Result<std::string> text = CalibrationYamlText(bad);
  ASSERT_FALSE(text.ok());
  EXPECT_THAT(text, IsError(ErrorCode::kInvalidArgument));
  EXPECT_THAT(text.error().message, AllOf(StartsWith("refusing to write an invalid calibration: "),
                                          HasSubstr("M2: focal lengths fx, fy must be > 0")));
}

// ---------------------------------------------------------------------------------------------
// Missing and unreadable files.

TEST_F(CalibrationFileTest, AFolderIsNotACalibrationFile) {
  Result<StereoCalibration> c = LoadCalibrationYaml(dir_);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(c.error().message, dir_ + ": is a directory, not a calibration file");
}

TEST_F(CalibrationFileTest, MissingFileMessageNamesThePath) {
  const std::string path = Path("absent/rig.yaml");
  Result<StereoCalibration> c = LoadCalibrationYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kNotFound));
  EXPECT_EQ(c.error().message, "calibration file not found: " + path);
}

TEST_F(CalibrationFileTest, EmptyOrUnparsableFilesAreInvalidAndNamed) {
  for (const std::string& text :
       {std::string(), std::string("%YAML:1.0\n---\nimage_width: 5\nM1: [ 1, 2\n  : : {\n")}) {
    const std::string path = WriteFile(dir_, "bad.yaml", text);
    Result<StereoCalibration> c = LoadCalibrationYaml(path);
    ASSERT_FALSE(c.ok()) << text;
    EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument,
                           StartsWith(path + ": not a valid calibration YAML file (")));
  }
}

TEST_F(CalibrationFileTest, ProblemsInAFileArePrefixedWithItsPath) {
  const std::string path =
      WriteFile(dir_, "small_m1.yaml",
                Yaml(With(AnalyticEntries(), "M1", MatrixNode(3, 2, {1, 2, 3, 4, 5, 6}))));
  Result<StereoCalibration> c = LoadCalibrationYaml(path);
  ASSERT_FALSE(c.ok());
  EXPECT_THAT(c, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(c.error().message, path + ": M1: expected a 3x3 matrix, got 3x2");

  const std::string list = WriteFile(dir_, "list.yaml", "%YAML:1.0\n---\n[ 1, 2 ]\n");
  Result<StereoCalibration> l = LoadCalibrationYaml(list);
  ASSERT_FALSE(l.ok());
  EXPECT_THAT(l.error().message, AllOf(StartsWith(list + ": "), HasSubstr("expected a map")));
}

TEST_F(CalibrationFileTest, SavingIntoAMissingFolderFailsNamingThePath) {
  const std::string path = Path("absent/rig.yaml");
  const Status s = SaveCalibrationYaml(IdealRig(), path);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s.error().message, StartsWith(path + ": "));
  EXPECT_FALSE(std::filesystem::exists(Path("absent")));
}

TEST_F(CalibrationFileTest, SavingAnInvalidCalibrationCreatesNoFile) {
  const std::string path = Path("new.yaml");
  StereoCalibration bad = IdealRig();
  bad.D1 = cv::Mat();
  const Status s = SaveCalibrationYaml(bad, path);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(s, IsError(ErrorCode::kInvalidArgument));
  EXPECT_EQ(s.error().message,
            path +
                ": refusing to write an invalid calibration: D1: expected a 1xN CV_64F row with N "
                "in {4, 5, 8, 12, 14}, got nothing");
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_TRUE(std::filesystem::is_empty(dir_));
}

// ---------------------------------------------------------------------------------------------
// Keys: missing, of the wrong size, malformed.

TEST(ParseCalibrationYaml, EveryMissingRequiredKeyIsNamedAlone) {
  const std::vector<std::pair<std::string, std::string>> required = {
      {"image_width", "a positive integer"},
      {"image_height", "a positive integer"},
      {"M1", "a 3x3 matrix"},
      {"D1", "a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}"},
      {"M2", "a 3x3 matrix"},
      {"D2", "a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}"},
      {"R", "a 3x3 matrix"},
      {"T", "a 3x1 or 1x3 matrix"}};
  for (const auto& [key, expected] : required) {
    EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), key, std::nullopt))),
              key + ": missing (expected " + expected + ")");
  }
  // The rectification terms, E and F are optional: without them the file is valid.
  std::vector<Entry> minimal = AnalyticEntries();
  for (const char* key : {"R1", "R2", "P1", "P2", "Q", "E", "F"}) {
    minimal = With(minimal, key, std::nullopt);
  }
  Result<StereoCalibration> c = ParseCalibrationYaml(Yaml(minimal));
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_FALSE(c->R1 || c->R2 || c->P1 || c->P2 || c->Q || c->E || c->F);
}

TEST(ParseCalibrationYaml, EveryMatrixOfTheWrongSizeIsNamedWithItsShape) {
  struct Case {
    std::string key;
    int rows, cols;
    std::string expected;
  };
  const std::string dist = "a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}";
  const std::vector<Case> cases = {{"M1", 3, 2, "a 3x3 matrix"},
                                   {"M2", 2, 3, "a 3x3 matrix"},
                                   {"D1", 2, 5, dist},
                                   {"D2", 1, 6, dist},
                                   {"R", 4, 4, "a 3x3 matrix"},
                                   {"T", 2, 2, "a 3x1 or 1x3 matrix"},
                                   {"T", 1, 4, "a 3x1 or 1x3 matrix"},
                                   {"R1", 3, 4, "a 3x3 matrix"},
                                   {"R2", 1, 9, "a 3x3 matrix"},
                                   {"P1", 3, 3, "a 3x4 matrix"},
                                   {"P2", 4, 3, "a 3x4 matrix"},
                                   {"Q", 3, 4, "a 4x4 matrix"},
                                   {"E", 9, 1, "a 3x3 matrix"},
                                   {"F", 2, 2, "a 3x3 matrix"}};
  for (const Case& c : cases) {
    const std::string node = EyeNode(c.rows, c.cols);
    EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), c.key, node))),
              c.key + ": expected " + c.expected + ", got " + std::to_string(c.rows) + "x" +
                  std::to_string(c.cols));
  }
}

TEST(ParseCalibrationYaml, PlainListsOfTheWrongLengthAreNamed) {
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "M1", "[ 1, 0, 0, 0, 1, 0, 0, 0 ]"))),
            "M1: expected a 3x3 matrix, got a list of 8 numbers");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "D1", "[ 0, 0, 0, 0, 0, 0 ]"))),
            "D1: expected a 1xN or Nx1 matrix with N in {4, 5, 8, 12, 14}, got a list of 6 "
            "numbers");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "P1", "[ 1, 0, 0, 0, 1, 0, 0, 0, 1 ]"))),
            "P1: expected a 3x4 matrix, got a list of 9 numbers");
  // The same numbers as a list of the right length are read row-major.
  Result<StereoCalibration> c = ParseCalibrationYaml(
      Yaml(With(AnalyticEntries(), "M1", "[ 700, 0, 319.5, 0, 700, 239.5, 0, 0, 1 ]")));
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->M1, AnalyticRig().K);
}

TEST(ParseCalibrationYaml, MalformedValuesAreNamedWithWhatIsWrong) {
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "F", "[ 1, x, 0, 0, 0, 0, 0, 0, 0 ]"))),
            "F: expected a 3x3 matrix, got a list with a non-number");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "E", "[ .nan, 0, 0, 0, 0, 0, 0, 0, 0 ]"))),
            "E: has non-finite values");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "M2",
                                 "!!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ "
                                 ".inf, 0, 320, 0, 700, 240, 0, 0, 1 ]"))),
            "M2: has non-finite values");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "R", "{ a: 1 }"))),
            "R: expected a 3x3 matrix (an !!opencv-matrix with rows, cols, dt and data, or a list "
            "of numbers)");
  EXPECT_EQ(
      ParseError(Yaml(With(AnalyticEntries(), "Q",
                           "!!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: \"3d\"\n   data: " +
                               Numbers(std::vector<double>(48, 0.0))))),
      "Q: expected a 4x4 matrix, got 3 channels");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "T", "0.6"))),
            "T: expected a 3x1 or 1x3 matrix, got a single value");
}

TEST(ParseCalibrationYaml, ImageSizeMustBePositiveIntegers) {
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "image_width", "0"))),
            "image_width: expected a positive integer, got 0");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "image_height", "-3"))),
            "image_height: expected a positive integer, got -3");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "image_width", "640.5"))),
            "image_width: expected a positive integer");
  EXPECT_EQ(ParseError(Yaml(With(AnalyticEntries(), "image_height", "\"480\""))),
            "image_height: expected a positive integer");
}

TEST(ParseCalibrationYaml, ValuesAreValidatedOnceEveryKeyIsRead) {
  // Readable keys with invalid values: Validate()'s problems, all of them.
  std::vector<Entry> entries = With(AnalyticEntries(), "R2", std::nullopt);
  entries = With(entries, "M1", MatrixNode(3, 3, {700, 0, 319.5, 0, 700, 239.5, 0, 0, 2}));
  EXPECT_EQ(ParseError(Yaml(entries)),
            "M1: last row must be (0 0 1); R1, R2, P1, P2, Q: give all five rectification terms "
            "or none (got 4)");
  // A key that cannot be read hides the value checks (no second report of the same key).
  entries = With(entries, "T", std::nullopt);
  EXPECT_EQ(ParseError(Yaml(entries)), "T: missing (expected a 3x1 or 1x3 matrix)");
}

// ---------------------------------------------------------------------------------------------
// Validate(): each check, one defect at a time.

TEST(StereoCalibrationValidate, EachDefectIsNamedAlone) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    std::string expected;
    std::function<void(StereoCalibration&)> spoil;
  };
  const std::vector<Case> cases = {
      {"image_width, image_height: must be > 0 (got 640x0)",
       [](StereoCalibration& c) { c.image_size.height = 0; }},
      {"M1: has non-finite values", [&](StereoCalibration& c) { c.M1(0, 2) = inf; }},
      {"M1: focal lengths fx, fy must be > 0", [](StereoCalibration& c) { c.M1(0, 0) = -700; }},
      {"M2: focal lengths fx, fy must be > 0", [](StereoCalibration& c) { c.M2(1, 1) = 0; }},
      {"M2: last row must be (0 0 1)", [](StereoCalibration& c) { c.M2(2, 0) = 1e-3; }},
      {"D1: expected a 1xN CV_64F row with N in {4, 5, 8, 12, 14}, got nothing",
       [](StereoCalibration& c) { c.D1 = cv::Mat(); }},
      {"D1: expected a 1xN CV_64F row with N in {4, 5, 8, 12, 14}, got 5x1",
       [](StereoCalibration& c) { c.D1 = cv::Mat::zeros(5, 1, CV_64F); }},
      {"D2: expected a 1xN CV_64F row with N in {4, 5, 8, 12, 14}, got 1x6",
       [](StereoCalibration& c) { c.D2 = cv::Mat::zeros(1, 6, CV_64F); }},
      {"D2: expected a 1xN CV_64F row with N in {4, 5, 8, 12, 14}, got 1x5",
       [](StereoCalibration& c) { c.D2 = cv::Mat::zeros(1, 5, CV_32F); }},
      {"D2: has non-finite values", [&](StereoCalibration& c) { c.D2.at<double>(0, 1) = nan; }},
      {"R: has non-finite values", [&](StereoCalibration& c) { c.R(1, 1) = nan; }},
      {"R: not a rotation", [](StereoCalibration& c) { c.R = c.R * 1.01; }},
      {"R: not a rotation", [](StereoCalibration& c) { c.R(2, 2) = -1; }},  // a reflection
      {"T: has non-finite values", [&](StereoCalibration& c) { c.T[2] = inf; }},
      {"T: the baseline |T| must be > 0", [](StereoCalibration& c) { c.T = cv::Vec3d(0, 0, 0); }},
      {"R1, R2, P1, P2, Q: give all five rectification terms or none (got 4)",
       [](StereoCalibration& c) { c.Q.reset(); }},
      {"R1: not a rotation", [](StereoCalibration& c) { (*c.R1)(0, 1) = 0.5; }},
      {"R2: has non-finite values", [&](StereoCalibration& c) { (*c.R2)(0, 0) = nan; }},
      {"P1: focal lengths must be > 0", [](StereoCalibration& c) { (*c.P1)(1, 1) = 0; }},
      {"P2: has non-finite values", [&](StereoCalibration& c) { (*c.P2)(0, 3) = nan; }},
      {"Q: has non-finite values", [&](StereoCalibration& c) { (*c.Q)(3, 2) = inf; }},
      {"E: has non-finite values", [&](StereoCalibration& c) { (*c.E)(1, 2) = nan; }},
      {"F: has non-finite values", [&](StereoCalibration& c) { (*c.F)(2, 1) = -inf; }},
  };
  for (const Case& k : cases) {
    StereoCalibration c = IdealRig();
    k.spoil(c);
    const std::vector<std::string> problems = c.Validate();
    ASSERT_EQ(problems.size(), 1u) << k.expected << ": " << ::testing::PrintToString(problems);
    EXPECT_THAT(problems[0], StartsWith(k.expected));
  }
}

TEST(StereoCalibrationValidate, AcceptsWhatTheFormatAllows) {
  EXPECT_THAT(IdealRig().Validate(), IsEmpty());
  // Every distortion length, and no rectification terms at all.
  for (int n : {4, 5, 8, 12, 14}) {
    StereoCalibration c = RawCalibration();
    c.D1 = cv::Mat::zeros(1, n, CV_64F);
    c.D2 = cv::Mat::zeros(1, n, CV_64F);
    EXPECT_THAT(c.Validate(), IsEmpty()) << n;
  }
  // R is a rotation to 1e-3 (|R R^T - I| and |det R - 1|): a rounded rotation passes, a clearly
  // scaled one does not.
  StereoCalibration rounded = IdealRig();
  rounded.R = rounded.R * (1 + 2e-4);
  EXPECT_THAT(rounded.Validate(), IsEmpty());
  rounded.R = IdealRig().R * (1 + 2e-3);
  EXPECT_THAT(::testing::PrintToString(rounded.Validate()), HasSubstr("R: not a rotation"));
}

}  // namespace
}  // namespace stevi::geometry
