// Stereo calibration files: OpenCV FileStorage YAML, one key per field of StereoCalibration below.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace stevi::geometry {

// The contents of a calibration file. M1/M2 are 3x3 camera matrices (pixels), D1/D2 distortion
// (k1 k2 p1 p2 k3, 1x4..1x14), R and T take points from the left camera to the right camera frame
// (x_right = R x_left + T), T in metres. The rectification terms are optional: when absent they are
// computed with Bouguet's method (cv::stereoRectify, alpha 0).
struct StereoCalibration {
  cv::Size image_size;
  cv::Matx33d M1, M2;
  cv::Mat D1, D2;  // CV_64F, one row
  cv::Matx33d R;
  cv::Vec3d T;  // metres
  std::optional<cv::Matx33d> R1, R2, E, F;
  std::optional<cv::Matx34d> P1, P2;
  std::optional<cv::Matx44d> Q;

  // Lists every problem: sizes, non-finite values, a zero baseline, a non-rotation R, ...
  std::vector<std::string> Validate() const;
};

// Reads a calibration YAML. A missing file gives kNotFound naming it; unparsable YAML, or missing,
// malformed or invalid keys, give kInvalidArgument naming the file and every bad key
// ("M1: expected a 3x3 matrix, got 3x2"). Matrices are !!opencv-matrix nodes or plain row-major
// lists of numbers; T may be 3x1 or 1x3, D1/D2 1xN or Nx1. The result passes Validate().
Result<StereoCalibration> LoadCalibrationYaml(const std::string& path);

// Parses calibration YAML held in memory (same rules as LoadCalibrationYaml).
Result<StereoCalibration> ParseCalibrationYaml(const std::string& yaml_text);

// Why YAML text must not be handed to OpenCV's parser (cv::FileStorage, OpenCV 4.6), or empty.
// Its YAMLParser mishandles two things no calibration or report file needs:
//   - an empty key, a line starting with ':' after its indentation: parseKey scans backwards
//     over spaces past the start of the key (and of its line buffer: a read out of bounds), then
//     throws std::length_error;
//   - text after the first document's top-level collection (a line indented less than the first,
//     a "..." end marker, a flow collection at the top): parse() can loop forever on a '-' there.
// So text is refused unless it is one top-level block map (or list): nothing indented less than
// its first line, no '...', no '{' or '[' first, no empty key. Returns "line N: problem".
std::string YamlTextProblem(std::string_view text);

// The YAML text SaveCalibrationYaml writes (kInvalidArgument for an invalid calibration).
Result<std::string> CalibrationYamlText(const StereoCalibration& calibration);

// Writes a calibration YAML atomically (a temporary file beside it, fsync, rename, fsync of the
// folder). An invalid calibration is refused and the file left as it was.
Status SaveCalibrationYaml(const StereoCalibration& calibration, const std::string& path);

// The calibration of an ideal, already rectified rig: identity R, zero distortion,
// T = (-baseline_m, 0, 0), both cameras with focal f_px and principal point (cx, cy).
StereoCalibration IdealCalibration(cv::Size image_size, double f_px, double baseline_m, double cx,
                                   double cy);

}  // namespace stevi::geometry
