#include "core/calibration/chessboard.h"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stevi::calibration {
namespace {

// Smallest distance between neighbouring corners of the grid (pixels).
double SmallestSpacing(const std::vector<cv::Point2f>& corners, cv::Size pattern) {
  double smallest = 1e30;
  for (int r = 0; r < pattern.height; ++r) {
    for (int c = 0; c < pattern.width; ++c) {
      const cv::Point2f& p = corners[r * pattern.width + c];
      if (c + 1 < pattern.width)
        smallest = std::min(smallest, cv::norm(p - corners[r * pattern.width + c + 1]));
      if (r + 1 < pattern.height)
        smallest = std::min(smallest, cv::norm(p - corners[(r + 1) * pattern.width + c]));
    }
  }
  return smallest;
}

// Mean grey level in a small square around `centre` (clipped to the image).
double MeanAround(const cv::Mat& grey, cv::Point2f centre, int half) {
  const cv::Rect box(cvRound(centre.x) - half, cvRound(centre.y) - half, 2 * half + 1,
                     2 * half + 1);
  const cv::Rect clipped = box & cv::Rect(0, 0, grey.cols, grey.rows);
  if (clipped.area() == 0) return 0;
  return cv::mean(grey(clipped))[0];
}

// Moves `p` to the saddle point of the quadratic a x^2 + b xy + c y^2 + d x + e y + f fitted by
// least squares to `smooth` in a (2r+1)^2 window around it, iterated. Keeps `p` when the fit is no
// saddle or wanders off by more than the window.
cv::Point2f SaddlePoint(const cv::Mat1f& smooth, cv::Point2f p, int r) {
  // The normal equations' matrix depends only on the window: build and factor it once.
  cv::Matx<double, 6, 6> ata = cv::Matx<double, 6, 6>::zeros();
  for (int y = -r; y <= r; ++y) {
    for (int x = -r; x <= r; ++x) {
      const cv::Vec<double, 6> row(x * x, x * y, y * y, x, y, 1);
      ata += row * row.t();
    }
  }
  const cv::Matx<double, 6, 6> ata_inv = ata.inv(cv::DECOMP_CHOLESKY);
  const cv::Point2f start = p;
  cv::Mat1f patch;
  for (int iteration = 0; iteration < 10; ++iteration) {
    cv::getRectSubPix(smooth, cv::Size(2 * r + 1, 2 * r + 1), p, patch, CV_32F);
    cv::Vec<double, 6> atb = cv::Vec<double, 6>::all(0);
    for (int y = -r; y <= r; ++y) {
      const float* row = patch[y + r];
      for (int x = -r; x <= r; ++x)
        atb += static_cast<double>(row[x + r]) * cv::Vec<double, 6>(x * x, x * y, y * y, x, y, 1);
    }
    const cv::Vec<double, 6> q = ata_inv * atb;
    const cv::Matx22d hessian(2 * q[0], q[1], q[1], 2 * q[2]);
    if (cv::determinant(hessian) >= 0) return start;  // not a saddle
    const cv::Vec2d step = hessian.inv() * cv::Vec2d(-q[3], -q[4]);
    p += cv::Point2f(static_cast<float>(step[0]), static_cast<float>(step[1]));
    if (cv::norm(p - start) > r) return start;
    if (cv::norm(step) < 1e-4) break;
  }
  return p;
}

void ReverseRows(std::vector<cv::Point2f>& corners, cv::Size pattern) {
  for (int r = 0; r < pattern.height; ++r) {
    std::reverse(corners.begin() + r * pattern.width, corners.begin() + (r + 1) * pattern.width);
  }
}

// Renumbers the corners by the board itself rather than by the detector (see DetectChessboard).
void Canonicalise(const cv::Mat& grey, cv::Size pattern, std::vector<cv::Point2f>& corners) {
  const int cols = pattern.width;
  auto at = [&](int r, int c) { return corners[r * cols + c]; };
  // Handedness: the printed face is seen from the front, so x (along a row) then y (along a
  // column) turn clockwise in the image (y down) for the board's own numbering.
  const cv::Point2f dx = at(0, 1) - at(0, 0);
  const cv::Point2f dy = at(1, 0) - at(0, 0);
  if (dx.x * dy.y - dx.y * dy.x < 0) ReverseRows(corners, pattern);

  bool reverse = false;
  if ((pattern.width + pattern.height) % 2 == 1) {
    // Mean level of the cells with (row + col) even (the first cell's colour) minus the others.
    const int half = std::max(1, static_cast<int>(0.15 * SmallestSpacing(corners, pattern)));
    double even_sum = 0, odd_sum = 0;
    int even_n = 0, odd_n = 0;
    for (int r = 0; r + 1 < pattern.height; ++r) {
      for (int c = 0; c + 1 < cols; ++c) {
        const cv::Point2f centre =
            (at(r, c) + at(r, c + 1) + at(r + 1, c) + at(r + 1, c + 1)) * 0.25f;
        const double level = MeanAround(grey, centre, half);
        if ((r + c) % 2 == 0) {
          even_sum += level;
          ++even_n;
        } else {
          odd_sum += level;
          ++odd_n;
        }
      }
    }
    reverse = even_sum / std::max(1, even_n) > odd_sum / std::max(1, odd_n);
  } else {
    const cv::Point2f first = corners.front(), last = corners.back();
    reverse = last.x + last.y < first.x + first.y;
  }
  if (reverse) std::reverse(corners.begin(), corners.end());
}

}  // namespace

