// The synthetic rig with someone moving a chessboard in front of it: for calibrating without
// hardware (CaptureCalibration, `stevi-server --scene chessboard`).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/calibration/chessboard.h"
#include "core/calibration/chessboard_render.h"
#include "core/common/fields.h"
#include "drivers/stereo_source.h"

namespace stevi::drivers {

struct ChessboardSourceOptions {
  int width = 640;
  int height = 480;
  double f_px = 700.0;      // the ideal rig's focal length (pixels)
  double baseline_m = 0.6;  // metres
  double fps = 10.0;
  // The board: 9x6 inner corners of 10 cm squares (a 1 m x 0.7 m board).
  calibration::BoardSpec board{9, 6, 0.10};
  // The board holds each pose this many frames, then moves to the next of `poses` varied poses
  // (tilted, over the whole view), cycling.
  int hold_frames = 5;
  int poses = 24;
  double noise_sigma = 2.0;  // Gaussian pixel noise, grey levels
  uint64_t seed = 1;

  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.SyntheticConfig that the chessboard scene takes.
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.width, Field("width", "pixels").In(64, 4096));
    v.Number(s.height, Field("height", "pixels").In(64, 4096));
    v.Number(s.f_px, Field("f_px", "pixels", "the ideal rig's focal length").Above(0).Below(1e5));
    v.Number(s.baseline_m, Field("baseline_m", "m").Above(0).Below(100));
    v.Number(s.noise_sigma, Field("noise_sigma", "grey levels", "pixel noise").In(0, 100));
    v.Number(s.seed, Field("seed"));
  }
};

// Endless frames of the board (rectified: the rig is ideal, so a calibration from them recovers
// f_px and baseline_m). Thread-compatible, like every StereoSource.
class ChessboardSource : public StereoSource {
 public:
  // Validates the options, builds the renderer and the poses.
  static Result<std::unique_ptr<ChessboardSource>> Open(ChessboardSourceOptions options);

  std::string Describe() const override;
  std::shared_ptr<const geometry::StereoRig> Rig() const override { return rig_; }
  Result<StereoFrame> Next() override;
  double NominalFps() const override { return options_.fps; }

  // The pose the board holds at frame `index` (board frame to left camera).
  const cv::Affine3d& PoseAt(int64_t index) const;

 private:
  ChessboardSource(ChessboardSourceOptions options, calibration::ChessboardRenderer renderer,
                   std::vector<cv::Affine3d> poses);
  // The index in poses_ of the pose held at frame `index`.
  size_t PoseIndexAt(int64_t index) const;

  ChessboardSourceOptions options_;
  calibration::ChessboardRenderer renderer_;
  std::vector<cv::Affine3d> poses_;
  std::shared_ptr<const geometry::StereoRig> rig_;
  int64_t next_index_ = 0;
  // The last pose rendered (its index in poses_) and its images, reused while the board holds it.
  size_t rendered_pose_ = SIZE_MAX;
  calibration::RenderedPair rendered_;
};

}  // namespace stevi::drivers
