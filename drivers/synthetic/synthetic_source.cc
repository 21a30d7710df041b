// The synthetic source itself: SyntheticOptions' validation, SyntheticSource (its description,
// its rig, and the frame loop that renders frame after frame, or replays the first lap with
// loop_frames) and OpenSyntheticSource. The rendering is SyntheticRenderer's (renderer.cc,
// ray_cast.cc, textures.cc).
#include "drivers/synthetic/synthetic_source.h"

#include <cmath>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace stevi::drivers {

std::vector<std::string> SyntheticOptions::Validate() const {
  std::vector<std::string> problems = fields::Check(*this);
  if (!(fps > 0.0) || !std::isfinite(fps)) problems.push_back("fps: must be > 0");
  if (!(blur_sigma_px >= 0.0 && blur_sigma_px <= 10.0)) {
    problems.push_back("blur_sigma_px: must be in 0..10" + Got(blur_sigma_px));
  }
  if (!(vignetting >= 0.0 && vignetting <= 0.9)) {
    problems.push_back("vignetting: must be in 0..0.9" + Got(vignetting));
  }
  if (!(right_gain >= 0.5 && right_gain <= 2.0)) {
    problems.push_back("right_gain: must be in 0.5..2" + Got(right_gain));
  }
  if (!(std::abs(right_vertical_shift_px) <= 2.0)) {
    problems.push_back("right_vertical_shift_px: must be in -2..2" + Got(right_vertical_shift_px));
  }
  for (const std::string& p : scene.Validate()) problems.push_back("scene." + p);
  return problems;
}

SyntheticSource::SyntheticSource(SyntheticOptions options)
    : renderer_(std::move(options)),
      rig_(std::make_shared<const geometry::StereoRig>(renderer_.Rig())) {}

std::string SyntheticSource::Describe() const {
  const SyntheticOptions& o = renderer_.options();
  std::ostringstream out;
  out << "synthetic " << o.width << "x" << o.height << " f=" << o.f_px << "px B=" << o.baseline_m
      << "m";
  return out.str();
}

std::shared_ptr<const geometry::StereoRig> SyntheticSource::Rig() const { return rig_; }

Result<StereoFrame> SyntheticSource::Next() {
  const int loop_frames = renderer_.options().loop_frames;
  if (loop_frames <= 0) {
    StereoFrame frame = renderer_.Render(next_index_, &truth_);
    ++next_index_;
    return frame;
  }
  const size_t k = static_cast<size_t>(next_index_ % loop_frames);
  if (k >= loop_.size()) loop_.push_back(renderer_.Render(next_index_));  // the first lap
  StereoFrame frame = loop_[k];  // shares the images: nobody writes into a source's frames
  frame.index = next_index_;
  const double t_s = static_cast<double>(next_index_) / renderer_.options().fps;  // as Render
  frame.t_ns = std::llround(t_s * 1e9);
  ++next_index_;
  return frame;
}

double SyntheticSource::NominalFps() const { return renderer_.options().fps; }

Result<std::unique_ptr<SyntheticSource>> OpenSyntheticSource(SyntheticOptions options) {
  const std::vector<std::string> problems = options.Validate();
  if (!problems.empty()) return InvalidArgument(problems);
  return std::make_unique<SyntheticSource>(std::move(options));
}

}  // namespace stevi::drivers
