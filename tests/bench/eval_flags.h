// The flags the evaluation tools (stevi-eval, stevi-eval-tracking) share.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <optional>
#include <string>
#include <vector>

#include "core/pipeline/config.h"

namespace stevi::bench {

struct EvalFlags {
  int max_frames = 0;     // --frames N: cap the frames per scenario (0 = each scenario's own)
  std::string scenario;   // --scenario NAME (empty = all)
  std::string algorithm;  // --algorithm NAME (empty = all)
  bool trace = false;     // --trace (only where allow_trace)
  // --size WxH: render every scenario at this size instead of its own, with the focal length scaled
  // by the width so the horizontal field of view stays (0 x 0 = each scenario's own size).
  int width = 0, height = 0;
  // --max-width N: PipelineConfig::max_width_px (frames wider are binned; 0 = never). Unset: the
  // default.
  std::optional<int> max_width_px;
  // stevi-eval only (allow_family): --family NAME|all, --seeds A-B, --json FILE, --dump DIR,
  // --dump-scenes N (the random scene families; see eval_family.h).
  std::string family;
  std::string seeds;
  std::string json;
  std::string dump;
  int dump_scenes = 3;
  // --scene-frames N: render N frames of every random scene (0 = its own 4..6); --confirm-window
  // N: the track-level confirmation window (frames, default 5). See eval_family.h.
  int scene_frames = 0;
  int confirm_window = 5;
  // --set path=value (repeatable): pipeline settings applied over each algorithm's own
  // configuration (pipeline::ApplySettings), to measure an option without a rebuild.
  std::vector<std::string> settings;
};

// Applies flags.settings to `config`; prints the problems and exits with 2 when any.
inline void ApplySettingFlags(const EvalFlags& flags, pipeline::PipelineConfig& config) {
  const std::vector<std::string> problems = pipeline::ApplySettings(config, flags.settings);
  if (problems.empty()) return;
  for (const std::string& p : problems) std::fprintf(stderr, "--set %s\n", p.c_str());
  std::exit(2);
}

// Parses a whole number >= `min` into `out`; the problem when it is not one.
inline std::optional<std::string> ParseWholeFlag(const std::string& flag, const std::string& value,
                                                 int min, int& out) {
  size_t used = 0;
  int parsed = 0;
  try {
    parsed = std::stoi(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != value.size() || value.empty() || parsed < min) {
    return flag + ": expected a whole number >= " + std::to_string(min) + ", got '" + value + "'";
  }
  out = parsed;
  return std::nullopt;
}

// Parses argv into `flags`; returns the problem ("--frames: expected ...", "unknown flag --x")
// when there is one.
inline std::optional<std::string> ParseEvalFlags(int argc, char** argv, bool allow_trace,
                                                 bool allow_size, EvalFlags& flags,
                                                 bool allow_family = false) {
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (flag == "--set") {
      if (i + 1 >= argc) return flag + " needs a value";
      flags.settings.push_back(argv[++i]);
      continue;
    }
    if (allow_trace && flag == "--trace") {
      flags.trace = true;
      continue;
    }
    if (allow_family &&
        (flag == "--family" || flag == "--seeds" || flag == "--json" || flag == "--dump" ||
         flag == "--dump-scenes" || flag == "--scene-frames" || flag == "--confirm-window")) {
      if (i + 1 >= argc) return flag + " needs a value";
      const std::string value = argv[++i];
      if (flag == "--scene-frames" || flag == "--confirm-window") {
        std::optional<std::string> problem =
            flag == "--scene-frames" ? ParseWholeFlag(flag, value, 1, flags.scene_frames)
                                     : ParseWholeFlag(flag, value, 1, flags.confirm_window);
        if (problem) return problem;
      } else if (flag == "--family") {
        flags.family = value;
      } else if (flag == "--seeds") {
        flags.seeds = value;
      } else if (flag == "--json") {
        flags.json = value;
      } else if (flag == "--dump") {
        flags.dump = value;
      } else {
        size_t used = 0;
        try {
          flags.dump_scenes = std::stoi(value, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != value.size() || flags.dump_scenes < 0) {
          return "--dump-scenes: expected a whole number >= 0, got '" + value + "'";
        }
      }
      continue;
    }
    if (flag != "--frames" && flag != "--scenario" && flag != "--algorithm" &&
        ((flag != "--size" && flag != "--max-width") || !allow_size)) {
      return "unknown flag " + flag;
    }
    if (i + 1 >= argc) return flag + " needs a value";
    const std::string value = argv[++i];
    if (flag == "--frames") {
      size_t used = 0;
      try {
        flags.max_frames = std::stoi(value, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != value.size() || flags.max_frames < 1) {
        return "--frames: expected a whole number >= 1, got '" + value + "'";
      }
    } else if (flag == "--size") {
      int w = 0, h = 0;
      char end = 0;
      if (std::sscanf(value.c_str(), "%dx%d%c", &w, &h, &end) != 2 || w < 64 || h < 64 ||
          w > 4096 || h > 4096) {
        return "--size: expected WxH with each side in 64..4096, got '" + value + "'";
      }
      flags.width = w;
      flags.height = h;
    } else if (flag == "--max-width") {
      size_t used = 0;
      int max_width = -1;
      try {
        max_width = std::stoi(value, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (used != value.size() || max_width < 0) {
        return "--max-width: expected a whole number >= 0, got '" + value + "'";
      }
      flags.max_width_px = max_width;
    } else if (flag == "--scenario") {
      flags.scenario = value;
    } else {
      flags.algorithm = value;
    }
  }
  return std::nullopt;
}

}  // namespace stevi::bench
