#include "core/common/flags.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <set>
#include <string>
#include <vector>

namespace stevi::flags {
namespace {

using ::testing::ElementsAre;

constexpr RealRange kUnit{.lo = 0, .hi = 1, .unit = "a number"};
constexpr RealRange kTimeout{.lo = 0, .hi = 3600, .unit = "seconds", .lo_open = true};
constexpr WholeRange kCount{.lo = 1};
constexpr WholeRange kPairs{.lo = 1, .hi = 200, .what = "a whole number of pairs"};

NumberProblem RealProblem(const std::string& text, const RealRange& range = kUnit) {
  return ParseNumber(text, range).problem;
}

NumberProblem WholeProblem(const std::string& text, const WholeRange& range = kCount) {
  return ParseNumber(text, range).problem;
}

TEST(ParseNumber, TakesDecimalRealNumbers) {
  EXPECT_DOUBLE_EQ(ParseNumber("0.5", kUnit).value, 0.5);
  EXPECT_DOUBLE_EQ(ParseNumber(".5", kUnit).value, 0.5);
  EXPECT_DOUBLE_EQ(ParseNumber("+0.25", kUnit).value, 0.25);
  EXPECT_DOUBLE_EQ(ParseNumber("5e-1", kUnit).value, 0.5);
  EXPECT_DOUBLE_EQ(ParseNumber("1.", kUnit).value, 1);
  EXPECT_DOUBLE_EQ(ParseNumber("-120", {.lo = -120, .hi = 100, .unit = "metres"}).value, -120);
  EXPECT_DOUBLE_EQ(ParseNumber("1e3", {.lo = 0, .hi = 1e4, .unit = "m"}).value, 1000);
  EXPECT_TRUE(ParseNumber("0.5", kUnit).ok());
}

TEST(ParseNumber, MinusZeroIsZero) {
  const Parsed<double> zero = ParseNumber("-0", kUnit);
  ASSERT_TRUE(zero.ok());
  EXPECT_EQ(zero.value, 0);
  EXPECT_FALSE(std::signbit(zero.value));
  EXPECT_EQ(RealProblem("-0.0", kTimeout), NumberProblem::kOutOfRange) << "(0, 3600] has no zero";
}

TEST(ParseNumber, RealBoundsAreInclusiveUnlessOpen) {
  EXPECT_TRUE(ParseNumber("0", kUnit).ok());
  EXPECT_TRUE(ParseNumber("1", kUnit).ok());
  EXPECT_EQ(RealProblem("1.0000000001"), NumberProblem::kOutOfRange);
  EXPECT_EQ(RealProblem("-1e-300"), NumberProblem::kOutOfRange);
  EXPECT_EQ(RealProblem("0", kTimeout), NumberProblem::kOutOfRange);
  EXPECT_TRUE(ParseNumber("1e-300", kTimeout).ok());
  EXPECT_TRUE(ParseNumber("3600", kTimeout).ok());
  EXPECT_EQ(RealProblem("3600.001", kTimeout), NumberProblem::kOutOfRange);
  // The smallest double above the bound, written out in full, is taken; the largest below is not.
  const RealRange point1{.lo = 0.1, .hi = 10000, .unit = "metres"};
  EXPECT_TRUE(ParseNumber("0.1", point1).ok());
  EXPECT_TRUE(ParseNumber("0.10000000000000002", point1).ok());
  EXPECT_EQ(RealProblem("0.09999999999999999", point1), NumberProblem::kOutOfRange);
}

TEST(ParseNumber, RejectsWhatIsNotADecimalNumber) {
  for (const std::string text :
       {"", "-", "+", ".", "e5", "abc", " 1", "\t1", "+-1", "++1", "-+1", "x1", ",5"}) {
    EXPECT_EQ(RealProblem(text), NumberProblem::kNotANumber) << "'" << text << "'";
    EXPECT_EQ(WholeProblem(text), NumberProblem::kNotANumber) << "'" << text << "'";
  }
}

TEST(ParseNumber, RejectsTrailingCharacters) {
  for (const std::string text : {"1 ", "1x", "0.5s", "1,5", "0x1", "1e", "1e+", "1..2", "1-"}) {
    EXPECT_EQ(RealProblem(text), NumberProblem::kTrailing) << "'" << text << "'";
  }
  for (const std::string text : {"5 ", "5x", "0x10", "1.5", "2.0", "1e3", "3."}) {
    EXPECT_EQ(WholeProblem(text), NumberProblem::kTrailing) << "'" << text << "'";
  }
  EXPECT_EQ(RealProblem(std::string("0.5\0", 4)), NumberProblem::kTrailing) << "an embedded NUL";
}

TEST(ParseNumber, RejectsNanAndInfinity) {
  const RealRange everything{.lo = -std::numeric_limits<double>::infinity(),
                             .hi = std::numeric_limits<double>::infinity(),
                             .unit = "anything"};
  for (const std::string text :
       {"nan", "NaN", "-nan", "nan(1)", "inf", "-inf", "+inf", "INF", "infinity", "-Infinity"}) {
    EXPECT_EQ(RealProblem(text, everything), NumberProblem::kNotFinite) << text;
    EXPECT_EQ(WholeProblem(text), NumberProblem::kNotANumber) << text;
  }
}

TEST(ParseNumber, RejectsWhatTheTypeCannotHold) {
  const RealRange everything{.lo = -1e308, .hi = 1e308, .unit = "anything"};
  EXPECT_EQ(RealProblem("1e400", everything), NumberProblem::kOverflow);
  EXPECT_EQ(RealProblem("-1e400", everything), NumberProblem::kOverflow);
  EXPECT_EQ(RealProblem("1e-400", everything), NumberProblem::kOverflow) << "it would be 0";
  EXPECT_TRUE(ParseNumber("1e308", everything).ok());
  const WholeRange all{.lo = std::numeric_limits<std::int64_t>::min()};
  EXPECT_EQ(ParseNumber("9223372036854775807", all).value,
            std::numeric_limits<std::int64_t>::max());
  EXPECT_EQ(ParseNumber("-9223372036854775808", all).value,
            std::numeric_limits<std::int64_t>::min());
  EXPECT_EQ(WholeProblem("9223372036854775808", all), NumberProblem::kOverflow);
  EXPECT_EQ(WholeProblem("-9223372036854775809", all), NumberProblem::kOverflow);
  EXPECT_EQ(WholeProblem("99999999999999999999999", all), NumberProblem::kOverflow);
}

TEST(ParseNumber, TakesWholeNumbersWithinTheirRange) {
  EXPECT_EQ(ParseNumber("1", kCount).value, 1);
  EXPECT_EQ(ParseNumber("+7", kCount).value, 7);
  EXPECT_EQ(ParseNumber("007", kCount).value, 7);
  EXPECT_EQ(ParseNumber("200", kPairs).value, 200);
  EXPECT_EQ(WholeProblem("0"), NumberProblem::kOutOfRange);
  EXPECT_EQ(WholeProblem("-1"), NumberProblem::kOutOfRange);
  EXPECT_EQ(WholeProblem("-0"), NumberProblem::kOutOfRange);
  EXPECT_EQ(WholeProblem("201", kPairs), NumberProblem::kOutOfRange);
  EXPECT_EQ(ParseNumber("-3", WholeRange{.lo = -5, .hi = 5}).value, -3);
}

TEST(ParseNumberPair, ReadsColumnsAndRows) {
  const WholeRange corners{.lo = 2, .hi = 100};
  const auto board = ParseNumberPair("9x6", 'x', corners);
  ASSERT_TRUE(board.ok());
  EXPECT_EQ(board.value.first, 9);
  EXPECT_EQ(board.value.second, 6);
  EXPECT_TRUE(ParseNumberPair("2x100", 'x', corners).ok());
  EXPECT_EQ(ParseNumberPair("9", 'x', corners).problem, NumberProblem::kNotANumber);
  EXPECT_EQ(ParseNumberPair("9X6", 'x', corners).problem, NumberProblem::kNotANumber);
  EXPECT_EQ(ParseNumberPair("x6", 'x', corners).problem, NumberProblem::kNotANumber);
  EXPECT_EQ(ParseNumberPair("9x", 'x', corners).problem, NumberProblem::kNotANumber);
  EXPECT_EQ(ParseNumberPair("9x6x3", 'x', corners).problem, NumberProblem::kTrailing);
  EXPECT_EQ(ParseNumberPair("9 x6", 'x', corners).problem, NumberProblem::kTrailing);
  EXPECT_EQ(ParseNumberPair("1x6", 'x', corners).problem, NumberProblem::kOutOfRange);
  EXPECT_EQ(ParseNumberPair("9x101", 'x', corners).problem, NumberProblem::kOutOfRange);
  EXPECT_EQ(ParseNumberPair("1x6.5", 'x', corners).problem, NumberProblem::kOutOfRange)
      << "the first number's problem comes first";
}

TEST(NumberProblemName, NamesEachProblem) {
  std::set<std::string> names;
  for (const NumberProblem p :
       {NumberProblem::kNone, NumberProblem::kNotANumber, NumberProblem::kTrailing,
        NumberProblem::kNotFinite, NumberProblem::kOverflow, NumberProblem::kOutOfRange}) {
    names.insert(std::string(NumberProblemName(p)));
  }
  EXPECT_EQ(names.size(), 6u);
  EXPECT_EQ(NumberProblemName(NumberProblem::kTrailing), "trailing characters");
}

TEST(FormatNumber, WritesTheShortestFixedText) {
  EXPECT_EQ(FormatNumber(0), "0");
  EXPECT_EQ(FormatNumber(0.1), "0.1");
  EXPECT_EQ(FormatNumber(10000), "10000");
  EXPECT_EQ(FormatNumber(-120), "-120");
  EXPECT_EQ(FormatNumber(16e6), "16000000");
  EXPECT_EQ(FormatNumber(1e12), "1000000000000");
  EXPECT_EQ(FormatNumber(0.001), "0.001");
}

TEST(Describe, SaysTheRangeAsTheMessagesDo) {
  EXPECT_EQ(Describe(kUnit), "a number in [0, 1]");
  EXPECT_EQ(Describe(kTimeout), "seconds in (0, 3600]");
  EXPECT_EQ(Describe(RealRange{.lo = 0.1, .hi = 10000, .unit = "metres"}),
            "metres in [0.1, 10000]");
  EXPECT_EQ(Describe(RealRange{.lo = -120, .hi = 100, .unit = "metres"}), "metres in [-120, 100]");
  EXPECT_EQ(Describe(kCount), "a whole number >= 1");
  EXPECT_EQ(Describe(kPairs), "a whole number of pairs in 1..200");
  EXPECT_EQ(Describe(WholeRange{.lo = 1, .hi = 1000}), "a whole number in 1..1000");
}

TEST(Expected, NamesTheFlagAndTheValue) {
  EXPECT_EQ(Expected("watch", "--count", "a whole number >= 1", "x"),
            "watch --count: expected a whole number >= 1, got 'x'");
  EXPECT_EQ(Expected("", "--timeout", "seconds", "0"), "--timeout: expected seconds, got '0'");
  EXPECT_EQ(Expected("record start", "--name", "a name", ""),
            "record start --name: expected a name, got ''");
}

// The flags of `stevi watch`, as the command declares them.
struct Watch {
  bool json = false, confirmed = false;
  double min_score = -1;
  std::int64_t count = 0;

