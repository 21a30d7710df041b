#include "core/calibration/calibrate.h"

#include "core/common/format.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <optional>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace stevi::calibration {
namespace {

// The thesis' rules of thumb (warnings, not gates).
constexpr int kAdvisedPairs = 20;
constexpr double kAdvisedViewCoverage = 0.4;
constexpr double kAdvisedUnionCoverage = 0.7;
// A pair whose RMS exceeds this multiple of the median (and kOutlierMinPx) gets a warning.
constexpr double kOutlierFactor = 3.0;
constexpr double kOutlierMinPx = 0.5;
// A pair is only dropped as an outlier when its RMS error also exceeds this (pixels).
constexpr double kOutlierMinDropPx = 1.0;
// Rejected pairs quoted in an error message before "and N more".
constexpr std::size_t kQuotedRejections = 4;

std::string PairLabel(int index, const std::string& name) {
  std::string label = "#" + std::to_string(index);
  if (!name.empty()) label += " (" + name + ")";
  return label;
}

// ---- Geometry helpers -------------------------------------------------------------------------

cv::Mat RowVector(const cv::Mat& d, int n) {
  cv::Mat row = cv::Mat::zeros(1, n, CV_64F);
  cv::Mat flat = d.reshape(1, 1);
  cv::Mat flat64;
  flat.convertTo(flat64, CV_64F);
  flat64.colRange(0, std::min(n, flat64.cols)).copyTo(row.colRange(0, std::min(n, flat64.cols)));
  return row;
}

bool Finite(const cv::Mat& m) { return m.empty() || cv::checkRange(m, true); }

// Undistorts and rectifies points accurately (the default 5 iterations of cv::undistortPoints
// leave tenths of a pixel near the corners of a strongly distorted image).
std::vector<cv::Point2f> RectifyPoints(const std::vector<cv::Point2f>& points, const cv::Matx33d& K,
                                       const cv::Mat& D, const cv::Matx33d& R,
                                       const cv::Matx34d& P) {
  std::vector<cv::Point2f> out;
  cv::undistortPoints(points, out, K, D, R, P,
                      cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-9));
  return out;
}

double HullCoverage(const std::vector<cv::Point2f>& corners, cv::Size image,
                    std::vector<cv::Point2f>& hull) {
  cv::convexHull(corners, hull);
  return cv::contourArea(hull) / image.area();
}

// Fraction of the grid's cells whose centre lies inside some hull.
double UnionCoverage(const std::vector<std::vector<cv::Point2f>>& hulls, cv::Size image,
                     cv::Size grid) {
  int covered = 0;
  for (int gy = 0; gy < grid.height; ++gy) {
    for (int gx = 0; gx < grid.width; ++gx) {
      const cv::Point2f centre(static_cast<float>((gx + 0.5) * image.width / grid.width),
                               static_cast<float>((gy + 0.5) * image.height / grid.height));
      for (const auto& hull : hulls) {
        if (cv::pointPolygonTest(hull, centre, false) >= 0) {
          ++covered;
          break;
        }
      }
    }
  }
  return static_cast<double>(covered) / grid.area();
}

// "#3 (a.png): no_board_left: ...; #5: ... and 4 more".
std::string RejectionSummary(const std::vector<RejectedPair>& rejected) {
  std::string out;
  for (std::size_t i = 0; i < rejected.size() && i < kQuotedRejections; ++i) {
    if (!out.empty()) out += "; ";
    out += PairLabel(rejected[i].index, rejected[i].name);
    out += ": ";
    out += rejected[i].detail;
  }
  if (rejected.size() > kQuotedRejections) {
    out += "; and " + std::to_string(rejected.size() - kQuotedRejections) + " more";
  }
  return out;
}

