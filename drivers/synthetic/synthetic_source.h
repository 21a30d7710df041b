// The built-in synthetic rig: renders a rectified stereo pair of a scene, with exact truth.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "drivers/stereo_source.h"
#include "drivers/truth.h"
#include "drivers/synthetic/scene.h"

namespace stevi::drivers {

inline constexpr int kMaxLoopFrames = 600;

struct SyntheticOptions {
  int width = 640;
  int height = 480;
  double f_px = 700.0;       // rectified focal length, pixels
  double baseline_m = 0.6;   // metres
  double fps = 10.0;         // the scene's clock: frame k is rendered at t = k / fps
  double noise_sigma = 2.0;  // Gaussian pixel noise, grey levels (0 disables)
  uint64_t seed = 1;         // seeds the pixel noise (frame k uses seed and k) and the textures
  // Sensor effects, applied to the rendered (linear, 0..255) images before the noise and the
  // 8-bit quantisation, in this order: blur (optics), vignetting, the right camera's gain. The
  // defaults disable them all (and the images are then exactly as without these fields).
  double blur_sigma_px = 0.0;  // Gaussian blur of both images, pixels (0 = none; <= 10)
  double vignetting = 0.0;     // radial fall-off: grey x (1 - vignetting (r / r_corner)^2), 0..0.9
  double right_gain = 1.0;     // right image = right_gain x image (a gain mismatch), 0.5..2
  // Residual vertical misalignment: the right image is rendered moved down by this many pixels
  // (sub-pixel, |shift| <= 2): right(u, v) = ideal_right(u, v - shift). The truth is of the left
  // image and stays exact.
  double right_vertical_shift_px = 0.0;
  Scene scene = DefaultScene();
  // SyntheticSource only. > 0: render frames 0..loop_frames-1 once (the first lap) and play them
  // again and again after that, with t_ns and index still counting up: a source that costs
  // nothing per frame after the first lap, as a camera does (benchmarks, slow machines). Costs
  // width * height * 2 bytes a frame; at most kMaxLoopFrames. Moving obstacles jump at each lap.
  int loop_frames = 0;

  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.SyntheticConfig (the scene is chosen by name, the rest is not
  // configurable over the wire).
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.width, Field("width", "pixels").In(16, 8192));
    v.Number(s.height, Field("height", "pixels").In(16, 8192));
    v.Number(s.f_px, Field("f_px", "pixels", "rectified focal length").Above(0));
    v.Number(s.baseline_m, Field("baseline_m", "m").Above(0));
    v.Number(s.noise_sigma, Field("noise_sigma", "grey levels", "pixel noise").AtLeast(0));
    v.Number(s.seed, Field("seed", "", "seeds the noise and the textures"));
    v.Number(s.loop_frames, Field("loop_frames", "frames",
                                  "render once and loop; 0 = render "
                                  "every frame")
                                .In(0, kMaxLoopFrames));
  }
};

// Renders frames of the scene. Pure function of (options, index): deterministic.
class SyntheticRenderer {
 public:
  explicit SyntheticRenderer(SyntheticOptions options);
  ~SyntheticRenderer();
  SyntheticRenderer(SyntheticRenderer&&) noexcept;
  SyntheticRenderer& operator=(SyntheticRenderer&&) noexcept;

  const SyntheticOptions& options() const;
  geometry::StereoRig Rig() const;
  // Renders frame `index` (rectified grey pair, t_ns = index / fps) and its truth.
  // unix_time_ns is left 0: the capture loop stamps it. Thread-safe (const, no shared state).
  StereoFrame Render(int64_t index, FrameTruth* truth = nullptr) const;
  // The truth of frame `index` alone (no images): identical to Render's truth, several times
  // cheaper. For scoring long sequences.
  FrameTruth Truth(int64_t index) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The synthetic source: an endless sequence of rendered frames. The frame's t_ns is the scene time.
class SyntheticSource : public StereoSource {
 public:
  // options must be valid (see OpenSyntheticSource).
  explicit SyntheticSource(SyntheticOptions options);
  std::string Describe() const override;
  std::shared_ptr<const geometry::StereoRig> Rig() const override;
  // Renders the next frame (never ends). t_ns is the scene time; unix_time_ns is left 0 for the
  // capture loop to stamp.
  Result<StereoFrame> Next() override;
  double NominalFps() const override;

  // Truth of the frame last returned by Next() (not kept with loop_frames: empty then).
  const FrameTruth& last_truth() const { return truth_; }
  // The same, through the StereoSource interface: nullptr with loop_frames (no truth kept).
  const FrameTruth* LastTruth() const override {
    return renderer_.options().loop_frames > 0 ? nullptr : &truth_;
  }
  const SyntheticRenderer& renderer() const { return renderer_; }

 private:
  SyntheticRenderer renderer_;
  std::shared_ptr<const geometry::StereoRig> rig_;
  FrameTruth truth_;
  int64_t next_index_ = 0;
  std::vector<StereoFrame> loop_;  // loop_frames: the first lap's frames (images shared, read-only)
};

// Validates the options (every problem listed) and builds the source.
Result<std::unique_ptr<SyntheticSource>> OpenSyntheticSource(SyntheticOptions options);

// A named evaluation scene with truth: the rig, noise, seed and scene, and how many frames to
// play (frame k at t = k / options.fps; moving obstacles loop every frames / fps seconds).
struct Scenario {
  std::string name;
  std::string description;  // what is in it and what makes it hard
  SyntheticOptions options;
  int frames = 60;
};

// The scenarios for evaluating the obstacle detectors, on the default rig (640x480, f = 700 px,
// B = 0.6 m, 10 fps): "clear_sky", "low_over_ground", "small_far", "close_pair", "low_contrast"
// and "tower_on_ground". Every obstacle shows at least 8 px of disparity (all of its pixels) and
// is mostly in frame. Defined in scene.cc, next to DefaultScene().
std::vector<Scenario> EvaluationScenarios();

// "flight": the demo scene with the rig flying forward at 3 m/s through it, repeating every 10 s
// (Scene::rig_velocity_mps), for the georeferencing demo. Defined in scene.cc.
Scenario FlightScenario();

// The scenarios for evaluating the tracker, on the same rig with the camera 100 m up (every
// obstacle against the sky, so that detection is clean): "crossing_occlusion" (two obstacles
// crossing at 30 and 48 m, and a drone hidden for 10 frames behind a nearer hovering one),
// "entries_exits" (four entries and three exits at the image sides) and "head_on" (a drone closing
// from 50 to 12.6 m, passing 2.4 m from the camera). Obstacle ids are the truth ids to score
// against. Defined in tracking_scenarios.cc.
std::vector<Scenario> TrackingScenarios();

}  // namespace stevi::drivers