  std::string Parse(const std::vector<std::string>& args) {
    return FlagSet("watch")
        .Switch("--json", &json)
        .Switch("--confirmed", &confirmed)
        .Real("--min-score", kUnit, [this](double s) { min_score = s; })
        .Whole("--count", kCount, [this](std::int64_t n) { count = n; })
        .Parse(args);
  }
};

TEST(FlagSet, TakesSwitchesAndValuesInAnyOrder) {
  Watch w;
  EXPECT_EQ(w.Parse({"--count", "5", "--json", "--min-score", "0.5", "--confirmed"}), "");
  EXPECT_TRUE(w.json);
  EXPECT_TRUE(w.confirmed);
  EXPECT_EQ(w.count, 5);
  EXPECT_DOUBLE_EQ(w.min_score, 0.5);

  Watch none;
  EXPECT_EQ(none.Parse({}), "");
  EXPECT_FALSE(none.json);
  EXPECT_EQ(none.count, 0);
}

TEST(FlagSet, ALaterRepeatWins) {
  Watch w;
  EXPECT_EQ(w.Parse({"--count", "5", "--json", "--count", "7", "--json"}), "");
  EXPECT_EQ(w.count, 7);
}

TEST(FlagSet, NumberErrorsNameTheCommandTheFlagAndTheValue) {
  const std::string count = "watch --count: expected a whole number >= 1, got '";
  const std::string score = "watch --min-score: expected a number in [0, 1], got '";
  const struct {
    std::string flag, value, message;
  } cases[] = {{"--count", "0", count + "0'"},     {"--count", "2.5", count + "2.5'"},
               {"--min-score", "2", score + "2'"}, {"--min-score", "nan", score + "nan'"},
               {"--min-score", "", score + "'"},   {"--min-score", "0.5x", score + "0.5x'"}};
  for (const auto& c : cases) EXPECT_EQ(Watch().Parse({c.flag, c.value}), c.message);
}

TEST(FlagSet, AnythingElseIsAnUnexpectedArgument) {
  EXPECT_EQ(Watch().Parse({"--bogus"}), "watch: unexpected argument '--bogus'");
  EXPECT_EQ(Watch().Parse({"5"}), "watch: unexpected argument '5'");
  EXPECT_EQ(Watch().Parse({"--JSON"}), "watch: unexpected argument '--JSON'") << "case matters";
  EXPECT_EQ(Watch().Parse({"--count=5"}), "watch: unexpected argument '--count=5'");
  // A value flag without its value.
  EXPECT_EQ(Watch().Parse({"--json", "--count"}), "watch --count: needs a value");
}

TEST(FlagSet, TheFirstProblemIsReportedAndWhatCameBeforeItWasTaken) {
  Watch w;
  EXPECT_EQ(w.Parse({"--count", "3", "--count", "0", "--bogus"}),
            "watch --count: expected a whole number >= 1, got '0'");
  EXPECT_EQ(w.count, 3);
  EXPECT_EQ(Watch().Parse({"--bogus", "--count", "0"}), "watch: unexpected argument '--bogus'");
}

TEST(FlagSet, AValueMayLookLikeAFlag) {
  std::string name;
  bool json = false;
  FlagSet set("record start");
  set.Text("--name", &name).Switch("--json", &json);
  EXPECT_EQ(set.Parse({"--name", "--json"}), "");
  EXPECT_EQ(name, "--json");
  EXPECT_FALSE(json);
  EXPECT_EQ(set.Parse({"--name", ""}), "");
  EXPECT_EQ(name, "");
}

TEST(FlagSet, AValueHandlerGivesItsOwnMessage) {
  std::string format;
  FlagSet set("export");
  set.Value("--format", [&format](const std::string& v) {
    if (v != "kml" && v != "geojson") return Expected("export", "--format", "kml or geojson", v);
    format = v;
    return std::string();
  });
  EXPECT_EQ(set.Parse({"--format", "kml"}), "");
  EXPECT_EQ(format, "kml");
  EXPECT_EQ(set.Parse({"--format", "kmz"}), "export --format: expected kml or geojson, got 'kmz'");
  EXPECT_EQ(format, "kml");
}

TEST(FlagSet, ParseStartsAtFirst) {
  bool json = false;
  FlagSet set("record stop");
  set.Switch("--json", &json);
  EXPECT_EQ(set.Parse({"stop", "--json"}, 1), "");
  EXPECT_TRUE(json);
  EXPECT_EQ(set.Parse({"stop", "--json", "now"}, 1), "record stop: unexpected argument 'now'");
  EXPECT_EQ(set.Parse({"stop"}, 1), "");
  EXPECT_EQ(set.Parse({"stop"}, 5), "") << "nothing after the end";
}

// The options before the command, as `stevi` declares them.
struct Global {
  bool help = false;
  std::string server;
  double timeout_s = 0;
  std::size_t next = 0;