int MonoFlags(const CalibrationModel& m) {
  int flags = 0;
  if (m.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  if (m.fix_principal_point) flags |= cv::CALIB_FIX_PRINCIPAL_POINT;
  if (m.zero_tangent_distortion) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (m.fix_k3) flags |= cv::CALIB_FIX_K3;
  if (m.rational_model) flags |= cv::CALIB_RATIONAL_MODEL;
  return flags;
}

int StereoFlags(const CalibrationModel& m) {
  int flags = MonoFlags(m);
  if (m.calibrate_cameras_first) {
    flags |= m.fix_intrinsics ? cv::CALIB_FIX_INTRINSIC : cv::CALIB_USE_INTRINSIC_GUESS;
  }
  if (m.same_focal_length) flags |= cv::CALIB_SAME_FOCAL_LENGTH;
  return flags;
}

struct Solution {
  cv::Mat K1, D1, K2, D2, R, T, E, F;
  cv::Mat1d errors;  // n x 2: RMS reprojection error of each pair in camera 1 and camera 2 (pixels)
  double rms = 0;
};

// cv::calibrateCamera per camera (optional), then cv::stereoCalibrate.
Result<Solution> Solve(const std::vector<PairCorners>& pairs,
                       const std::vector<cv::Point3f>& object, cv::Size image_size,
                       const CalibrationModel& model) {
  const std::vector<std::vector<cv::Point3f>> object_points(pairs.size(), object);
  std::vector<std::vector<cv::Point2f>> left_points, right_points;
  for (const PairCorners& p : pairs) {
    left_points.push_back(p.left);
    right_points.push_back(p.right);
  }
  const int n_dist = model.rational_model ? 8 : 5;
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS,
                                  model.max_iterations, model.epsilon);
  Solution s;
  s.K1 = cv::Mat::eye(3, 3, CV_64F);
  s.K2 = cv::Mat::eye(3, 3, CV_64F);
  s.D1 = cv::Mat::zeros(1, n_dist, CV_64F);
  s.D2 = cv::Mat::zeros(1, n_dist, CV_64F);
  if (model.calibrate_cameras_first) {
    std::vector<cv::Mat> rvecs, tvecs;
    cv::calibrateCamera(object_points, left_points, image_size, s.K1, s.D1, rvecs, tvecs,
                        MonoFlags(model), criteria);
    cv::calibrateCamera(object_points, right_points, image_size, s.K2, s.D2, rvecs, tvecs,
                        MonoFlags(model), criteria);
    s.D1 = RowVector(s.D1, n_dist);
    s.D2 = RowVector(s.D2, n_dist);
  }
  cv::Mat per_view;
  s.rms =
      cv::stereoCalibrate(object_points, left_points, right_points, s.K1, s.D1, s.K2, s.D2,
                          image_size, s.R, s.T, s.E, s.F, per_view, StereoFlags(model), criteria);
  s.D1 = RowVector(s.D1, n_dist);
  s.D2 = RowVector(s.D2, n_dist);
  per_view.convertTo(s.errors, CV_64F);
  if (!std::isfinite(s.rms) || !Finite(s.K1) || !Finite(s.K2) || !Finite(s.D1) || !Finite(s.D2) ||
      !Finite(s.R) || !Finite(s.T) || s.errors.rows != static_cast<int>(pairs.size()) ||
      s.errors.cols != 2) {
    return Internal("the stereo calibration diverged (non-finite result)");
  }
  return s;
}

// "#3 (view3) 67.71 px, #0 (view0) 2.10 px, #5 1.90 px": the three pairs with the largest error.
std::string WorstPairs(const std::vector<PairCorners>& pairs, const cv::Mat1d& errors) {
  std::vector<std::pair<double, int>> order;
  for (int i = 0; i < errors.rows; ++i) order.emplace_back(std::max(errors(i, 0), errors(i, 1)), i);
  std::sort(order.rbegin(), order.rend());
  std::string out;
  for (std::size_t k = 0; k < order.size() && k < 3; ++k) {
    if (!out.empty()) out += ", ";
    out += PairLabel(pairs[order[k].second].index, pairs[order[k].second].name) + " " +
           Fixed(order[k].first, 2) + " px";
  }
  return out;
}

// ---- Checks before solving --------------------------------------------------------------------

