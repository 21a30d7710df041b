// The flags the evaluation tools (stevi-eval, stevi-eval-tracking) share.
#pragma once

#include <exception>
#include <optional>
#include <string>

namespace stevi::bench {

struct EvalFlags {
  int max_frames = 0;          // --frames N: cap the frames per scenario (0 = each scenario's own)
  std::string scenario;        // --scenario NAME (empty = all)
  std::string algorithm;       // --algorithm NAME (empty = all)
  bool trace = false;          // --trace (only where allow_trace)
};

// Parses argv into `flags`; returns the problem ("--frames: expected ...", "unknown flag --x")
// when there is one.
inline std::optional<std::string> ParseEvalFlags(int argc, char** argv, bool allow_trace,
                                                 EvalFlags& flags) {
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if (allow_trace && flag == "--trace") {
      flags.trace = true;
      continue;
    }
    if (flag != "--frames" && flag != "--scenario" && flag != "--algorithm") {
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
    } else if (flag == "--scenario") {
      flags.scenario = value;
    } else {
      flags.algorithm = value;
    }
  }
  return std::nullopt;
}

}  // namespace stevi::bench
