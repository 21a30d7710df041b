// The pipeline's configuration: one options struct per stage, validated as a whole.
#pragma once

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/error.h"
#include "core/common/fields.h"
#include "core/detection/canonical.h"
#include "core/detection/range_scan.h"
#include "core/detection/stevie.h"
#include "core/detection/stevis.h"
#include "core/detection/stixels.h"
#include "core/geometry/range.h"
#include "core/stereo/matcher.h"
#include "core/geo/mount.h"
#include "core/tracking/tracker.h"

namespace stevi::pipeline {

enum class Algorithm { kCanonical, kSteViE, kSteViS, kStixels };

// "canonical", "stevie", "stevis", "stixels".
std::string_view AlgorithmName(Algorithm algorithm);
std::optional<Algorithm> AlgorithmFromName(std::string_view name);

struct PipelineConfig {
  Algorithm algorithm = Algorithm::kCanonical;
  // Frames wider than this (pixels) are binned after rectification: each k x k block of pixels
  // averaged into one, with the smallest whole k that brings the width to this or less. Matching,
  // detection, tracking and the published images, boxes and rig are then those of the binned
  // images. Binning stops where the rig's disparity floor would fall under
  // geometry::kMinBinnedDisparityPx (BinningFactor): it is chosen for what it costs in range. The
  // detectors' kernels and rings scale with the image width, but areas are counted in processed
  // pixels and the matcher searches a fixed number of disparities, so binning is also the cheap
  // way to see a wide frame: see the README's configuration section for the figures. 0 = never bin.
  int max_width_px = 800;
  // The matcher. The stixel world wants matcher.kind = dense (disparities on real surfaces, with a
  // per-pixel confidence); SteViE and SteViS were tuned on block matching.
  stereo::MatcherOptions matcher;
  geometry::RangeOptions range;
  detection::CanonicalOptions canonical;
  detection::SteViEOptions stevie;
  detection::SteViSOptions stevis;
  // The stixel world and its obstacles (core/detection/README.md, "The stixel world"). Its ground
  // is range_scan.ground: one plane per frame serves the obstacles and the range scan.
  detection::StixelOptions stixels;
  // Tracking of the detections over frames; can change while serving (the tracks are kept).
  tracking::TrackerOptions tracking;
  // How the camera sits on the vehicle, for georeferencing the tracks (core/geo/mount.h). Can
  // change while serving.
  geo::MountOptions mount;
  // The nearest range per azimuth bin in the body frame, from the disparity alone
  // (core/detection/README.md, "The range scan"). Can change while serving.
  detection::RangeScanOptions range_scan;

  // Every problem of every stage, each as "field.path: problem".
  std::vector<std::string> Validate() const;

  static constexpr fields::ChoiceName<Algorithm> kAlgorithmNames[] = {
      {Algorithm::kCanonical, "canonical"},
      {Algorithm::kSteViE, "stevie"},
      {Algorithm::kSteViS, "stevis"},
      {Algorithm::kStixels, "stixels"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.algorithm, Field("algorithm", "", "which detector runs").Flag("algorithm", "NAME"),
             kAlgorithmNames);
    v.Number(s.max_width_px, Field("max_width_px", "pixels", "wider frames are binned")
                                 .In(64, 16384)
                                 .Or(0, "never bin"));
    v.Nested(s.matcher, Field("matcher"));
    v.Nested(s.range, Field("range"));
    v.Nested(s.canonical, Field("canonical"));
    v.Nested(s.stevie, Field("stevie"));
    v.Nested(s.stevis, Field("stevis"));
    v.Nested(s.stixels, Field("stixels"));
    v.Nested(s.tracking, Field("tracking"));
    v.Nested(s.mount, Field("mount"));
    v.Nested(s.range_scan, Field("range_scan"));
  }
};

// The default configuration with `algorithm` and the matcher it was built for: the dense matcher
// for the stixel world (it weighs every disparity by its confidence), block matching for the
// thesis detectors (their gates were tuned on it).
PipelineConfig ConfigForAlgorithm(Algorithm algorithm);

// Applies settings written "path=value" (the option table's dotted paths: "stixels.split=edges",
// "matcher.kind=dense", "tracking.confirm_window=7") in order, then validates the whole. On any
// problem `config` is left as it was and every problem is returned, each naming its setting.
std::vector<std::string> ApplySettings(PipelineConfig& config,
                                       const std::vector<std::string>& settings);

// Holds the active configuration. Thread-safe. Readers take an immutable snapshot per frame;
// Set() validates first and leaves the active config untouched when anything is wrong.
class ConfigStore {
 public:
  explicit ConfigStore(PipelineConfig initial = {});
  std::shared_ptr<const PipelineConfig> Get() const;
  // Returns the new snapshot, or kInvalidArgument naming every bad field.
  Result<std::shared_ptr<const PipelineConfig>> Set(PipelineConfig config);

 private:
  mutable std::mutex mu_;
  std::shared_ptr<const PipelineConfig> active_;
};

}  // namespace stevi::pipeline