// Why no pair has the board in both images: every pair was rejected before detection, no image
// had the board (its size is probably wrong), or each pair had it in one image only.
Error NoPairError(const DetectedPairs& detected, const BoardSpec& board) {
  bool any_board = false, any_decoded = false;
  for (const RejectedPair& r : detected.rejected) {
    any_board |= r.reason == RejectReason::kNoBoardLeft || r.reason == RejectReason::kNoBoardRight;
    any_decoded |= r.reason == RejectReason::kNoBoardLeft ||
                   r.reason == RejectReason::kNoBoardRight || r.reason == RejectReason::kNoBoard;
  }
  if (!any_decoded) {
    return InvalidArgument(
        "no usable pair: every one of the " + std::to_string(detected.pairs_given) +
        " pairs was rejected before detection: " + RejectionSummary(detected.rejected));
  }
  if (!any_board) {
    return InvalidArgument("no board of " + board.Name() +
                           " inner corners found in any pair; check the board size (inner corners, "
                           "columns x rows) and that the whole board is in view");
  }
  return InvalidArgument("no pair has the board of " + board.Name() +
                         " inner corners in both images: " + RejectionSummary(detected.rejected));
}

// An error when the pairs are too few to solve, or the image size is not set.
std::optional<Error> CheckPairCount(const DetectedPairs& detected,
                                    const CalibrationOptions& options) {
  const int n_pairs = static_cast<int>(detected.pairs.size());
  if (n_pairs == 0) return NoPairError(detected, options.board);
  if (n_pairs < kMinSolvablePairs) {
    return InvalidArgument(
        "too few pairs: " + std::to_string(n_pairs) + " of " +
        std::to_string(detected.pairs_given) +
        " have the board in both images, at least 3 are needed to calibrate (the "
        "min_pairs gate asks for " +
        std::to_string(options.gates.min_pairs) + ")" +
        (detected.rejected.empty() ? std::string()
                                   : "; rejected: " + RejectionSummary(detected.rejected)));
  }
  const cv::Size image_size = detected.image_size;
  if (image_size.width <= 0 || image_size.height <= 0) {
    return InvalidArgument("image_size: must be > 0 (got " + SizeText(image_size) + ")");
  }
  return std::nullopt;
}

// An error naming the first pair whose corners do not fit the board.
std::optional<Error> CheckCorners(const std::vector<PairCorners>& pairs, const BoardSpec& board,
                                  const std::vector<cv::Point3f>& object) {
  for (const PairCorners& p : pairs) {
    if (p.left.size() != object.size() || p.right.size() != object.size()) {
      return InvalidArgument("pair " + PairLabel(p.index, p.name) + ": " +
                             std::to_string(p.left.size()) + " and " +
                             std::to_string(p.right.size()) + " corners, the board of " +
                             board.Name() + " has " + std::to_string(object.size()));
    }
  }
  return std::nullopt;
}

// ---- The solve, without outlier pairs ---------------------------------------------------------

// The pairs of a solution whose error is far above the median pair's.
struct Outliers {
  std::vector<double> worst;  // per pair: its RMS error in the worse camera (pixels)
  double median = 0;          // the median of worst
  std::vector<int> pairs;     // the outliers' positions, increasing
};

Outliers FindOutliers(const cv::Mat1d& errors, double outlier_factor) {
  Outliers o;
  for (int i = 0; i < errors.rows; ++i) o.worst.push_back(std::max(errors(i, 0), errors(i, 1)));
  std::vector<double> sorted = o.worst;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  o.median = sorted[sorted.size() / 2];
  for (int i = 0; i < static_cast<int>(o.worst.size()); ++i) {
    if (o.worst[i] > outlier_factor * o.median && o.worst[i] > kOutlierMinDropPx)
      o.pairs.push_back(i);
  }
  return o;
}

// Moves the outliers from `used` to `rejected` (kOutlier, with their error), the last first.
void LeaveOut(const Outliers& outliers, const cv::Mat1d& errors, std::vector<PairCorners>& used,
              std::vector<RejectedPair>& rejected) {
  const double median = outliers.median;
  for (auto it = outliers.pairs.rbegin(); it != outliers.pairs.rend(); ++it) {
    const PairCorners& p = used[*it];
    const double worst = outliers.worst[*it];
    const bool left_worse = errors(*it, 0) >= errors(*it, 1);
    rejected.push_back({p.index, p.name, RejectReason::kOutlier,
                        "RMS error " + Fixed(worst, 2) + " px in the " +
                            (left_worse ? "left" : "right") + " image, " +
                            Fixed(worst / median, 1) + " times the median pair's (" +
                            Fixed(median, 3) + " px): left out and solved again"});
    used.erase(used.begin() + *it);
  }
}

