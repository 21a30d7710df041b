// A stereo source for the engine's and the services' tests: real synthetic frames around the
// failures and the end a camera or a recording has.
#pragma once

#include <future>
#include <memory>
#include <string>

#include "drivers/stereo_source.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::server::test_support {

// A source that fails `failures` times (camera down), then renders `frames` synthetic frames,
// then ends: the engine's retry, accounting and end-of-stream paths on a real renderer. `fps`:
// the rate the engine paces it at (0: as fast as it can).
class FlakySource : public drivers::StereoSource {
 public:
  FlakySource(int failures, int frames, double fps = 0)
      : failures_(failures), frames_(frames), fps_(fps) {
    drivers::SyntheticOptions options;
    options.width = 320;
    options.height = 240;
    options.f_px = 350;
    renderer_ = std::make_unique<drivers::SyntheticRenderer>(options);
    rig_ = std::make_shared<const geometry::StereoRig>(renderer_->Rig());
  }
  std::string Describe() const override { return "flaky synthetic"; }
  std::shared_ptr<const geometry::StereoRig> Rig() const override { return rig_; }
  double NominalFps() const override { return fps_; }
  Result<StereoFrame> Next() override {
    if (failures_ > 0) {
      --failures_;
      return Unavailable("camera unplugged");
    }
    if (next_ >= frames_) {
      if (!ended_told_) ended_.set_value();  // the capture thread marks the source ENDED next
      ended_told_ = true;
      return OutOfRange("end of the recording");
    }
    return renderer_->Render(next_++);
  }

  // Ready once Next() has said the recording ended.
  std::shared_future<void> Ended() const { return ended_future_; }

 private:
  std::promise<void> ended_;
  std::shared_future<void> ended_future_ = ended_.get_future().share();
  bool ended_told_ = false;
  int failures_, frames_, next_ = 0;
  double fps_;
  std::unique_ptr<drivers::SyntheticRenderer> renderer_;
  std::shared_ptr<const geometry::StereoRig> rig_;
};

}  // namespace stevi::server::test_support
