// stevi-eval --family: the detectors over the randomised scene families
// (drivers/synthetic/random_scenes.h), per family and overall. See tests/bench/README.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "core/pipeline/config.h"

namespace stevi::bench {

struct EvalVariant {
  std::string name;
  pipeline::PipelineConfig config;
};

struct FamilyEvalOptions {
  std::vector<std::string> families;  // each one of drivers::RandomSceneFamilies()
  uint64_t seed_first = 1, seed_last = 40;
  int max_frames = 0;  // cap per scene (0 = the scene's own 4..6)
  // --scene-frames N: render N frames of every scene (0 = the scene's own 4..6, or max_frames).
  // Frames past the scene's own continue its obstacles' straight paths (the renderer is a pure
  // function of the scene and the frame index, so the frames stay a pure function of (family,
  // seed, N)); obstacles that leave the view stop being expected.
  int scene_frames = 0;
  // The track-level window: an obstacle must be confirmed within this many frames of becoming
  // measurable (--confirm-window N).
  int confirm_window = 5;
  std::optional<int> max_width_px;  // PipelineConfig::max_width_px (unset: the default)
  std::string json_path;            // --json FILE (empty: none)
  std::string dump_dir;             // --dump DIR (empty: none)
  int dump_scenes = 3;              // --dump: the first N seeds of each family
};

// Parses "A-B" or "A" into [first, last]; false when malformed or first > last.
bool ParseSeedRange(const std::string& text, uint64_t& first, uint64_t& last);

// Runs every variant over every scene; prints the tables (and writes the JSON and the pictures).
// Returns the process exit code.
int RunFamilyEval(const FamilyEvalOptions& options, const std::vector<EvalVariant>& variants);

}  // namespace stevi::bench
