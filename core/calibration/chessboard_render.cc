#include "core/calibration/chessboard_render.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <random>

#include <opencv2/calib3d.hpp>

namespace stevi::calibration {
namespace {

constexpr int kMaxSupersampling = 16;
constexpr int kAttemptsPerPose = 400;
constexpr int kTargetCells = 3;  // the board centres are aimed at a kTargetCells^2 grid

const cv::TermCriteria kUndistortCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100,
                                          1e-9);

// Uniform in [lo, hi) from the generator's raw bits (the same on every standard library).
double Uniform(std::mt19937& rng, double lo, double hi) {
  const double unit = (static_cast<double>(rng()) + 0.5) / 4294967296.0;
  return lo + (hi - lo) * unit;
}

cv::Matx33d Rotation(const cv::Vec3d& rvec) {
  cv::Matx33d r;
  cv::Rodrigues(rvec, r);
  return r;
}

std::vector<std::string> InputProblems(const geometry::StereoCalibration& rig,
                                       const BoardSpec& board, cv::Size image_size) {
  std::vector<std::string> problems;
  AppendPrefixed(problems, "truth_rig.", rig.Validate());
  AppendPrefixed(problems, "board.", board.Validate());
  if (image_size.width < 16 || image_size.height < 16 || image_size.width > 16384 ||
      image_size.height > 16384) {
    problems.push_back("image_size: each side must be in [16, 16384] pixels (got " +
                       std::to_string(image_size.width) + "x" + std::to_string(image_size.height) +
                       ")");
  }
  return problems;
}

// Board pose in the right camera from the pose in the left one.
cv::Affine3d RightPose(const geometry::StereoCalibration& rig, const cv::Affine3d& board_in_left) {
  return cv::Affine3d(rig.R, rig.T) * board_in_left;
}

}  // namespace

struct ChessboardRenderer::RayGrid {
  // Normalised ray (x, y) for the pixel corner (i - 0.5, j - 0.5), i in 0..width, j in 0..height.
  cv::Mat2d rays;
};

std::vector<std::string> RenderOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(margin_squares >= 0) || margin_squares > 10) {
    problems.push_back("margin_squares: must be in [0, 10] squares" + Got(margin_squares));
  }
  for (const auto& [name, level] : {std::pair<const char*, double>{"dark_level", dark_level},
                                    {"light_level", light_level},
                                    {"background_level", background_level}}) {
    if (!(level >= 0 && level <= 255))
      problems.push_back(std::string(name) + ": must be in [0, 255]" + Got(level));
  }
  if (supersampling < 1 || supersampling > kMaxSupersampling) {
    problems.push_back("supersampling: must be in [1, 16] samples per axis" + Got(supersampling));
  }
  return problems;
}

std::vector<std::string> PoseOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(max_tilt_deg >= 0 && max_tilt_deg <= 60))
    problems.push_back("max_tilt_deg: must be in [0, 60]" + Got(max_tilt_deg));
  if (!(max_roll_deg >= 0 && max_roll_deg <= 180))
    problems.push_back("max_roll_deg: must be in [0, 180]" + Got(max_roll_deg));
  if (!(min_width_fraction > 0 && min_width_fraction <= 1)) {
    problems.push_back("min_width_fraction: must be in (0, 1]" + Got(min_width_fraction));
  }
  if (!(max_width_fraction >= min_width_fraction && max_width_fraction <= 1)) {
    problems.push_back("max_width_fraction: must be in [min_width_fraction, 1]" +
                       Got(max_width_fraction));
  }
  if (!(margin_squares >= 0 && margin_squares <= 10))
    problems.push_back("margin_squares: must be in [0, 10]" + Got(margin_squares));
  if (border_px < 0 || border_px > 100)
    problems.push_back("border_px: must be in [0, 100] pixels" + Got(border_px));
  return problems;
}

ProjectedBoard ProjectChessboard(const geometry::StereoCalibration& truth_rig,
                                 const BoardSpec& board, const cv::Affine3d& board_in_left) {
  const std::vector<cv::Point3f> object = board.ObjectPoints();
  ProjectedBoard out;
  const cv::Affine3d in_right = RightPose(truth_rig, board_in_left);
  cv::projectPoints(object, board_in_left.rvec(), board_in_left.translation(), truth_rig.M1,
                    truth_rig.D1, out.left);
  cv::projectPoints(object, in_right.rvec(), in_right.translation(), truth_rig.M2, truth_rig.D2,
                    out.right);
  return out;
}

