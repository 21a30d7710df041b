// Stereo calibration from chessboard image pairs: detection, cv::stereoCalibrate, Bouguet
// rectification, a quality report with gates, and the left/right swap.
#pragma once

#include <cstdint>
#include <string>
#include <variant>
#include <vector>

#include <opencv2/core.hpp>

#include "core/calibration/chessboard.h"
#include "core/common/fields.h"
#include "core/calibration/report.h"
#include "core/common/error.h"
#include "core/geometry/calibration_io.h"

namespace stevi::calibration {

// The camera model and solver (maps to cv::CALIB_* flags of cv::calibrateCamera and
// cv::stereoCalibrate). The defaults solve both cameras fully: fx, fy, cx, cy, k1 k2 p1 p2 k3.
struct CalibrationModel {
  // Solve each camera alone first (cv::calibrateCamera) and start the joint stereo solve from
  // those intrinsics (CALIB_USE_INTRINSIC_GUESS). Off: cv::stereoCalibrate initialises them itself.
  bool calibrate_cameras_first = true;
  // Keep the intrinsics of the first step fixed and solve only R and T (CALIB_FIX_INTRINSIC).
  // Needs calibrate_cameras_first.
  bool fix_intrinsics = false;
  bool same_focal_length = false;        // CALIB_SAME_FOCAL_LENGTH (stereo step)
  bool fix_aspect_ratio = false;         // CALIB_FIX_ASPECT_RATIO: fx / fy stays as initialised
  bool fix_principal_point = false;      // CALIB_FIX_PRINCIPAL_POINT
  bool zero_tangent_distortion = false;  // CALIB_ZERO_TANGENT_DIST: p1 = p2 = 0
  bool fix_k3 = false;                   // CALIB_FIX_K3: k3 = 0
  bool rational_model = false;           // CALIB_RATIONAL_MODEL: also k4 k5 k6 (8 coefficients)
  // Levenberg-Marquardt stopping rule of both steps: at most this many iterations, or a relative
  // change below epsilon.
  int max_iterations = 100;
  double epsilon = 1e-10;

  std::vector<std::string> Validate() const;
};

// Quality gates. A calibration that fails one is still returned, with report.passed = false and
// the gate in report.failures; applying it is the caller's decision.
// Fewer pairs than this cannot be solved for two cameras' intrinsics and their relative pose.
inline constexpr int kMinSolvablePairs = 3;

struct QualityGates {
  // Fewest pairs used (board found in both images). The thesis advises at least 20.
  int min_pairs = 10;
  // Largest stereo RMS reprojection error (pixels).
  double max_rms_px = 1.0;
  // Largest mean epipolar error after rectification (pixels): the mean row difference of matched
  // corners. The matchers compare one row of the left image with one row of the right, so a
  // vertical error eats straight into their window: at half a pixel block matching already loses
  // fine texture. A sound calibration measures about 0.1 px here (0.105 px on the XIMEA rig, 0.02
  // px on rendered boards), and the figure is in-sample, so optimistic: 0.5 px fails a calibration
  // that is clearly unfit for matching while leaving room for noisy real captures. (1 px, the
  // RMS gate's value, would let through rigs whose rectified rows are a pixel apart.)
  double max_epipolar_px = 0.5;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  // The fields of stevi.v1.QualityGates.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.min_pairs,
             Field("min_pairs", "pairs", "fewest pairs used").In(kMinSolvablePairs, 10000));
    v.Number(s.max_rms_px, Field("max_rms_px", "pixels", "stereo RMS reprojection error").Above(0));
    v.Number(
        s.max_epipolar_px,
        Field("max_epipolar_px", "pixels", "mean row difference after rectification").Above(0));
  }
};