  std::string Parse(const std::vector<std::string>& args) {
    next = 0;
    return FlagSet("")
        .Stop("--help", &help)
        .Text("--server", &server)
        .Real("--timeout", kTimeout, [this](double s) { timeout_s = s; })
        .ParseLeading(args, next);
  }
};

TEST(FlagSetParseLeading, StopsAtTheCommand) {
  Global g;
  EXPECT_EQ(g.Parse({"--server", "h:1", "--timeout", "2.5", "watch", "--count", "3"}), "");
  EXPECT_EQ(g.server, "h:1");
  EXPECT_DOUBLE_EQ(g.timeout_s, 2.5);
  EXPECT_EQ(g.next, 4u);
  EXPECT_EQ(g.Parse({"status"}), "");
  EXPECT_EQ(g.next, 0u);
  EXPECT_EQ(g.Parse({"--server", "h:1"}), "");
  EXPECT_EQ(g.next, 2u) << "no command: next is the end";
  EXPECT_EQ(g.Parse({"-v", "status"}), "");
  EXPECT_EQ(g.next, 0u) << "one dash is not an option";
}

TEST(FlagSetParseLeading, UnknownOrIncompleteOptions) {
  EXPECT_EQ(Global().Parse({"--bogus", "status"}), "unknown option '--bogus'");
  EXPECT_EQ(Global().Parse({"--server"}), "--server: needs a value");
  EXPECT_EQ(Global().Parse({"--timeout", "0", "status"}),
            "--timeout: expected seconds in (0, 3600], got '0'");
  EXPECT_EQ(Global().Parse({"--timeout", "1e9", "status"}),
            "--timeout: expected seconds in (0, 3600], got '1e9'");
}

TEST(FlagSetParseLeading, AStopFlagEndsTheWalk) {
  Global g;
  EXPECT_EQ(g.Parse({"--server", "h:1", "--help", "--bogus"}), "");
  EXPECT_TRUE(g.help);
  EXPECT_EQ(g.next, 3u);
  Global late;
  EXPECT_EQ(late.Parse({"--bogus", "--help"}), "unknown option '--bogus'");
  EXPECT_FALSE(late.help);
  Global as_value;
  EXPECT_EQ(as_value.Parse({"--server", "--help"}), "");
  EXPECT_FALSE(as_value.help) << "--server took it as its value";
  EXPECT_EQ(as_value.server, "--help");
}

TEST(FlagSet, HandlersRunInOrder) {
  std::vector<std::string> seen;
  FlagSet set("t");
  set.Value("--a",
            [&seen](const std::string& v) {
              seen.push_back("a=" + v);
              return std::string();
            })
      .Whole("--n", {.lo = 0, .hi = 9},
             [&seen](std::int64_t n) { seen.push_back(std::to_string(n)); });
  EXPECT_EQ(set.Parse({"--n", "1", "--a", "x", "--n", "2"}), "");
  EXPECT_THAT(seen, ElementsAre("1", "a=x", "2"));
}

}  // namespace
}  // namespace stevi::flags