Result<ChessboardRenderer> ChessboardRenderer::Create(const geometry::StereoCalibration& truth_rig,
                                                      const BoardSpec& board, cv::Size image_size,
                                                      const RenderOptions& options) {
  std::vector<std::string> problems = InputProblems(truth_rig, board, image_size);
  AppendPrefixed(problems, "options.", options.Validate());
  if (!problems.empty()) return InvalidArgument(problems);

  ChessboardRenderer renderer;
  renderer.rig_ = truth_rig;
  renderer.board_ = board;
  renderer.image_size_ = image_size;
  renderer.options_ = options;
  std::vector<cv::Point2d> corners;
  corners.reserve(static_cast<std::size_t>(image_size.width + 1) * (image_size.height + 1));
  for (int j = 0; j <= image_size.height; ++j) {
    for (int i = 0; i <= image_size.width; ++i) corners.emplace_back(i - 0.5, j - 0.5);
  }
  auto grid = [&](const cv::Matx33d& K,
                  const cv::Mat& D) -> Result<std::shared_ptr<const RayGrid>> {
    auto rays = std::make_shared<RayGrid>();
    std::vector<cv::Point2d> normalised;
    try {
      cv::undistortPoints(corners, normalised, K, D, cv::noArray(), cv::noArray(),
                          kUndistortCriteria);
    } catch (const cv::Exception& e) {
      return InvalidArgument("truth_rig: cannot undistort (" + e.err + ")");
    }
    rays->rays = cv::Mat2d(image_size.height + 1, image_size.width + 1);
    std::copy(normalised.begin(), normalised.end(), rays->rays.begin());
    return std::shared_ptr<const RayGrid>(std::move(rays));
  };
  Result<std::shared_ptr<const RayGrid>> left = grid(truth_rig.M1, truth_rig.D1);
  if (!left.ok()) return left.error();
  Result<std::shared_ptr<const RayGrid>> right = grid(truth_rig.M2, truth_rig.D2);
  if (!right.ok()) return right.error();
  renderer.left_rays_ = *left;
  renderer.right_rays_ = *right;
  return renderer;
}

cv::Mat1b ChessboardRenderer::RenderCamera(const RayGrid& grid, const cv::Matx33d& R,
                                           const cv::Vec3d& t) const {
  // Board (u, v, 1) -> ray: lambda (x, y, 1) = [r1 r2 t] (u, v, 1); invert for ray -> board.
  const cv::Matx33d H(R(0, 0), R(0, 1), t[0], R(1, 0), R(1, 1), t[1], R(2, 0), R(2, 1), t[2]);
  const cv::Matx33d H_inv = H.inv();
  const int width = image_size_.width, height = image_size_.height;

  // Homogeneous board coordinates of every pixel corner's ray. They are linear in the ray, so
  // interpolating them inside a pixel equals interpolating the ray.
  cv::Mat3d board_h(height + 1, width + 1);
  for (int j = 0; j <= height; ++j) {
    const cv::Vec2d* ray = grid.rays[j];
    cv::Vec3d* out = board_h[j];
    for (int i = 0; i <= width; ++i) out[i] = H_inv * cv::Vec3d(ray[i][0], ray[i][1], 1.0);
  }

  const double s = board_.square_size_m;
  const double margin = options_.margin_squares * s;
  const double u_lo = -s, u_hi = board_.inner_cols * s, v_lo = -s, v_hi = board_.inner_rows * s;
  const double dark = options_.dark_level, light = options_.light_level,
               background = options_.background_level;
  // n x n samples in the pixel, each in its own row and column of an n^2 x n^2 grid (a
  // multi-jittered pattern): an edge along x or y is resolved to 1/n^2 of a pixel, not 1/n.
  const int n = options_.supersampling;
  std::vector<cv::Vec2d> offsets;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j)
      offsets.emplace_back((i + (j + 0.5) / n) / n, (j + (i + 0.5) / n) / n);
  }
  const double inv_samples = 1.0 / (n * n);

  cv::Mat1b image(height, width);
  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const cv::Vec3d* top = board_h[y];
      const cv::Vec3d* bottom = board_h[y + 1];
      for (int x = 0; x < width; ++x) {
        double sum = 0;
        for (const cv::Vec2d& ab : offsets) {
          const double a = ab[0], b = ab[1];
          const cv::Vec3d h = (top[x] * (1 - a) + top[x + 1] * a) * (1 - b) +
                              (bottom[x] * (1 - a) + bottom[x + 1] * a) * b;
          if (!(h[2] > 0)) {  // the plane is behind the camera along this ray
            sum += background;
            continue;
          }
          const double u = h[0] / h[2], v = h[1] / h[2];
          if (u < u_lo - margin || u >= u_hi + margin || v < v_lo - margin || v >= v_hi + margin) {
            sum += background;
          } else if (u < u_lo || u >= u_hi || v < v_lo || v >= v_hi) {
            sum += light;
          } else {
            // Square index counted from the corner square at (-s, -s); (i + j) even is dark, so the
            // square between corners 0, 1, cols and cols+1 is dark (DetectChessboard's rule).
            const long i = static_cast<long>(std::floor(u / s)) + 1;
            const long j = static_cast<long>(std::floor(v / s)) + 1;
            sum += ((i + j) % 2 == 0) ? dark : light;
          }
        }
        image(y, x) = cv::saturate_cast<uchar>(sum * inv_samples);
      }
    }
  });
  return image;
}

