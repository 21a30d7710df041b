// A synthetic chessboard seen by a stereo rig: images for calibration tests and for the server's
// synthetic source, with the true corner positions.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include "core/calibration/chessboard.h"
#include "core/common/error.h"
#include "core/geometry/calibration_io.h"

namespace stevi::calibration {

struct RenderOptions {
  // Light margin around the squares (in squares). Detectors want a quiet zone of about one square.
  double margin_squares = 1.0;
  // Grey levels (0..255): dark squares, light squares and the margin, and everything off the board.
  double dark_level = 30;
  double light_level = 225;
  double background_level = 110;
  // Samples per pixel along each axis, averaged (anti-aliasing): 4 gives 16 samples a pixel, and
  // corners the detectors find to a few hundredths of a pixel.
  int supersampling = 4;

  std::vector<std::string> Validate() const;
};

struct RenderedPair {
  cv::Mat1b left, right;
};

// The board's inner corners as each camera of the rig sees them (pixels, lens distortion applied),
// in BoardSpec::ObjectPoints() order: the truth that detection is measured against.
struct ProjectedBoard {
  std::vector<cv::Point2f> left, right;
};

// `board_in_left` takes board-frame points (BoardSpec::ObjectPoints(), metres) to the left camera:
// point_in_left = board_in_left * point_in_board. The right camera sees R * point_in_left + T.
ProjectedBoard ProjectChessboard(const geometry::StereoCalibration& truth_rig,
                                 const BoardSpec& board, const cv::Affine3d& board_in_left);

// Renders a planar chessboard for the two cameras of a rig, with their intrinsics and distortion:
// every sample of every pixel is undistorted to a ray (cv::undistortPoints, iterated to 1e-9 px,
// done once per camera and interpolated inside the pixel) and intersected with the board plane.
// Build once and render many poses. Immutable after Create(); Render() is thread-safe.
class ChessboardRenderer {
 public:
  // kInvalidArgument listing every problem of the rig, the board, the size or the options.
  static Result<ChessboardRenderer> Create(const geometry::StereoCalibration& truth_rig,
                                           const BoardSpec& board, cv::Size image_size,
                                           const RenderOptions& options = {});

  RenderedPair Render(const cv::Affine3d& board_in_left) const;

  const geometry::StereoCalibration& rig() const { return rig_; }
  cv::Size image_size() const { return image_size_; }

 private:
  struct RayGrid;  // normalised rays at the pixel corners of one camera
  ChessboardRenderer() = default;
  cv::Mat1b RenderCamera(const RayGrid& rays, const cv::Matx33d& R, const cv::Vec3d& t) const;

  geometry::StereoCalibration rig_;
  BoardSpec board_;
  cv::Size image_size_;
  RenderOptions options_;
  std::shared_ptr<const RayGrid> left_rays_, right_rays_;
};

// One-off convenience: ChessboardRenderer::Create(...).Render(board_pose_in_left_cam).
Result<RenderedPair> RenderChessboardPair(const geometry::StereoCalibration& truth_rig,
                                          const BoardSpec& board,
                                          const cv::Affine3d& board_pose_in_left_cam,
                                          cv::Size image_size, const RenderOptions& options = {});

struct PoseOptions {
  // Tilt of the board about its own x and y axes, each uniform in +-max_tilt_deg (degrees).
  double max_tilt_deg = 30;
  // Turn of the board in its plane, uniform in +-max_roll_deg (degrees).
  double max_roll_deg = 15;
  // The board's width (squares only) as seen in the left image, as a fraction of the image width,
  // uniform in [min, max]; sets the distance.
  double min_width_fraction = 0.45;
  double max_width_fraction = 0.75;
  // The board plus this margin (in squares) must be fully inside both images, this far (pixels)
  // from the edges.
  double margin_squares = 1.0;
  int border_px = 4;

  std::vector<std::string> Validate() const;
};

// `count` varied board poses (board_in_left), deterministic for a seed: the board's centre is
// aimed at the cells of a 3x3 grid over the range of centres that keep the board in view (so
// the corner cells push it into the image's corners), in turn (shuffled by the seed, jittered in
// the cell), tilted and turned at random, and kept only when the board with its margin is fully
// in view of both cameras; when it is not, the aim slides towards the middle, so the board ends up
// as far out as it fits. kInvalidArgument for invalid input; kOutOfRange when no pose fits
// (cameras that do not overlap, a board too large).
Result<std::vector<cv::Affine3d>> GenerateBoardPoses(const geometry::StereoCalibration& truth_rig,
                                                     const BoardSpec& board, cv::Size image_size,
                                                     int count, std::uint32_t seed,
                                                     const PoseOptions& options = {});

}  // namespace stevi::calibration
