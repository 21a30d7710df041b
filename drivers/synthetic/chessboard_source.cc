#include "drivers/synthetic/chessboard_source.h"

#include <cmath>
#include <sstream>
#include <utility>

#include "core/common/error.h"
#include "core/geometry/calibration_io.h"
#include "core/geometry/stereo_rig.h"

namespace stevi::drivers {

std::vector<std::string> ChessboardSourceOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (!(fps > 0 && fps <= 1000)) problems.push_back("fps: must be in (0, 1000]" + Got(fps));
  if (hold_frames < 1 || hold_frames > 10000) {
    problems.push_back("hold_frames: must be in 1..10000" + Got(hold_frames));
  }
  if (poses < 1 || poses > 1000) problems.push_back("poses: must be in 1..1000" + Got(poses));
  AppendPrefixed(problems, "board.", board.Validate());
  return problems;
}

Result<std::unique_ptr<ChessboardSource>> ChessboardSource::Open(ChessboardSourceOptions options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  const cv::Size size(options.width, options.height);
  const geometry::StereoCalibration rig = geometry::IdealCalibration(
      size, options.f_px, options.baseline_m, options.width / 2.0, options.height / 2.0);
  Result<calibration::ChessboardRenderer> renderer =
      calibration::ChessboardRenderer::Create(rig, options.board, size);
  if (!renderer.ok()) return renderer.error();
  Result<std::vector<cv::Affine3d>> poses = calibration::GenerateBoardPoses(
      rig, options.board, size, options.poses, static_cast<std::uint32_t>(options.seed));
  if (!poses.ok()) return poses.error();
  return std::unique_ptr<ChessboardSource>(new ChessboardSource(
      std::move(options), std::move(renderer).value(), std::move(poses).value()));
}

ChessboardSource::ChessboardSource(ChessboardSourceOptions options,
                                   calibration::ChessboardRenderer renderer,
                                   std::vector<cv::Affine3d> poses)
    : options_(std::move(options)),
      renderer_(std::move(renderer)),
      poses_(std::move(poses)),
      rig_(std::make_shared<const geometry::StereoRig>(geometry::StereoRig::Ideal(
          cv::Size(options_.width, options_.height), options_.f_px, options_.baseline_m,
          options_.width / 2.0, options_.height / 2.0, "synthetic"))) {}

std::string ChessboardSource::Describe() const {
  std::ostringstream out;
  out << "synthetic chessboard " << options_.board.Name() << " of "
      << options_.board.square_size_m * 1000 << " mm squares, " << options_.width << "x"
      << options_.height << " f=" << options_.f_px << "px B=" << options_.baseline_m << "m";
  return out.str();
}

size_t ChessboardSource::PoseIndexAt(int64_t index) const {
  const int64_t step = (index < 0 ? 0 : index) / options_.hold_frames;
  return static_cast<size_t>(step % static_cast<int64_t>(poses_.size()));
}

const cv::Affine3d& ChessboardSource::PoseAt(int64_t index) const {
  return poses_[PoseIndexAt(index)];
}

Result<StereoFrame> ChessboardSource::Next() {
  const int64_t index = next_index_++;
  // One rendering per pose (the board holds each for hold_frames frames); every frame gets its
  // own copy, which the noise below and the frame's consumers may write to.
  const size_t pose = PoseIndexAt(index);
  if (rendered_pose_ != pose) {
    rendered_ = renderer_.Render(poses_[pose]);
    rendered_pose_ = pose;
  }
  calibration::RenderedPair pair{rendered_.left.clone(), rendered_.right.clone()};
  if (options_.noise_sigma > 0) {
    // Deterministic per frame and view.
    for (int view = 0; view < 2; ++view) {
      cv::Mat1b& image = view == 0 ? pair.left : pair.right;
      cv::RNG rng(options_.seed * 1000003ULL + static_cast<uint64_t>(index) * 2 + view);
      cv::Mat noise(image.size(), CV_32F);
      rng.fill(noise, cv::RNG::NORMAL, 0.0, options_.noise_sigma);
      cv::Mat sum;
      image.convertTo(sum, CV_32F);
      sum += noise;
      sum.convertTo(image, CV_8U);  // saturating
    }
  }
  StereoFrame frame;
  frame.left = pair.left;
  frame.right = pair.right;
  frame.index = index;
  frame.t_ns = static_cast<int64_t>(std::llround(static_cast<double>(index) / options_.fps * 1e9));
  frame.rectified = true;
  return frame;
}

}  // namespace stevi::drivers
