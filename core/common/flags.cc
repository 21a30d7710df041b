#include "core/common/flags.h"

#include <charconv>
#include <cmath>
#include <system_error>
#include <type_traits>

namespace stevi::flags {
namespace {

// The one parser under both ranges: the whole of `text` as a T.
template <typename T>
NumberProblem ParseAs(std::string_view text, T& value) {
  // std::from_chars takes neither white space nor a leading '+'; "+5" is a number, "+-5" is not.
  if (!text.empty() && text.front() == '+') {
    text.remove_prefix(1);
    if (!text.empty() && text.front() == '-') return NumberProblem::kNotANumber;
  }
  const char* const end = text.data() + text.size();
  const std::from_chars_result r = std::from_chars(text.data(), end, value);
  if (r.ec == std::errc::invalid_argument) return NumberProblem::kNotANumber;
  if (r.ec == std::errc::result_out_of_range) return NumberProblem::kOverflow;
  if (r.ptr != end) return NumberProblem::kTrailing;
  if constexpr (std::is_floating_point_v<T>) {
    if (!std::isfinite(value)) return NumberProblem::kNotFinite;
    value += T(0);  // -0 becomes 0
  }
  return NumberProblem::kNone;
}

}  // namespace

std::string_view NumberProblemName(NumberProblem problem) {
  switch (problem) {
    case NumberProblem::kNone: return "none";
    case NumberProblem::kNotANumber: return "not a number";
    case NumberProblem::kTrailing: return "trailing characters";
    case NumberProblem::kNotFinite: return "not finite";
    case NumberProblem::kOverflow: return "beyond the number type";
    case NumberProblem::kOutOfRange: return "out of range";
  }
  return "unknown";
}

Parsed<double> ParseNumber(std::string_view text, const RealRange& range) {
  Parsed<double> out;
  out.problem = ParseAs(text, out.value);
  const bool above_lo = range.lo_open ? out.value > range.lo : out.value >= range.lo;
  if (out.ok() && !(above_lo && out.value <= range.hi)) out.problem = NumberProblem::kOutOfRange;
  return out;
}

Parsed<std::int64_t> ParseNumber(std::string_view text, const WholeRange& range) {
  Parsed<std::int64_t> out;
  out.problem = ParseAs(text, out.value);
  if (out.ok() && (out.value < range.lo || out.value > range.hi)) {
    out.problem = NumberProblem::kOutOfRange;
  }
  return out;
}

Parsed<std::pair<std::int64_t, std::int64_t>> ParseNumberPair(std::string_view text, char separator,
                                                              const WholeRange& range) {
  Parsed<std::pair<std::int64_t, std::int64_t>> out;
  const std::size_t at = text.find(separator);
  if (at == std::string_view::npos) {
    out.problem = NumberProblem::kNotANumber;
    return out;
  }
  const Parsed<std::int64_t> first = ParseNumber(text.substr(0, at), range);
  const Parsed<std::int64_t> second = ParseNumber(text.substr(at + 1), range);
  out.value = {first.value, second.value};
  out.problem = first.ok() ? second.problem : first.problem;
  return out;
}

std::string FormatNumber(double value) {
  // The shortest round trip in fixed notation: 309 integer digits at most, a sign, the fraction.
  char buffer[400];
  const std::to_chars_result r =
      std::to_chars(buffer, buffer + sizeof(buffer), value, std::chars_format::fixed);
  return std::string(buffer, r.ptr);
}

std::string Describe(const RealRange& range) {
  return std::string(range.unit) + " in " + (range.lo_open ? "(" : "[") + FormatNumber(range.lo) +
         ", " + FormatNumber(range.hi) + "]";
}

std::string Describe(const WholeRange& range) {
  if (range.hi == std::numeric_limits<std::int64_t>::max()) {
    return std::string(range.what) + " >= " + std::to_string(range.lo);
  }
  return std::string(range.what) + " in " + std::to_string(range.lo) + ".." +
         std::to_string(range.hi);
}

std::string Expected(std::string_view context, std::string_view flag, std::string_view expected,
                     std::string_view value) {
  std::string out(context);
  if (!out.empty()) out += ' ';
  out.append(flag).append(": expected ").append(expected).append(", got '");
  out.append(value).append("'");
  return out;
}

namespace {

// A Value handler that parses a number within `range` and hands it to `take`.
template <typename Range, typename T>
std::function<std::string(const std::string&)> NumberTaker(std::string context, std::string name,
                                                           Range range,
                                                           std::function<void(T)> take) {
  return [context = std::move(context), name = std::move(name), range,
          take = std::move(take)](const std::string& text) {
    const auto number = ParseNumber(text, range);
    if (!number.ok()) return Expected(context, name, Describe(range), text);
    take(number.value);
    return std::string();
  };
}

// A handler for a flag alone: sets *on.
std::function<std::string(const std::string&)> SetTrue(bool* on) {
  return [on](const std::string&) {
    *on = true;
    return std::string();
  };
}

}  // namespace

FlagSet::FlagSet(std::string context) : context_(std::move(context)) {}

FlagSet& FlagSet::Add(Flag flag) {
  flags_.push_back(std::move(flag));
  return *this;
}

FlagSet& FlagSet::Switch(std::string name, bool* on) {
  return Add({std::move(name), false, false, SetTrue(on)});
}

FlagSet& FlagSet::Switch(std::string name, std::function<void()> on) {
  return Add({std::move(name), false, false, [on = std::move(on)](const std::string&) {
                on();
                return std::string();
              }});
}

FlagSet& FlagSet::AllowEquals() {
  allow_equals_ = true;
  return *this;
}

FlagSet& FlagSet::Stop(std::string name, bool* seen) {
  return Add({std::move(name), false, true, SetTrue(seen)});
}

FlagSet& FlagSet::Value(std::string name, std::function<std::string(const std::string&)> take) {
  return Add({std::move(name), true, false, std::move(take)});
}

FlagSet& FlagSet::Text(std::string name, std::string* value) {
  return Value(std::move(name), [value](const std::string& text) {
    *value = text;
    return std::string();
  });
}

FlagSet& FlagSet::Real(std::string name, const RealRange& range, std::function<void(double)> take) {
  return Value(name, NumberTaker(context_, name, range, std::move(take)));
}

FlagSet& FlagSet::Whole(std::string name, const WholeRange& range,
                        std::function<void(std::int64_t)> take) {
  return Value(name, NumberTaker(context_, name, range, std::move(take)));
}

std::string FlagSet::Parse(const std::vector<std::string>& args, std::size_t first) const {
  return Walk(args, first, /*leading=*/false);
}

std::string FlagSet::ParseLeading(const std::vector<std::string>& args, std::size_t& next) const {
  return Walk(args, next, /*leading=*/true);
}

const FlagSet::Flag* FlagSet::Find(const std::string& arg,
                                   std::optional<std::string>& inline_value) const {
  inline_value.reset();
  std::string name = arg;
  const std::size_t eq = arg.find('=');
  if (allow_equals_ && arg.rfind("--", 0) == 0 && eq != std::string::npos) {
    name = arg.substr(0, eq);
    inline_value = arg.substr(eq + 1);
  }
  const Flag* flag = nullptr;
  for (const Flag& f : flags_) {
    if (f.name == name) flag = &f;
  }
  if (flag != nullptr && inline_value && !flag->takes_value) return nullptr;
  return flag;
}

std::string FlagSet::Walk(const std::vector<std::string>& args, std::size_t& next,
                          bool leading) const {
  for (; next < args.size(); ++next) {
    const std::string& arg = args[next];
    if (leading && arg.rfind("--", 0) != 0) return "";
    std::optional<std::string> inline_value;
    const Flag* flag = Find(arg, inline_value);
    if (flag == nullptr) {
      if (leading) return "unknown option '" + arg + "'";
      return context_ + ": unexpected argument '" + arg + "'";
    }
    if (flag->takes_value && !inline_value && next + 1 >= args.size()) {
      return (context_.empty() ? "" : context_ + " ") + arg + ": needs a value";
    }
    const std::string value =
        inline_value ? *inline_value : (flag->takes_value ? args[++next] : arg);
    const std::string problem = flag->take(value);
    if (!problem.empty()) return problem;
    if (flag->stops) {
      ++next;
      return "";
    }
  }
  return "";
}

}  // namespace stevi::flags