// A solution and the pairs it was solved from; the pairs left out, by index.
struct Fit {
  std::vector<PairCorners> used;
  std::vector<RejectedPair> rejected;
  Solution solution;
};

// Solves; drops pairs far worse than the rest (a mis-numbered or mis-detected board) and solves
// again: at most 3 rounds, and max_outlier_fraction of the pairs in all.
Result<Fit> SolveWithoutOutliers(const DetectedPairs& detected,
                                 const std::vector<cv::Point3f>& object,
                                 const CalibrationOptions& options) {
  const int n_pairs = static_cast<int>(detected.pairs.size());
  Fit fit{detected.pairs, detected.rejected, {}};
  const int max_outliers = static_cast<int>(options.max_outlier_fraction * n_pairs);
  int dropped = 0;
  for (int round = 0;; ++round) {
    Result<Solution> solved = Solve(fit.used, object, detected.image_size, options.model);
    if (!solved.ok()) return solved.error();
    fit.solution = std::move(*solved);
    if (options.outlier_factor <= 0 || round >= 3) break;
    const Outliers outliers = FindOutliers(fit.solution.errors, options.outlier_factor);
    const int n_outliers = static_cast<int>(outliers.pairs.size());
    if (outliers.pairs.empty() || dropped + n_outliers > max_outliers ||
        static_cast<int>(fit.used.size() - outliers.pairs.size()) < kMinSolvablePairs) {
      break;
    }
    LeaveOut(outliers, fit.solution.errors, fit.used, fit.rejected);
    dropped += n_outliers;
  }
  std::stable_sort(fit.rejected.begin(), fit.rejected.end(),
                   [](const RejectedPair& a, const RejectedPair& b) { return a.index < b.index; });
  return fit;
}

// ---- The calibration --------------------------------------------------------------------------

// The solution as a calibration (not rectified), camera 1 being the input's left camera.
geometry::StereoCalibration ToCalibration(const Solution& solution, cv::Size image_size) {
  geometry::StereoCalibration c;
  c.image_size = image_size;
  c.M1 = cv::Matx33d(solution.K1);
  c.M2 = cv::Matx33d(solution.K2);
  c.D1 = solution.D1;
  c.D2 = solution.D2;
  c.R = cv::Matx33d(solution.R);
  c.T = cv::Vec3d(solution.T.reshape(1, 3));
  c.E = cv::Matx33d(solution.E);
  c.F = cv::Matx33d(solution.F);
  return c;
}

// The left/right swap: x_right = R x_left + T puts the right camera's centre at -R^T T in the
// left frame; T_x > 0 means the camera named left is on the right. Swap the roles exactly:
// R' = R^T, T' = -R^T T, E' = E^T, F' = F^T.
void SwapCameras(geometry::StereoCalibration& c) {
  std::swap(c.M1, c.M2);
  std::swap(c.D1, c.D2);
  const cv::Matx33d r_old = c.R;
  c.R = r_old.t();
  c.T = -(r_old.t() * c.T);
  c.E = c.E->t();
  c.F = c.F->t();
}

// Bouguet's rectification (zero disparity at infinity): R1 R2 P1 P2 Q.
void Rectify(geometry::StereoCalibration& c, double alpha) {
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(cv::Mat(c.M1), c.D1, cv::Mat(c.M2), c.D2, c.image_size, cv::Mat(c.R),
                    cv::Mat(c.T), R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, alpha);
  c.R1 = cv::Matx33d(R1);
  c.R2 = cv::Matx33d(R2);
  c.P1 = cv::Matx34d(P1);
  c.P2 = cv::Matx34d(P2);
  c.Q = cv::Matx44d(Q);
}

