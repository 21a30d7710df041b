// The calibration report's YAML: every field written and read back with values that differ from
// the defaults, and the text byte-identical to a file the writer produced before its fields were
// put in one table (kFixtureYaml), so that stored reports keep reading and writing the same.
#include "core/calibration/report.h"

#include <string>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::calibration {
namespace {

using ::testing::HasSubstr;

// A report whose every field, and every field of each list element, differs from its default.
CalibrationReport FullReport() {
  CalibrationReport r;
  r.created_unix_ms = 1764443700123;
  r.image_size = cv::Size(1280, 720);
  r.board = BoardSpec{.inner_cols = 11, .inner_rows = 8, .square_size_m = 0.0315};
  r.detector = "sb + cornerSubPix";
  r.pairs_given = 23;
  r.pairs_used = 2;
  r.pairs = {{4, "pair-04", 0.21, 0.23, 0.11, 0.31, 0.29},
             {7, "pair \"07\"", 0.27, 0.25, 0.13, 0.42, 0.44}};
  r.rejected = {{1, "pair-01", RejectReason::kNoBoardLeft, "no board in the left image"},
                {9, "", RejectReason::kOutlier, "rms 3.2 px"}};
  r.rms_px = 0.375;
  r.rms_left_px = 0.25;
  r.rms_right_px = 0.5;
  r.epipolar_mean_px = 0.125;
  r.epipolar_max_px = 0.875;
  r.coverage_grid = cv::Size(10, 8);
  r.coverage_mean_view = 0.3125;
  r.coverage_min_view = 0.0625;
  r.coverage_union_left = 0.71875;
  r.coverage_union_right = 0.6875;
  r.fx_left_px = 1001.5;
  r.fy_left_px = 1002.25;
  r.fx_right_px = 999.75;
  r.fy_right_px = 1000.125;
  r.baseline_m = 0.1205;
  r.rectified_f_px = 995.5;
  r.swap_left_right = true;
  r.passed = true;
  r.failures = {{"max_rms_px", 1.42, 1, "stereo RMS 1.42 px > 1 px (max_rms_px)"},
                {"min_pairs", 2, 10, "2 pairs < 10"}};
  r.warnings = {"few pairs", "tab\there"};
  return r;
}

// ReportToYaml(FullReport()) and ReportToYaml(CalibrationReport()) as written before the writer
// and the reader shared one field table.
constexpr const char* kFullYaml = R"yaml(%YAML:1.0
---
created_unix_ms: "1764443700123"
passed: 1
swap_left_right: 1
image_width: 1280
image_height: 720
board:
   inner_cols: 11
   inner_rows: 8
   square_size_m: 3.1500000000000000e-02
detector: "sb + cornerSubPix"
pairs_given: 23
pairs_used: 2
rms_px: 3.7500000000000000e-01
rms_left_px: 2.5000000000000000e-01
rms_right_px: 5.0000000000000000e-01
epipolar_mean_px: 1.2500000000000000e-01
epipolar_max_px: 8.7500000000000000e-01
coverage_grid_cols: 10
coverage_grid_rows: 8
coverage_mean_view: 3.1250000000000000e-01
coverage_min_view: 6.2500000000000000e-02
coverage_union_left: 7.1875000000000000e-01
coverage_union_right: 6.8750000000000000e-01
fx_left_px: 1.0015000000000000e+03
fy_left_px: 1.0022500000000000e+03
fx_right_px: 9.9975000000000000e+02
fy_right_px: 1.0001250000000000e+03
baseline_m: 1.2050000000000000e-01
rectified_f_px: 9.9550000000000000e+02
failures:
   -
      gate: "max_rms_px"
      measured: 1.4199999999999999e+00
      limit: 1.
      message: "stereo RMS 1.42 px > 1 px (max_rms_px)"
   -
      gate: "min_pairs"
      measured: 2.
      limit: 10.
      message: "2 pairs < 10"
warnings:
   - "few pairs"
   - "tab\there"
rejected:
   -
      index: 1
      name: "pair-01"
      reason: no_board_left
      detail: "no board in the left image"
   -
      index: 9
      name: ""
      reason: outlier
      detail: "rms 3.2 px"
pairs:
   -
      index: 4
      name: "pair-04"
      rms_left_px: 2.0999999999999999e-01
      rms_right_px: 2.3000000000000001e-01
      epipolar_mean_px: 1.1000000000000000e-01
      coverage_left: 3.1000000000000000e-01
      coverage_right: 2.8999999999999998e-01
   -
      index: 7
      name: "pair \"07\""
      rms_left_px: 2.7000000000000002e-01
      rms_right_px: 2.5000000000000000e-01
      epipolar_mean_px: 1.3000000000000000e-01
      coverage_left: 4.1999999999999998e-01
      coverage_right: 4.4000000000000000e-01
)yaml";
constexpr const char* kDefaultYaml = R"yaml(%YAML:1.0
---
created_unix_ms: "0"
passed: 0
swap_left_right: 0
image_width: 0
image_height: 0
board:
   inner_cols: 9
   inner_rows: 6
   square_size_m: 2.5000000000000001e-02