struct CalibrationOptions {
  BoardSpec board;
  DetectionOptions detection;
  CalibrationModel model;
  QualityGates gates;
  // Bouguet's free scaling parameter (cv::stereoRectify alpha): 0 keeps only valid pixels (the
  // rectified images have no black border; what StereoRig uses by default), 1 keeps every source
  // pixel, -1 lets OpenCV choose.
  double rectify_alpha = 0.0;
  // Largest accepted image (pixels, each dimension), checked on the PNG/JPEG header before
  // decoding, and on cv::Mat inputs.
  cv::Size max_image_size{4096, 4096};
  // Outlier pairs: a pair whose RMS error (in its worse camera) exceeds outlier_factor times the
  // median pair's, and 1 px, is left out (RejectReason::kOutlier) and the calibration solved again
  // (at most 3 rounds, and at most max_outlier_fraction of the pairs in all). Typically a board the
  // detector numbered differently in the two images. 0 disables.
  double outlier_factor = 5.0;
  double max_outlier_fraction = 0.25;
  // Cells across and down of the grid the union coverage is counted on.
  cv::Size coverage_grid{10, 8};

  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.CalibrationSettings (its model is the `flags` bit mask, mapped by the
  // server), and the core's own numbers; Validate() adds the detection's, the model's and the
  // sizes' checks.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Nested(s.board, Field("board"));
    v.Nested(s.gates, Field("gates"));
    v.Number(s.rectify_alpha, Field("alpha", "", "Bouguet's free scaling of the rectification")
                                  .In(0, 1)
                                  .Or(-1, "OpenCV's choice"));
    v.Number(s.outlier_factor, Field("outlier_factor", "", "outlier pairs' RMS over the median's")
                                   .In(2, 1000)
                                   .Or(0, "off")
                                   .NoProto());
    v.Number(
        s.max_outlier_fraction,
        Field("max_outlier_fraction", "", "outlier pairs left out at most").In(0, 0.5).NoProto());
  }
};

// One image: encoded PNG or JPEG bytes (std::string or a byte vector), or an already decoded
// 8-bit cv::Mat (grey, BGR or BGRA).
using ImageData = std::variant<std::string, std::vector<std::uint8_t>, cv::Mat>;

// One stereo view of the board, as the cameras named left and right delivered it.
struct ImagePair {
  ImageData left;
  ImageData right;
  std::string name;  // for the report, e.g. "left10.jpg"; may be empty
};

// The corners of one pair with the board found in both images (order of BoardSpec::ObjectPoints).
struct PairCorners {
  int index = 0;
  std::string name;
  std::vector<cv::Point2f> left, right;
};

// What detection made of the input: the common image size, the usable pairs and the rejected ones.
struct DetectedPairs {
  cv::Size image_size;
  int pairs_given = 0;
  std::vector<PairCorners> pairs;
  std::vector<RejectedPair> rejected;
};

struct CalibrationResult {
  // M1 D1 M2 D2 R T and R1 R2 P1 P2 Q E F. T_x < 0 always: when the input's cameras were named the
  // wrong way round, the roles are swapped here and report.swap_left_right is set, and the
  // source's images must be swapped before this calibration is applied to them.
  geometry::StereoCalibration calibration;
  CalibrationReport report;
};

// Decodes (header size checked first) and detects the board in every pair, in parallel. Problems of
// one pair reject it with a reason (RejectReason); the image size is the one most pairs share.
// Errors (kInvalidArgument): invalid options, an empty input. Never throws.
Result<DetectedPairs> DetectPairs(const std::vector<ImagePair>& pairs,
                                  const CalibrationOptions& options);

// Calibrates from detected corners: cv::calibrateCamera per camera (optional), cv::stereoCalibrate,
// outlier pairs left out and solved again, the swap when T_x > 0, cv::stereoRectify (Bouguet, zero
// disparity, options.rectify_alpha), and the report with its gates. kInvalidArgument when no pair
// has the board in both images ("no board of 9x6 inner corners found in any pair; check the board
// size" when no image had it), when fewer than 3 pairs are left (too few to solve; the min_pairs
// gate only reports), or when the corners do not fit the board; kInternal when OpenCV fails or the
// solve diverges. Never throws.
Result<CalibrationResult> CalibrateFromCorners(const DetectedPairs& detected,
                                               const CalibrationOptions& options);

// DetectPairs, then CalibrateFromCorners.
Result<CalibrationResult> CalibrateStereo(const std::vector<ImagePair>& pairs,
                                          const CalibrationOptions& options);

}  // namespace stevi::calibration