// kInternal for a calibration that fails Validate(), with the RMS and the worst pairs.
Error InvalidResult(const std::vector<std::string>& problems, double rms,
                    const std::vector<PairCorners>& used, const cv::Mat1d& errors) {
  Error err = InvalidArgument(problems);
  err.code = ErrorCode::kInternal;
  err.message = "the stereo calibration gave an invalid result (" + err.message + "); RMS " +
                Fixed(rms, 2) + " px, worst pairs: " + WorstPairs(used, errors);
  return err;
}

// ---- The report -------------------------------------------------------------------------------

// What was calibrated and from what: time, image, board, detector, pairs, the solve's RMS.
void DescribeInput(const DetectedPairs& detected, const Fit& fit, bool swap,
                   const CalibrationOptions& options, CalibrationReport& report) {
  report.created_unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
  report.image_size = detected.image_size;
  report.board = options.board;
  report.detector = std::string(CornerDetectorName(options.detection.detector)) + " + " +
                    std::string(CornerRefinementName(options.detection.refinement));
  report.pairs_given = detected.pairs_given;
  report.pairs_used = static_cast<int>(fit.used.size());
  report.rejected = fit.rejected;
  report.rms_px = fit.solution.rms;
  report.swap_left_right = swap;
  report.coverage_grid = options.coverage_grid;
}

// Each pair's RMS error, epipolar error after rectification and coverage, and their totals.
// `errors` and the calibration's cameras are those of the result: with `swap`, camera 1 has the
// input's right images.
void MeasurePairs(const std::vector<PairCorners>& used, const cv::Mat1d& errors, bool swap,
                  const geometry::StereoCalibration& c, cv::Size grid, CalibrationReport& report) {
  const int n_used = static_cast<int>(used.size());
  double sum_left = 0, sum_right = 0, epi_sum = 0, epi_max = 0;
  std::size_t epi_n = 0;
  std::vector<std::vector<cv::Point2f>> hulls_left, hulls_right;
  double coverage_sum = 0, coverage_min = 1;
  for (int i = 0; i < n_used; ++i) {
    const std::vector<cv::Point2f>& left_points = swap ? used[i].right : used[i].left;
    const std::vector<cv::Point2f>& right_points = swap ? used[i].left : used[i].right;
    PairReport p;
    p.index = used[i].index;
    p.name = used[i].name;
    p.rms_left_px = errors(i, 0);
    p.rms_right_px = errors(i, 1);
    sum_left += p.rms_left_px * p.rms_left_px;
    sum_right += p.rms_right_px * p.rms_right_px;
    const std::vector<cv::Point2f> rect_left = RectifyPoints(left_points, c.M1, c.D1, *c.R1, *c.P1);
    const std::vector<cv::Point2f> rect_right =
        RectifyPoints(right_points, c.M2, c.D2, *c.R2, *c.P2);
    double pair_sum = 0;
    for (std::size_t k = 0; k < rect_left.size(); ++k) {
      const double dy = std::abs(static_cast<double>(rect_left[k].y) - rect_right[k].y);
      pair_sum += dy;
      epi_max = std::max(epi_max, dy);
    }
    p.epipolar_mean_px = pair_sum / static_cast<double>(rect_left.size());
    epi_sum += pair_sum;
    epi_n += rect_left.size();
    hulls_left.emplace_back();
    hulls_right.emplace_back();
    p.coverage_left = HullCoverage(left_points, c.image_size, hulls_left.back());
    p.coverage_right = HullCoverage(right_points, c.image_size, hulls_right.back());
    coverage_sum += p.coverage_left + p.coverage_right;
    coverage_min = std::min({coverage_min, p.coverage_left, p.coverage_right});
    report.pairs.push_back(p);
  }
  report.rms_left_px = std::sqrt(sum_left / n_used);
  report.rms_right_px = std::sqrt(sum_right / n_used);
  report.epipolar_mean_px = epi_sum / static_cast<double>(epi_n);
  report.epipolar_max_px = epi_max;
  report.coverage_mean_view = coverage_sum / (2.0 * n_used);
  report.coverage_min_view = coverage_min;
  report.coverage_union_left = UnionCoverage(hulls_left, c.image_size, grid);
  report.coverage_union_right = UnionCoverage(hulls_right, c.image_size, grid);
}