RenderedPair ChessboardRenderer::Render(const cv::Affine3d& board_in_left) const {
  const cv::Affine3d in_right = RightPose(rig_, board_in_left);
  RenderedPair out;
  out.left = RenderCamera(*left_rays_, board_in_left.rotation(), board_in_left.translation());
  out.right = RenderCamera(*right_rays_, in_right.rotation(), in_right.translation());
  return out;
}

Result<RenderedPair> RenderChessboardPair(const geometry::StereoCalibration& truth_rig,
                                          const BoardSpec& board,
                                          const cv::Affine3d& board_pose_in_left_cam,
                                          cv::Size image_size, const RenderOptions& options) {
  Result<ChessboardRenderer> renderer =
      ChessboardRenderer::Create(truth_rig, board, image_size, options);
  if (!renderer.ok()) return renderer.error();
  return renderer->Render(board_pose_in_left_cam);
}

namespace {

// True when the outline of the board plus margin (sampled densely) projects inside the image,
// `border` pixels from the edges, in front of the camera, and where the lens model is still
// one-to-one (undistorting the projection gives the ray back).
bool OutlineInView(const std::vector<cv::Point3d>& outline, const cv::Affine3d& pose,
                   const cv::Matx33d& K, const cv::Mat& D, cv::Size image, int border) {
  std::vector<cv::Point3d> in_cam;
  in_cam.reserve(outline.size());
  for (const cv::Point3d& p : outline) {
    const cv::Vec3d q = pose * cv::Vec3d(p.x, p.y, p.z);
    if (q[2] <= 1e-3) return false;
    in_cam.emplace_back(q[0], q[1], q[2]);
  }
  std::vector<cv::Point2d> projected;
  cv::projectPoints(in_cam, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K, D, projected);
  for (const cv::Point2d& p : projected) {
    if (p.x < border || p.y < border || p.x > image.width - 1 - border ||
        p.y > image.height - 1 - border) {
      return false;
    }
  }
  std::vector<cv::Point2d> back;
  cv::undistortPoints(projected, back, K, D, cv::noArray(), cv::noArray(), kUndistortCriteria);
  for (std::size_t k = 0; k < back.size(); ++k) {
    const double x = in_cam[k].x / in_cam[k].z, y = in_cam[k].y / in_cam[k].z;
    if (std::abs(back[k].x - x) > 1e-4 || std::abs(back[k].y - y) > 1e-4) return false;
  }
  return true;
}

// The board with its margin as GenerateBoardPoses places it: its outline (sampled densely along
// each edge), its centre and its sizes, in the board's frame.
struct BoardOutline {
  std::vector<cv::Point3d> points;
  cv::Vec3d centre;
  double board_width_m = 0;  // the printed squares' width
  double width_m = 0, height_m = 0;
};

BoardOutline MakeBoardOutline(const BoardSpec& board, const PoseOptions& options) {
  const double s = board.square_size_m;
  const double m = options.margin_squares * s;
  const double u0 = -s - m, u1 = board.inner_cols * s + m, v0 = -s - m,
               v1 = board.inner_rows * s + m;
  BoardOutline outline;
  constexpr int kPerEdge = 16;
  for (int k = 0; k < kPerEdge; ++k) {
    const double f = static_cast<double>(k) / kPerEdge;
    outline.points.emplace_back(u0 + f * (u1 - u0), v0, 0);
    outline.points.emplace_back(u1, v0 + f * (v1 - v0), 0);
    outline.points.emplace_back(u1 - f * (u1 - u0), v1, 0);
    outline.points.emplace_back(u0, v1 - f * (v1 - v0), 0);
  }
  outline.centre = cv::Vec3d((board.inner_cols - 1) * s / 2, (board.inner_rows - 1) * s / 2, 0);
  outline.board_width_m = (board.inner_cols + 1) * s;
  outline.width_m = u1 - u0;
  outline.height_m = v1 - v0;
  return outline;
}

// One random pose of the board in the left camera: aimed at target cell `cell` of the image's
// kTargetCells x kTargetCells grid, the aim pulled towards the middle by 1 - `pull`, with a random
// width, tilt and roll; its centre kept where the board (about hw x hh pixels from its centre)
// stays in both images (the right camera sees it shifted by the disparity).
cv::Affine3d DrawPose(std::mt19937& rng, int cell, double pull, const BoardOutline& outline,
                      const geometry::StereoCalibration& truth_rig, cv::Size image_size,
                      const PoseOptions& options) {
  const double deg = CV_PI / 180;
  const double cx = 0.5 + pull * ((cell % kTargetCells + Uniform(rng, 0, 1)) / kTargetCells - 0.5);
  const double cy = 0.5 + pull * ((cell / kTargetCells + Uniform(rng, 0, 1)) / kTargetCells - 0.5);
  const double width_fraction =
      Uniform(rng, options.min_width_fraction, options.max_width_fraction);
  const double tilt_x = Uniform(rng, -options.max_tilt_deg, options.max_tilt_deg) * deg;
  const double tilt_y = Uniform(rng, -options.max_tilt_deg, options.max_tilt_deg) * deg;
  const double roll = Uniform(rng, -options.max_roll_deg, options.max_roll_deg) * deg;

  const double z = truth_rig.M1(0, 0) * outline.board_width_m / (width_fraction * image_size.width);
  const double hw =
      0.5 * width_fraction * image_size.width * outline.width_m / outline.board_width_m +
      options.border_px;
  const double hh = hw * outline.height_m / outline.width_m;
  const double shift = truth_rig.M2(0, 0) * truth_rig.T[0] / z;
  double lo_x = hw + std::max(0.0, -shift), hi_x = image_size.width - 1 - hw - std::max(0.0, shift);
  double lo_y = hh, hi_y = image_size.height - 1 - hh;
  if (lo_x > hi_x) lo_x = hi_x = 0.5 * (lo_x + hi_x);
  if (lo_y > hi_y) lo_y = hi_y = 0.5 * (lo_y + hi_y);
  std::vector<cv::Point2d> target{{lo_x + cx * (hi_x - lo_x), lo_y + cy * (hi_y - lo_y)}}, ray;
  cv::undistortPoints(target, ray, truth_rig.M1, truth_rig.D1, cv::noArray(), cv::noArray(),
                      kUndistortCriteria);
  const cv::Vec3d centre(ray[0].x * z, ray[0].y * z, z);
  const cv::Matx33d rotation = Rotation(cv::Vec3d(0, 0, roll)) * Rotation(cv::Vec3d(0, tilt_y, 0)) *
                               Rotation(cv::Vec3d(tilt_x, 0, 0));
  return cv::Affine3d(rotation, centre - rotation * outline.centre);
}

}  // namespace

