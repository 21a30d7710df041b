// Fuzz target: the calibration store's YAML files, parsed by OpenCV's cv::FileStorage and read by
// our code: a stereo calibration (core/geometry/calibration_io.h ParseCalibrationYaml, also what
// a recording's manifest and a --calibration file hold) and a calibration's quality report
// (core/calibration/report.h ParseReportYaml).
//
// Input: byte 0 picks the parser (even: calibration, odd: report); the rest is the YAML text.
// Checked besides the sanitizers:
//   - an accepted calibration passes Validate(), writes back (CalibrationYamlText) and parses back
//     to the same calibration: equal values (-0.0 may come back as 0.0, as OpenCV writes it);
//   - an accepted report writes back (ReportToYaml) and parses back to the same report (NaN equal
//     to NaN), and its text summary (FormatReportText) can be made;
//   - nothing throws out.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include "core/calibration/report.h"
#include "core/geometry/calibration_io.h"
#include "tests/fuzz/require.h"

namespace calibration = stevi::calibration;
namespace geometry = stevi::geometry;

namespace {

using stevi::fuzz::Require;

// ---- Calibration ------------------------------------------------------------------------------

// Equal values, as the product compares them (drivers/recording RigsIdentical): every finite
// double comes back exactly, but OpenCV writes -0.0 as "0.", which is equal, not the same bits.
bool Same(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

bool Same(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type() || a.type() != CV_64FC1) return false;
  for (int r = 0; r < a.rows; ++r) {
    for (int c = 0; c < a.cols; ++c) {
      if (!Same(a.at<double>(r, c), b.at<double>(r, c))) return false;
    }
  }
  return true;
}

template <int R, int C>
bool Same(const cv::Matx<double, R, C>& a, const cv::Matx<double, R, C>& b) {
  for (int i = 0; i < R * C; ++i) {
    if (!Same(a.val[i], b.val[i])) return false;
  }
  return true;
}

template <int R, int C>
bool Same(const std::optional<cv::Matx<double, R, C>>& a,
          const std::optional<cv::Matx<double, R, C>>& b) {
  return a.has_value() == b.has_value() && (!a || Same(*a, *b));
}

bool Same(const geometry::StereoCalibration& a, const geometry::StereoCalibration& b) {
  return a.image_size == b.image_size && Same(a.M1, b.M1) && Same(a.M2, b.M2) && Same(a.D1, b.D1) &&
         Same(a.D2, b.D2) && Same(a.R, b.R) && Same(cv::Matx31d(a.T.val), cv::Matx31d(b.T.val)) &&
         Same(a.R1, b.R1) && Same(a.R2, b.R2) && Same(a.P1, b.P1) && Same(a.P2, b.P2) &&
         Same(a.Q, b.Q) && Same(a.E, b.E) && Same(a.F, b.F);
}

void FuzzCalibration(const std::string& text) {
  const stevi::Result<geometry::StereoCalibration> parsed = geometry::ParseCalibrationYaml(text);
  if (!parsed.ok()) return;
  Require(parsed->Validate().empty());
  const stevi::Result<std::string> written = geometry::CalibrationYamlText(*parsed);
  Require(written.ok());
  const stevi::Result<geometry::StereoCalibration> again = geometry::ParseCalibrationYaml(*written);
  Require(again.ok());
  Require(Same(*parsed, *again));
}

// ---- Report -----------------------------------------------------------------------------------

bool Same(const calibration::PairReport& a, const calibration::PairReport& b) {
  return a.index == b.index && a.name == b.name && Same(a.rms_left_px, b.rms_left_px) &&
         Same(a.rms_right_px, b.rms_right_px) && Same(a.epipolar_mean_px, b.epipolar_mean_px) &&
         Same(a.coverage_left, b.coverage_left) && Same(a.coverage_right, b.coverage_right);
}

bool Same(const calibration::RejectedPair& a, const calibration::RejectedPair& b) {
  return a.index == b.index && a.name == b.name && a.reason == b.reason && a.detail == b.detail;
}

bool Same(const calibration::GateFailure& a, const calibration::GateFailure& b) {
  return a.gate == b.gate && Same(a.measured, b.measured) && Same(a.limit, b.limit) &&
         a.message == b.message;
}

template <class T>
bool SameList(const std::vector<T>& a, const std::vector<T>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!Same(a[i], b[i])) return false;
  }
  return true;
}

bool Same(const calibration::CalibrationReport& a, const calibration::CalibrationReport& b) {
  return a.created_unix_ms == b.created_unix_ms && a.image_size == b.image_size &&
         a.board.inner_cols == b.board.inner_cols && a.board.inner_rows == b.board.inner_rows &&
         Same(a.board.square_size_m, b.board.square_size_m) && a.detector == b.detector &&
         a.pairs_given == b.pairs_given && a.pairs_used == b.pairs_used &&
         SameList(a.pairs, b.pairs) && SameList(a.rejected, b.rejected) &&
         Same(a.rms_px, b.rms_px) && Same(a.rms_left_px, b.rms_left_px) &&
         Same(a.rms_right_px, b.rms_right_px) && Same(a.epipolar_mean_px, b.epipolar_mean_px) &&
         Same(a.epipolar_max_px, b.epipolar_max_px) && a.coverage_grid == b.coverage_grid &&
         Same(a.coverage_mean_view, b.coverage_mean_view) &&
         Same(a.coverage_min_view, b.coverage_min_view) &&
         Same(a.coverage_union_left, b.coverage_union_left) &&
         Same(a.coverage_union_right, b.coverage_union_right) && Same(a.fx_left_px, b.fx_left_px) &&
         Same(a.fy_left_px, b.fy_left_px) && Same(a.fx_right_px, b.fx_right_px) &&
         Same(a.fy_right_px, b.fy_right_px) && Same(a.baseline_m, b.baseline_m) &&
         Same(a.rectified_f_px, b.rectified_f_px) && a.swap_left_right == b.swap_left_right &&
         a.passed == b.passed && SameList(a.failures, b.failures) && a.warnings == b.warnings;
}

void FuzzReport(const std::string& text) {
  const stevi::Result<calibration::CalibrationReport> parsed = calibration::ParseReportYaml(text);
  if (!parsed.ok()) return;
  (void)calibration::FormatReportText(*parsed);
  const stevi::Result<std::string> written = calibration::ReportToYaml(*parsed);
  Require(written.ok());
  const stevi::Result<calibration::CalibrationReport> again =
      calibration::ParseReportYaml(*written);
  Require(again.ok());
  Require(Same(*parsed, *again));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  if ((data[0] & 1) == 0) {
    FuzzCalibration(text);
  } else {
    FuzzReport(text);
  }
  return 0;
}