// Focal lengths, baseline and the rectified focal length of the calibration.
void SummariseCalibration(const geometry::StereoCalibration& c, CalibrationReport& report) {
  report.fx_left_px = c.M1(0, 0);
  report.fy_left_px = c.M1(1, 1);
  report.fx_right_px = c.M2(0, 0);
  report.fy_right_px = c.M2(1, 1);
  report.baseline_m = cv::norm(c.T);
  report.rectified_f_px = (*c.P1)(0, 0);
}

// The quality gates: failures, and passed when there is none.
void CheckGates(const QualityGates& gates, CalibrationReport& report) {
  const int n_used = report.pairs_used;
  const double rms = report.rms_px;
  if (n_used < gates.min_pairs) {
    report.failures.push_back({"min_pairs", static_cast<double>(n_used),
                               static_cast<double>(gates.min_pairs),
                               std::to_string(n_used) + " pairs used < " +
                                   std::to_string(gates.min_pairs) + " (min_pairs)"});
  }
  if (!(rms <= gates.max_rms_px)) {
    report.failures.push_back({"max_rms_px", rms, gates.max_rms_px,
                               "stereo RMS reprojection error " + Fixed(rms, 3) + " px > " +
                                   Fixed(gates.max_rms_px, 3) + " px (max_rms_px)"});
  }
  if (!(report.epipolar_mean_px <= gates.max_epipolar_px)) {
    report.failures.push_back({"max_epipolar_px", report.epipolar_mean_px, gates.max_epipolar_px,
                               "mean epipolar error after rectification " +
                                   Fixed(report.epipolar_mean_px, 3) + " px > " +
                                   Fixed(gates.max_epipolar_px, 3) + " px (max_epipolar_px)"});
  }
  report.passed = report.failures.empty();
}

// Warnings for the pairs whose error is far above the median pair's.
void WarnAboutOutliers(CalibrationReport& report) {
  std::vector<double> pair_rms;
  for (const PairReport& p : report.pairs)
    pair_rms.push_back(std::max(p.rms_left_px, p.rms_right_px));
  std::nth_element(pair_rms.begin(), pair_rms.begin() + pair_rms.size() / 2, pair_rms.end());
  const double median = pair_rms[pair_rms.size() / 2];
  for (const PairReport& p : report.pairs) {
    const double worst = std::max(p.rms_left_px, p.rms_right_px);
    if (worst > kOutlierFactor * median && worst > kOutlierMinPx) {
      report.warnings.push_back(
          "pair " + PairLabel(p.index, p.name) + " has an RMS error of " + Fixed(worst, 2) +
          " px, " + Fixed(worst / median, 1) +
          " times the median: check its corners (motion blur, a mis-detection)");
    }
  }
}

// Advice that fails no gate: the swap, few pairs, low coverage, pairs with a large error.
void AddAdvice(const geometry::StereoCalibration& c, cv::Size grid, CalibrationReport& report) {
  const int n_used = report.pairs_used;
  if (report.swap_left_right) {
    report.warnings.push_back(
        "left and right swapped: the camera named left sits to the right of the other (solved T_x "
        "= +" +
        Fixed(-c.T[0] * 1000, 1) +
        " mm); this calibration's camera 1 is the input's right camera, so "
        "the source's left and right images must be swapped when it is applied (swap_left_right)");
  }
  if (n_used < kAdvisedPairs) {
    report.warnings.push_back(std::to_string(n_used) + " pairs used; the thesis advises at least " +
                              std::to_string(kAdvisedPairs));
  }
  if (report.coverage_mean_view < kAdvisedViewCoverage) {
    report.warnings.push_back(
        "the board covers " + Fixed(100 * report.coverage_mean_view, 0) +
        " % of the image per view on average; the thesis asks for at least 40 % "
        "(hold the board closer)");
  }
  const double union_min = std::min(report.coverage_union_left, report.coverage_union_right);
  if (union_min < kAdvisedUnionCoverage) {
    report.warnings.push_back(
        "the boards reached only " + Fixed(100 * union_min, 0) + " % of the " + SizeText(grid) +
        " grid cells; the distortion is extrapolated elsewhere (move the board "
        "into the corners and edges)");
  }
  WarnAboutOutliers(report);
}

