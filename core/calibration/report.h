// The quality report of a stereo calibration, as text for people and as YAML for the store.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/calibration/chessboard.h"
#include "core/common/error.h"

namespace stevi::calibration {

// Why an input pair was left out of the calibration.
enum class RejectReason {
  kUndecodable,   // not a PNG or JPEG, a malformed header, corrupt data, an unsupported cv::Mat
  kTooLarge,      // the header announced more than CalibrationOptions::max_image_size
  kSizeMismatch,  // the left and right images differ in size
  kSizeDiffers,   // the pair's size differs from the size of most pairs
  kNoBoardLeft,   // no complete board in the left image (the right one has it)
  kNoBoardRight,  // no complete board in the right image (the left one has it)
  kNoBoard,       // no complete board in either image
  kOutlier,       // its reprojection error was far above the other pairs'
                  // (CalibrationOptions::outlier_factor)
};

// "undecodable", "too_large", "size_mismatch", "size_differs", "no_board_left", "no_board_right",
// "no_board", "outlier".
std::string_view RejectReasonName(RejectReason reason);

struct RejectedPair {
  int index = 0;     // position in the input list
  std::string name;  // the pair's name as given (may be empty)
  RejectReason reason = RejectReason::kUndecodable;
  std::string detail;  // "left image: not a PNG or JPEG image (starts with 47 49 46 38)"
};

// One pair used in the calibration. "left" and "right" are the cameras of the returned
// calibration: with swap_left_right they are the input's right and left images.
struct PairReport {
  int index = 0;
  std::string name;
  double rms_left_px = 0;       // RMS reprojection error of this view in camera 1 (pixels)
  double rms_right_px = 0;      // ... in camera 2
  double epipolar_mean_px = 0;  // mean |y_left - y_right| of its corners after rectification
  double coverage_left = 0;     // area of the corners' convex hull / image area, 0..1
  double coverage_right = 0;
};

// A quality gate the calibration failed.
struct GateFailure {
  std::string gate;  // "min_pairs", "max_rms_px", "max_epipolar_px"
  double measured = 0;
  double limit = 0;
  std::string message;  // "stereo RMS reprojection error 1.42 px > 1 px (max_rms_px)"
};

struct CalibrationReport {
  // When the calibration was computed (Unix epoch, milliseconds); 0 = unknown.
  std::int64_t created_unix_ms = 0;
  cv::Size image_size;
  BoardSpec board;
  std::string detector;  // "<CornerDetectorName> + <CornerRefinementName>"

  int pairs_given = 0;
  int pairs_used = 0;  // == pairs.size()
  std::vector<PairReport> pairs;
  std::vector<RejectedPair> rejected;

  // RMS reprojection error over every corner of both cameras (cv::stereoCalibrate's value), and
  // per camera of the returned calibration (pixels).
  double rms_px = 0;
  double rms_left_px = 0;
  double rms_right_px = 0;
  // Row difference |y_left - y_right| of matched corners after rectifying them with the result:
  // mean and largest over every corner of every used pair (pixels).
  double epipolar_mean_px = 0;
  double epipolar_max_px = 0;

  // Coverage: per view, the convex hull of the corners over the image area (0..1); the union, the
  // fraction of the cells of a coverage_grid (e.g. 10x8) whose centre lies in some view's hull.
  cv::Size coverage_grid;
  double coverage_mean_view = 0;  // mean over views of both cameras
  double coverage_min_view = 0;
  double coverage_union_left = 0;
  double coverage_union_right = 0;

  // Summary of the returned calibration.
  double fx_left_px = 0, fy_left_px = 0, fx_right_px = 0, fy_right_px = 0;
  double baseline_m = 0;      // |T|
  double rectified_f_px = 0;  // P1(0, 0)

  // The camera named left in the input sits physically to the right (the solved T_x was > 0). The
  // calibration returned has the roles swapped (camera 1 = the input's right images), so whoever
  // applies it must swap the source's left and right images.
  bool swap_left_right = false;

  // True when every quality gate passed; otherwise `failures` names each failed gate.
  bool passed = false;
  std::vector<GateFailure> failures;
  // Advice that does not fail a gate (few pairs, low coverage, a pair with a large error, the
  // swap).
  std::vector<std::string> warnings;
};

// A multi-line, human-readable summary (figures, gates, warnings, rejected pairs, per-pair table).
std::string FormatReportText(const CalibrationReport& report);

// The report as YAML (OpenCV FileStorage), as stored beside the calibration file.
Result<std::string> ReportToYaml(const CalibrationReport& report);

// Reads ReportToYaml's output back. kInvalidArgument naming the missing or malformed keys.
Result<CalibrationReport> ParseReportYaml(const std::string& yaml_text);

}  // namespace stevi::calibration