detector: ""
pairs_given: 0
pairs_used: 0
rms_px: 0.
rms_left_px: 0.
rms_right_px: 0.
epipolar_mean_px: 0.
epipolar_max_px: 0.
coverage_grid_cols: 0
coverage_grid_rows: 0
coverage_mean_view: 0.
coverage_min_view: 0.
coverage_union_left: 0.
coverage_union_right: 0.
fx_left_px: 0.
fy_left_px: 0.
fx_right_px: 0.
fy_right_px: 0.
baseline_m: 0.
rectified_f_px: 0.
failures:
   []
warnings:
   []
rejected:
   []
pairs:
   []
)yaml";

// Every field, named here one by one (not through the report's own table).
void ExpectSameReport(const CalibrationReport& b, const CalibrationReport& r) {
  EXPECT_EQ(b.created_unix_ms, r.created_unix_ms);
  EXPECT_EQ(b.image_size, r.image_size);
  EXPECT_EQ(b.board.inner_cols, r.board.inner_cols);
  EXPECT_EQ(b.board.inner_rows, r.board.inner_rows);
  EXPECT_EQ(b.board.square_size_m, r.board.square_size_m);
  EXPECT_EQ(b.detector, r.detector);
  EXPECT_EQ(b.pairs_given, r.pairs_given);
  EXPECT_EQ(b.pairs_used, r.pairs_used);
  ASSERT_EQ(b.pairs.size(), r.pairs.size());
  for (std::size_t i = 0; i < r.pairs.size(); ++i) {
    SCOPED_TRACE("pairs[" + std::to_string(i) + "]");
    EXPECT_EQ(b.pairs[i].index, r.pairs[i].index);
    EXPECT_EQ(b.pairs[i].name, r.pairs[i].name);
    EXPECT_EQ(b.pairs[i].rms_left_px, r.pairs[i].rms_left_px);
    EXPECT_EQ(b.pairs[i].rms_right_px, r.pairs[i].rms_right_px);
    EXPECT_EQ(b.pairs[i].epipolar_mean_px, r.pairs[i].epipolar_mean_px);
    EXPECT_EQ(b.pairs[i].coverage_left, r.pairs[i].coverage_left);
    EXPECT_EQ(b.pairs[i].coverage_right, r.pairs[i].coverage_right);
  }
  ASSERT_EQ(b.rejected.size(), r.rejected.size());
  for (std::size_t i = 0; i < r.rejected.size(); ++i) {
    SCOPED_TRACE("rejected[" + std::to_string(i) + "]");
    EXPECT_EQ(b.rejected[i].index, r.rejected[i].index);
    EXPECT_EQ(b.rejected[i].name, r.rejected[i].name);
    EXPECT_EQ(b.rejected[i].reason, r.rejected[i].reason);
    EXPECT_EQ(b.rejected[i].detail, r.rejected[i].detail);
  }
  EXPECT_EQ(b.rms_px, r.rms_px);
  EXPECT_EQ(b.rms_left_px, r.rms_left_px);
  EXPECT_EQ(b.rms_right_px, r.rms_right_px);
  EXPECT_EQ(b.epipolar_mean_px, r.epipolar_mean_px);
  EXPECT_EQ(b.epipolar_max_px, r.epipolar_max_px);
  EXPECT_EQ(b.coverage_grid, r.coverage_grid);
  EXPECT_EQ(b.coverage_mean_view, r.coverage_mean_view);
  EXPECT_EQ(b.coverage_min_view, r.coverage_min_view);
  EXPECT_EQ(b.coverage_union_left, r.coverage_union_left);
  EXPECT_EQ(b.coverage_union_right, r.coverage_union_right);
  EXPECT_EQ(b.fx_left_px, r.fx_left_px);
  EXPECT_EQ(b.fy_left_px, r.fy_left_px);
  EXPECT_EQ(b.fx_right_px, r.fx_right_px);
  EXPECT_EQ(b.fy_right_px, r.fy_right_px);
  EXPECT_EQ(b.baseline_m, r.baseline_m);
  EXPECT_EQ(b.rectified_f_px, r.rectified_f_px);
  EXPECT_EQ(b.swap_left_right, r.swap_left_right);
  EXPECT_EQ(b.passed, r.passed);
  ASSERT_EQ(b.failures.size(), r.failures.size());
  for (std::size_t i = 0; i < r.failures.size(); ++i) {
    SCOPED_TRACE("failures[" + std::to_string(i) + "]");
    EXPECT_EQ(b.failures[i].gate, r.failures[i].gate);
    EXPECT_EQ(b.failures[i].measured, r.failures[i].measured);
    EXPECT_EQ(b.failures[i].limit, r.failures[i].limit);
    EXPECT_EQ(b.failures[i].message, r.failures[i].message);
  }
  EXPECT_EQ(b.warnings, r.warnings);
}

