// The `stevi` tool's flags: one number parser (whole and real numbers, each within a range) and a
// small flag set that walks a command's arguments. The standard library only.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stevi::flags {

// The real numbers a flag accepts: [lo, hi], or (lo, hi] with lo_open. `unit` names them in the
// error message: "metres" gives "metres in [0.1, 10000]".
struct RealRange {
  double lo = 0;
  double hi = 0;
  std::string_view unit;
  bool lo_open = false;
};

// The whole numbers a flag accepts: lo..hi. `what` names them in the error message: "a whole
// number in 1..1000", or "a whole number >= 1" when hi is left at the largest value.
struct WholeRange {
  std::int64_t lo = 0;
  std::int64_t hi = std::numeric_limits<std::int64_t>::max();
  std::string_view what = "a whole number";
};

// Why a text is not an accepted number.
enum class NumberProblem {
  kNone,
  kNotANumber,  // empty, a sign alone, leading white space, letters
  kTrailing,   // a number with more after it: "5x", "1 ", "0x10"; "1.5" or "1e3" for a whole number
  kNotFinite,  // nan, inf, infinity (no flag takes them)
  kOverflow,   // beyond what the type holds: 2^63, "1e400", or "1e-400" (which would be 0)
  kOutOfRange,  // a number, outside the flag's range
};

// "not a number", "trailing characters", ...
std::string_view NumberProblemName(NumberProblem problem);

template <typename T>
struct Parsed {
  T value{};
  NumberProblem problem = NumberProblem::kNone;

  bool ok() const { return problem == NumberProblem::kNone; }
};

// The one number parser. Takes decimal text as a whole: an optional sign, digits, and for a real
// number a fraction and an exponent ("-1.5e3"); no white space, no hexadecimal. Locale-independent.
// A real -0 becomes 0.
Parsed<double> ParseNumber(std::string_view text, const RealRange& range);
Parsed<std::int64_t> ParseNumber(std::string_view text, const WholeRange& range);

// Two whole numbers with a separator, each in `range`: "9x6" with 'x'. The first one's problem
// when both have one; kNotANumber when the separator is missing.
Parsed<std::pair<std::int64_t, std::int64_t>> ParseNumberPair(std::string_view text, char separator,
                                                              const WholeRange& range);

// The shortest decimal text that reads back as `value`, never in exponent form: 0.1, 10000, -120.
std::string FormatNumber(double value);

// What a range accepts, as error messages say it: "metres in [0.1, 10000]", "seconds in (0, 3600]",
// "a whole number of pairs in 1..200", "a whole number >= 1".
std::string Describe(const RealRange& range);
std::string Describe(const WholeRange& range);

// "CONTEXT FLAG: expected EXPECTED, got 'VALUE'"; "FLAG: ..." when the context is empty.
std::string Expected(std::string_view context, std::string_view flag, std::string_view expected,
                     std::string_view value);

// A command's flags, declared once, then walked over its arguments in order (a later repeat of a
// flag wins). The handlers run as their flag is met, so the first problem is the one reported.
class FlagSet {
 public:
  // `context` begins the error messages: "watch", "record start"; "" for the global options.
  explicit FlagSet(std::string context);

  // A flag alone.
  FlagSet& Switch(std::string name, bool* on);
  FlagSet& Switch(std::string name, std::function<void()> on);
  // Also take "--name=value" for a flag with a value (the servers' spelling besides
  // "--name value").
  FlagSet& AllowEquals();
  // A flag alone that ends the walk where it stands (--help): *seen becomes true.
  FlagSet& Stop(std::string name, bool* seen);
  // A flag with the next argument as its value. `take` returns "" when it accepts the value, else
  // the whole error message.
  FlagSet& Value(std::string name, std::function<std::string(const std::string&)> take);
  // A value taken as it is.
  FlagSet& Text(std::string name, std::string* value);
  // A number within `range`; otherwise "CONTEXT NAME: expected <Describe(range)>, got 'VALUE'".
  FlagSet& Real(std::string name, const RealRange& range, std::function<void(double)> take);
  FlagSet& Whole(std::string name, const WholeRange& range, std::function<void(std::int64_t)> take);

  // Every argument from `first` on must be one of these flags (with its value). Returns "" when
  // all were taken, else the first problem: a handler's, "CONTEXT FLAG: needs a value" for a
  // value flag at the end, or "CONTEXT: unexpected argument 'X'" for anything else.
  std::string Parse(const std::vector<std::string>& args, std::size_t first = 0) const;

  // The options before a command: takes arguments from `next` on while they begin with "--" (or
  // until a Stop flag) and leaves `next` at the first one not taken. An unknown one: "unknown
  // option 'X'"; a value flag without its value: "FLAG: needs a value".
  std::string ParseLeading(const std::vector<std::string>& args, std::size_t& next) const;

 private:
  struct Flag {
    std::string name;
    bool takes_value = false;
    bool stops = false;
    std::function<std::string(const std::string&)> take;
  };

  FlagSet& Add(Flag flag);
  std::string Walk(const std::vector<std::string>& args, std::size_t& next, bool leading) const;

  // The flag named by `arg`, with the value of "--name=value" in `inline_value` (AllowEquals).
  const Flag* Find(const std::string& arg, std::optional<std::string>& inline_value) const;

  std::string context_;
  std::vector<Flag> flags_;
  bool allow_equals_ = false;
};

}  // namespace stevi::flags