Result<std::vector<cv::Affine3d>> GenerateBoardPoses(const geometry::StereoCalibration& truth_rig,
                                                     const BoardSpec& board, cv::Size image_size,
                                                     int count, std::uint32_t seed,
                                                     const PoseOptions& options) {
  std::vector<std::string> problems = InputProblems(truth_rig, board, image_size);
  AppendPrefixed(problems, "options.", options.Validate());
  if (count < 0 || count > 100000) problems.push_back("count: must be in [0, 100000]" + Got(count));
  if (!problems.empty()) return InvalidArgument(problems);

  const BoardOutline outline = MakeBoardOutline(board, options);
  std::mt19937 rng(seed);
  std::vector<int> cells(kTargetCells * kTargetCells);
  std::iota(cells.begin(), cells.end(), 0);
  for (std::size_t i = cells.size() - 1; i > 0; --i) {
    std::swap(cells[i], cells[static_cast<std::size_t>(rng() % (i + 1))]);
  }

  std::vector<cv::Affine3d> poses;
  const cv::Affine3d left_to_right(truth_rig.R, truth_rig.T);
  try {
    for (int k = 0; k < count; ++k) {
      bool placed = false;
      for (int attempt = 0; attempt < kAttemptsPerPose && !placed; ++attempt) {
        // Aim at the pose's cell; when the board does not fit there, slide the aim towards the
        // middle a little with every attempt, so that the board ends up as far out as it fits.
        const int cell = cells[static_cast<std::size_t>(k) % cells.size()];
        const double pull = 1.0 - static_cast<double>(attempt) / kAttemptsPerPose;
        const cv::Affine3d pose =
            DrawPose(rng, cell, pull, outline, truth_rig, image_size, options);
        if (!OutlineInView(outline.points, pose, truth_rig.M1, truth_rig.D1, image_size,
                           options.border_px))
          continue;
        if (!OutlineInView(outline.points, left_to_right * pose, truth_rig.M2, truth_rig.D2,
                           image_size, options.border_px)) {
          continue;
        }
        poses.push_back(pose);
        placed = true;
      }
      if (!placed) {
        return OutOfRange(
            "GenerateBoardPoses: no pose keeps the board (with its margin) in view "
            "of both cameras; use a smaller board or width fraction");
      }
    }
  } catch (const cv::Exception& e) {
    return InvalidArgument("GenerateBoardPoses: OpenCV failed (" + e.err + ")");
  }
  return poses;
}

}  // namespace stevi::calibration