TEST(ReportYaml, TextIsTheSameAsBefore) {
  const Result<std::string> full = ReportToYaml(FullReport());
  ASSERT_TRUE(full.ok()) << full.error().message;
  EXPECT_EQ(*full, kFullYaml);
  const Result<std::string> empty = ReportToYaml(CalibrationReport());
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  EXPECT_EQ(*empty, kDefaultYaml);
}

TEST(ReportYaml, EveryFieldRoundTrips) {
  const CalibrationReport r = FullReport();
  const Result<std::string> yaml = ReportToYaml(r);
  ASSERT_TRUE(yaml.ok()) << yaml.error().message;
  const Result<CalibrationReport> back = ParseReportYaml(*yaml);
  ASSERT_TRUE(back.ok()) << back.error().message;
  ExpectSameReport(*back, r);
  // The file written before the change reads back to the same report.
  const Result<CalibrationReport> old = ParseReportYaml(kFullYaml);
  ASSERT_TRUE(old.ok()) << old.error().message;
  ExpectSameReport(*old, r);
  const Result<CalibrationReport> empty = ParseReportYaml(kDefaultYaml);
  ASSERT_TRUE(empty.ok()) << empty.error().message;
  ExpectSameReport(*empty, CalibrationReport());
}

// Each key the reader needs, when missing, is named in the error.
TEST(ReportYaml, EveryMissingKeyIsNamed) {
  const std::string yaml = kFullYaml;
  for (const char* key : {"created_unix_ms",
                          "passed",
                          "swap_left_right",
                          "image_width",
                          "image_height",
                          "board",
                          "inner_cols",
                          "inner_rows",
                          "square_size_m",
                          "detector",
                          "pairs_given",
                          "pairs_used",
                          "rms_px",
                          "rms_left_px",
                          "rms_right_px",
                          "epipolar_mean_px",
                          "epipolar_max_px",
                          "coverage_grid_cols",
                          "coverage_grid_rows",
                          "coverage_mean_view",
                          "coverage_min_view",
                          "coverage_union_left",
                          "coverage_union_right",
                          "fx_left_px",
                          "fy_left_px",
                          "fx_right_px",
                          "fy_right_px",
                          "baseline_m",
                          "rectified_f_px",
                          "failures",
                          "warnings",
                          "rejected",
                          "pairs",
                          "gate",
                          "measured",
                          "limit",
                          "message",
                          "index",
                          "name",
                          "reason",
                          "detail",
                          "coverage_left",
                          "coverage_right"}) {
    SCOPED_TRACE(key);
    // The first line that starts with the key (after indentation) gets its key renamed.
    std::string damaged = yaml;
    const std::size_t at = damaged.find(std::string(key) + ":");
    ASSERT_NE(at, std::string::npos);
    ASSERT_TRUE(at == 0 || damaged[at - 1] == ' ' || damaged[at - 1] == '\n');
    damaged.insert(at, "x_");
    const Result<CalibrationReport> bad = ParseReportYaml(damaged);
    ASSERT_FALSE(bad.ok());
    EXPECT_THAT(bad.error().message, HasSubstr(std::string(key) + ": missing"));
  }
}

}  // namespace
}  // namespace stevi::calibration
