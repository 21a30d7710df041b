// Chessboard targets: the board description and sub-pixel detection of its inner corners.
#pragma once

#include "core/common/fields.h"

#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace stevi::calibration {

// A planar chessboard, counted by its inner corners (the points where four squares meet): a board
// of 10x7 squares has 9x6 inner corners.
// Most inner corners along either side of a board.
inline constexpr int kMaxInnerCorners = 100;

struct BoardSpec {
  // Inner corners along a row of the pattern (columns) and along a column (rows). Both >= 3 and
  // different (a square grid looks the same turned by 90 degrees, so left and right images could
  // number its corners differently).
  int inner_cols = 9;
  int inner_rows = 6;
  // Side of one square (metres). Sets the unit of T: the baseline comes out in metres.
  double square_size_m = 0.025;

  // (inner_cols, inner_rows), as OpenCV's patternSize.
  cv::Size PatternSize() const { return {inner_cols, inner_rows}; }
  // "9x6".
  std::string Name() const;
  // The inner corners in the board frame (metres): corner 0 at the origin, x along a row, y along
  // a column, z = 0; row by row, the order of DetectChessboard's corners.
  std::vector<cv::Point3f> ObjectPoints() const;

  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.BoardSpec, by its names.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.inner_cols,
             Field("columns", "", "inner corners along a row").In(3, kMaxInnerCorners));
    v.Number(s.inner_rows,
             Field("rows", "", "inner corners along a column").In(3, kMaxInnerCorners));
    v.Number(s.square_size_m,
             Field("square_m", "metres", "side of one square").Above(0).AtMost(10));
  }
};

enum class CornerDetector {
  // cv::findChessboardCornersSB (sector-based), and cv::findChessboardCorners when it finds
  // nothing.
  // The default: on the XIMEA captures the sector-based detector alone misses two boards that the
  // classic one finds (22 pairs instead of 24), and the classic one alone takes twice as long over
  // the set (0.15-0.3 s a 640x512 image against 0.05 s; 2.7 s on the image without a board).
  kSectorBasedThenClassic,
  // cv::findChessboardCornersSB only.
  kSectorBased,
  // cv::findChessboardCorners (quads of an adaptive threshold).
  kClassic,
};

std::string_view CornerDetectorName(CornerDetector detector);

// How the detector's corners are refined; cv::cornerSubPix always runs first. (The sector-based
// detector's own corners are half as accurate as cornerSubPix's on the XIMEA JPEGs: RMS 0.35 px
// against 0.17 px.)
enum class CornerRefinement {
  // Then fit a quadratic surface to the image, smoothed by a Gaussian, in a small window around
  // each corner and move the corner to its saddle point (iterated). On rendered boards the mean
  // error drops from 0.06 px (cornerSubPix) to 0.015 px and the worst from 0.16 to 0.07 px; on the
  // XIMEA captures the RMS drops from 0.170 to 0.160 px and the epipolar error from 0.133 to
  // 0.105 px. The default.
  kSaddlePoint,
  // cv::cornerSubPix only.
  kCornerSubPix,
};

std::string_view CornerRefinementName(CornerRefinement refinement);

struct DetectionOptions {
  CornerDetector detector = CornerDetector::kSectorBasedThenClassic;
  CornerRefinement refinement = CornerRefinement::kSaddlePoint;
  // Half size of the cornerSubPix window (pixels); shrunk to 40 % of the smallest corner spacing
  // so that the window never reaches the next corner.
  int subpix_half_window_px = 5;
  // kSaddlePoint: half size of the fitted window (pixels; shrunk to 30 % of the smallest corner
  // spacing, at least 2) and the sigma of the smoothing (pixels; at most 12 % of the spacing).
  int saddle_half_window_px = 3;
  double saddle_blur_sigma_px = 1.5;

  std::vector<std::string> Validate() const;
};

// The board's inner corners in an 8-bit grey (CV_8UC1) image, sub-pixel, in the order of
// BoardSpec::ObjectPoints(). The numbering is the board's own, not the detector's, so that the
// left and right views of a pair number the same physical corner 0: x then y turn clockwise in the
// image (the printed face is seen from the front), and when inner_cols + inner_rows is odd (e.g.
// 9x6, where a half turn swaps the colours of the squares) the square between corners 0, 1, cols
// and cols+1 is a dark one; otherwise (a board that looks the same after a half turn) corner 0 is
// the one nearer the image's top-left. kNotFound when no complete board is found;
// kInvalidArgument for an image of another type or invalid options; kInternal when OpenCV fails.
// Never throws.
Result<std::vector<cv::Point2f>> DetectChessboard(const cv::Mat& grey, const BoardSpec& board,
                                                  const DetectionOptions& options = {});

}  // namespace stevi::calibration
