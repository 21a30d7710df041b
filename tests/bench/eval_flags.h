// The flags the evaluation tools (stevi-eval, stevi-eval-tracking) share.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/common/flags.h"
#include "core/pipeline/config.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/bench/bench_flags.h"

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
  bool help = false;  // --help: the tool prints its usage and exits 0
};

// Applies flags.settings to `config`; prints the problems and exits with 2 when any.
inline void ApplySettingFlags(const EvalFlags& flags, pipeline::PipelineConfig& config) {
  const std::vector<std::string> problems = pipeline::ApplySettings(config, flags.settings);
  if (problems.empty()) return;
  for (const std::string& p : problems) std::fprintf(stderr, "--set %s\n", p.c_str());
  std::exit(2);
}

// What is wrong with --scenario `name` among `scenarios`: empty when no name was given or it names
// one of them, else the problem, listing their names.
inline std::string UnknownScenario(const std::vector<drivers::Scenario>& scenarios,
                                   const std::string& name) {
  if (name.empty() || std::any_of(scenarios.begin(), scenarios.end(),
                                  [&](const drivers::Scenario& sc) { return sc.name == name; })) {
    return "";
  }
  std::string names;
  for (const drivers::Scenario& sc : scenarios) names += " " + sc.name;
  return "unknown scenario '" + name + "' (one of:" + names + ")";
}

// The ranges of the numeric flags.
inline constexpr flags::WholeRange kAtLeastOne{.lo = 1};   // --frames, --scene-frames, ...
inline constexpr flags::WholeRange kAtLeastZero{.lo = 0};  // --max-width, --dump-scenes
inline constexpr flags::WholeRange kSizeSide{.lo = 64, .hi = 4096};  // --size, each side

// --size WxH into out.width and out.height.
inline std::string TakeSize(const std::string& value, EvalFlags& out) {
  const flags::Parsed<std::pair<std::int64_t, std::int64_t>> size =
      flags::ParseNumberPair(value, 'x', kSizeSide);
  if (!size.ok()) {
    return flags::Expected("", "--size", "WxH, each side " + flags::Describe(kSizeSide), value);
  }
  out.width = static_cast<int>(size.value.first);
  out.height = static_cast<int>(size.value.second);
  return "";
}

// Parses argv into `out` (--help sets out.help and ends the walk); returns the problem
// ("--frames: expected a whole number >= 1, got 'x'", "unexpected argument '--x'") when there is
// one. --trace only where allow_trace, --size and --max-width where allow_size, and --family,
// --seeds, --json, --dump, --dump-scenes, --scene-frames, --confirm-window where allow_family.
inline std::optional<std::string> ParseEvalFlags(int argc, char** argv, bool allow_trace,
                                                 bool allow_size, EvalFlags& out,
                                                 bool allow_family = false) {
  flags::FlagSet set("");
  set.Value("--set",
            [&out](const std::string& setting) {
              out.settings.push_back(setting);
              return std::string();
            })
      .Text("--scenario", &out.scenario)
      .Text("--algorithm", &out.algorithm)
      .Stop("--help", &out.help);
  WholeInt(set, "--frames", kAtLeastOne, &out.max_frames);
  if (allow_trace) set.Switch("--trace", &out.trace);
  if (allow_size) {
    set.Value("--size", [&out](const std::string& value) { return TakeSize(value, out); });
    WholeInt(set, "--max-width", kAtLeastZero, [&out](int width) { out.max_width_px = width; });
  }
  if (allow_family) {
    set.Text("--family", &out.family)
        .Text("--seeds", &out.seeds)
        .Text("--json", &out.json)
        .Text("--dump", &out.dump);
    WholeInt(set, "--dump-scenes", kAtLeastZero, &out.dump_scenes);
    WholeInt(set, "--scene-frames", kAtLeastOne, &out.scene_frames);
    WholeInt(set, "--confirm-window", kAtLeastOne, &out.confirm_window);
  }
  std::string problem = ParseArgs(set, argc, argv);
  if (problem.empty()) return std::nullopt;
  return problem;
}

// ParseEvalFlags for a tool's main: after --help prints `usage` on stdout and exits 0; on a
// problem prints "TOOL: PROBLEM" and the usage on stderr and exits 2.
inline EvalFlags ParseEvalFlagsOrExit(const char* tool, const char* usage, int argc, char** argv,
                                      bool allow_trace, bool allow_size,
                                      bool allow_family = false) {
  EvalFlags out;
  if (const std::optional<std::string> problem =
          ParseEvalFlags(argc, argv, allow_trace, allow_size, out, allow_family)) {
    std::fprintf(stderr, "%s: %s\n%s", tool, problem->c_str(), usage);
    std::exit(2);
  }
  if (out.help) {
    std::fputs(usage, stdout);
    std::exit(0);
  }
  return out;
}

}  // namespace stevi::bench