std::string BoardSpec::Name() const {
  return std::to_string(inner_cols) + "x" + std::to_string(inner_rows);
}

std::vector<cv::Point3f> BoardSpec::ObjectPoints() const {
  std::vector<cv::Point3f> points;
  points.reserve(static_cast<std::size_t>(std::max(0, inner_cols * inner_rows)));
  for (int r = 0; r < inner_rows; ++r) {
    for (int c = 0; c < inner_cols; ++c) {
      points.emplace_back(static_cast<float>(c * square_size_m),
                          static_cast<float>(r * square_size_m), 0.0f);
    }
  }
  return points;
}

std::vector<std::string> BoardSpec::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (inner_cols == inner_rows) {
    problems.push_back(
        "columns, rows: must differ (a square grid of corners is ambiguous under a quarter turn)" +
        Got(inner_cols));
  }
  return problems;
}

std::string_view CornerDetectorName(CornerDetector detector) {
  switch (detector) {
    case CornerDetector::kSectorBasedThenClassic: return "sector_based_then_classic";
    case CornerDetector::kSectorBased: return "sector_based";
    case CornerDetector::kClassic: return "classic";
  }
  return "unknown";
}

std::string_view CornerRefinementName(CornerRefinement refinement) {
  switch (refinement) {
    case CornerRefinement::kSaddlePoint: return "saddle_point";
    case CornerRefinement::kCornerSubPix: return "corner_subpix";
  }
  return "unknown";
}

std::vector<std::string> DetectionOptions::Validate() const {
  std::vector<std::string> problems;
  if (detector != CornerDetector::kSectorBasedThenClassic &&
      detector != CornerDetector::kSectorBased && detector != CornerDetector::kClassic) {
    problems.push_back("detector: unknown value" + Got(static_cast<int>(detector)));
  }
  if (refinement != CornerRefinement::kSaddlePoint &&
      refinement != CornerRefinement::kCornerSubPix) {
    problems.push_back("refinement: unknown value" + Got(static_cast<int>(refinement)));
  }
  if (subpix_half_window_px < 1 || subpix_half_window_px > 30) {
    problems.push_back("subpix_half_window_px: must be in [1, 30] pixels" +
                       Got(subpix_half_window_px));
  }
  if (saddle_half_window_px < 2 || saddle_half_window_px > 15) {
    problems.push_back("saddle_half_window_px: must be in [2, 15] pixels" +
                       Got(saddle_half_window_px));
  }
  if (!(saddle_blur_sigma_px >= 0 && saddle_blur_sigma_px <= 10)) {
    problems.push_back("saddle_blur_sigma_px: must be in [0, 10] pixels" +
                       Got(saddle_blur_sigma_px));
  }
  return problems;
}

Result<std::vector<cv::Point2f>> DetectChessboard(const cv::Mat& grey, const BoardSpec& board,
                                                  const DetectionOptions& options) {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "board.", board.Validate());
  AppendPrefixed(problems, "detection.", options.Validate());
  if (!problems.empty()) return InvalidArgument(problems);
  if (grey.empty() || grey.type() != CV_8UC1) {
    return InvalidArgument(
        "DetectChessboard: expected a non-empty 8-bit grey image (CV_8UC1), got " +
        (grey.empty() ? std::string("an empty one") : cv::typeToString(grey.type())));
  }
  const cv::Size pattern = board.PatternSize();
  std::vector<cv::Point2f> corners;
  try {
    const bool sector_based = options.detector != CornerDetector::kClassic;
    const bool classic = options.detector != CornerDetector::kSectorBased;
    bool found = false;
    if (sector_based) {
      found = cv::findChessboardCornersSB(grey, pattern, corners,
                                          cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE);
    }
    if (!found && classic) {
      found = cv::findChessboardCorners(
          grey, pattern, corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
    }
    if (found && static_cast<int>(corners.size()) == pattern.area()) {
      const double spacing = SmallestSpacing(corners, pattern);
      const int half =
          std::clamp(static_cast<int>(0.4 * spacing), 1, options.subpix_half_window_px);
      cv::cornerSubPix(grey, corners, cv::Size(half, half), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
      if (options.refinement == CornerRefinement::kSaddlePoint) {
        const int r = std::clamp(static_cast<int>(0.3 * spacing), 2, options.saddle_half_window_px);
        const double sigma = std::min(options.saddle_blur_sigma_px, 0.12 * spacing);
        cv::Mat1f smooth;
        grey.convertTo(smooth, CV_32F);
        if (sigma > 0) cv::GaussianBlur(smooth, smooth, cv::Size(0, 0), sigma);
        for (cv::Point2f& p : corners) p = SaddlePoint(smooth, p, r);
      }
    }
    if (!found || static_cast<int>(corners.size()) != pattern.area()) {
      return NotFound("no board of " + board.Name() + " inner corners found");
    }
    Canonicalise(grey, pattern, corners);
  } catch (const cv::Exception& e) {
    return Internal("chessboard detection failed in OpenCV (" + e.err + ")");
  }
  return corners;
}

}  // namespace stevi::calibration