Result<CalibrationResult> CalibrateChecked(const DetectedPairs& detected,
                                           const CalibrationOptions& options) {
  if (std::optional<Error> error = CheckPairCount(detected, options)) return *error;
  const std::vector<cv::Point3f> object = options.board.ObjectPoints();
  if (std::optional<Error> error = CheckCorners(detected.pairs, options.board, object))
    return *error;

  Result<Fit> solved = SolveWithoutOutliers(detected, object, options);
  if (!solved.ok()) return solved.error();
  const Fit& fit = *solved;
  cv::Mat1d errors = fit.solution.errors;  // n x 2: RMS of each view in camera 1 and camera 2

  geometry::StereoCalibration c = ToCalibration(fit.solution, detected.image_size);
  const bool swap = c.T[0] > 0;
  if (swap) {
    SwapCameras(c);
    for (int i = 0; i < errors.rows; ++i) std::swap(errors(i, 0), errors(i, 1));
  }
  Rectify(c, options.rectify_alpha);
  if (std::vector<std::string> problems = c.Validate(); !problems.empty()) {
    return InvalidResult(problems, fit.solution.rms, fit.used, errors);
  }

  CalibrationResult result;
  result.calibration = c;
  CalibrationReport& report = result.report;
  DescribeInput(detected, fit, swap, options, report);
  MeasurePairs(fit.used, errors, swap, c, options.coverage_grid, report);
  SummariseCalibration(c, report);
  CheckGates(options.gates, report);
  AddAdvice(c, options.coverage_grid, report);
  return result;
}

}  // namespace

std::vector<std::string> CalibrationModel::Validate() const {
  std::vector<std::string> problems;
  if (fix_intrinsics && !calibrate_cameras_first) {
    problems.push_back(
        "fix_intrinsics: needs calibrate_cameras_first (nothing to keep fixed otherwise)");
  }
  if (max_iterations < 1 || max_iterations > 10000) {
    problems.push_back("max_iterations: must be in [1, 10000]" + Got(max_iterations));
  }
  if (!(epsilon > 0) || !(epsilon < 1))
    problems.push_back("epsilon: must be in (0, 1)" + Got(epsilon));
  return problems;
}

std::vector<std::string> CalibrationOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  AppendPrefixed(problems, "detection.", detection.Validate());
  AppendPrefixed(problems, "model.", model.Validate());
  if (max_image_size.width < 16 || max_image_size.height < 16 || max_image_size.width > 65535 ||
      max_image_size.height > 65535) {
    problems.push_back("max_image_size: each side must be in [16, 65535] pixels (got " +
                       SizeText(max_image_size) + ")");
  }
  if (coverage_grid.width < 1 || coverage_grid.height < 1 || coverage_grid.width > 1000 ||
      coverage_grid.height > 1000) {
    problems.push_back("coverage_grid: each side must be in [1, 1000] cells (got " +
                       SizeText(coverage_grid) + ")");
  }
  return problems;
}

Result<CalibrationResult> CalibrateFromCorners(const DetectedPairs& detected,
                                               const CalibrationOptions& options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  try {
    return CalibrateChecked(detected, options);
  } catch (const cv::Exception& e) {
    return Internal("the stereo calibration failed in OpenCV (" + e.err + ")");
  } catch (const std::exception& e) {
    return Internal(std::string("the stereo calibration failed (") + e.what() + ")");
  }
}

Result<CalibrationResult> CalibrateStereo(const std::vector<ImagePair>& pairs,
                                          const CalibrationOptions& options) {
  Result<DetectedPairs> detected = DetectPairs(pairs, options);
  if (!detected.ok()) return detected.error();
  return CalibrateFromCorners(*detected, options);
}

}  // namespace stevi::calibration
