// The benchmarks' and evaluation tools' flags: flags::FlagSet over argv, with the three things
// these tools need beyond it:
//   - ranges open above ("seconds > 0", where flags::Describe would say "(0, inf]"),
//   - whole numbers that must fit an int,
//   - no context: "--seconds: expected ...", and "unexpected argument 'x'" where FlagSet::Parse
//     with an empty context says ": unexpected argument 'x'".
#pragma once

#include <climits>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "core/common/flags.h"

namespace stevi::bench {

// The upper bound of a real range open above: {.lo = 0, .hi = kNoUpperBound, .unit = "seconds",
// .lo_open = true} takes every finite number > 0 (ParseNumber takes no infinity).
inline constexpr double kNoUpperBound = std::numeric_limits<double>::infinity();

// What `range` accepts: flags::Describe, or "seconds > 0" when it is open above.
inline std::string DescribeRange(const flags::RealRange& range) {
  if (range.hi != kNoUpperBound) return flags::Describe(range);
  return std::string(range.unit) + (range.lo_open ? " > " : " >= ") + flags::FormatNumber(range.lo);
}

// A real number within `range`, handed to `take`: FlagSet::Real, or the same with DescribeRange
// in its message when the range is open above.
inline flags::FlagSet& Real(flags::FlagSet& set, const std::string& name,
                            const flags::RealRange& range, std::function<void(double)> take) {
  if (range.hi != kNoUpperBound) return set.Real(name, range, std::move(take));
  return set.Value(name, [name, range, take = std::move(take)](const std::string& text) {
    const flags::Parsed<double> number = flags::ParseNumber(text, range);
    if (!number.ok()) return flags::Expected("", name, DescribeRange(range), text);
    take(number.value);
    return std::string();
  });
}

// The same into *value.
inline flags::FlagSet& Real(flags::FlagSet& set, const std::string& name,
                            const flags::RealRange& range, double* value) {
  return Real(set, name, range, [value](double v) { *value = v; });
}

// A whole number within `range`, handed to `take` as an int: FlagSet::Whole when range.hi fits an
// int; a range open above (hi left at its default) is taken up to INT_MAX, and still described as
// ">= lo".
inline flags::FlagSet& WholeInt(flags::FlagSet& set, const std::string& name,
                                const flags::WholeRange& range, std::function<void(int)> take) {
  if (range.hi <= INT_MAX) {
    return set.Whole(name, range,
                     [take = std::move(take)](std::int64_t v) { take(static_cast<int>(v)); });
  }
  flags::WholeRange fits = range;
  fits.hi = INT_MAX;
  return set.Value(name, [name, range, fits, take = std::move(take)](const std::string& text) {
    const flags::Parsed<std::int64_t> number = flags::ParseNumber(text, fits);
    if (!number.ok()) return flags::Expected("", name, flags::Describe(range), text);
    take(static_cast<int>(number.value));
    return std::string();
  });
}

// The same into *value.
inline flags::FlagSet& WholeInt(flags::FlagSet& set, const std::string& name,
                                const flags::WholeRange& range, int* value) {
  return WholeInt(set, name, range, [value](int v) { *value = v; });
}

// Walks argv[1..] with `set` (made with an empty context). Returns "" when every argument was
// taken (or a Stop flag such as --help was met), else the first problem: a flag's own
// ("--seconds: expected seconds > 0, got 'x'"), "--seconds: needs a value", or
// "unexpected argument '--x'".
inline std::string ParseArgs(const flags::FlagSet& set, int argc, char** argv) {
  const std::vector<std::string> args(argv + (argc > 0 ? 1 : 0), argv + argc);
  std::string problem = set.Parse(args);
  // FlagSet::Parse begins this one with the context, which these tools leave empty.
  if (problem.rfind(": unexpected argument ", 0) == 0) problem.erase(0, 2);
  return problem;
}

}  // namespace stevi::bench
