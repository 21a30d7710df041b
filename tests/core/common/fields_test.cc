// The field lists of core/common/fields.h: bounds, their words, checks of a struct with a nested
// one, and the option table.
#include "core/common/fields.h"

#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace stevi::fields {
namespace {

using ::testing::ElementsAre;
using ::testing::IsEmpty;

TEST(Field, ClosedOpenAndOneSidedBounds) {
  const Field closed = Field("n").In(1, 3);
  EXPECT_TRUE(closed.Accepts(1));
  EXPECT_TRUE(closed.Accepts(3));
  EXPECT_FALSE(closed.Accepts(0.999));
  EXPECT_FALSE(closed.Accepts(3.001));
  const Field half_open = Field("f").Above(0).AtMost(1);
  EXPECT_FALSE(half_open.Accepts(0));
  EXPECT_TRUE(half_open.Accepts(1e-9));
  EXPECT_TRUE(half_open.Accepts(1));
  EXPECT_EQ(half_open.Describe(), "in (0, 1]");
  EXPECT_EQ(Field("x").Below(5).Describe(), "< 5");
  EXPECT_EQ(Field("x").AtLeast(-1).Describe(), ">= -1");
  EXPECT_EQ(Field("x").Describe(), "");
  EXPECT_TRUE(Field("x").Accepts(-1e300));
}

TEST(Field, NanAndInfinityAreNeverValid) {
  EXPECT_FALSE(Field("x").Accepts(std::nan("")));
  EXPECT_FALSE(Field("x").Accepts(std::numeric_limits<double>::infinity()));
  EXPECT_FALSE(Field("x").AtLeast(0).Accepts(std::numeric_limits<double>::infinity()));
  EXPECT_FALSE(Field("x").Or(0, "off").Accepts(std::nan("")));
}

TEST(Field, OddMultipleAndSpecialValue) {
  const Field odd = Field("k", "pixels").Odd().In(1, 9);
  EXPECT_TRUE(odd.Accepts(1));
  EXPECT_TRUE(odd.Accepts(9));
  EXPECT_FALSE(odd.Accepts(4));
  EXPECT_FALSE(odd.Accepts(11));
  EXPECT_EQ(odd.Problem(4), "k: must be in [1, 9] pixels and odd (got 4)");

  const Field step = Field("d").MultipleOf(16).AtMost(64);
  EXPECT_TRUE(step.Accepts(16));
  EXPECT_TRUE(step.Accepts(64));
  EXPECT_FALSE(step.Accepts(0));  // positive multiples only
  EXPECT_FALSE(step.Accepts(-16));
  EXPECT_FALSE(step.Accepts(24));
  EXPECT_FALSE(step.Accepts(80));

  const Field special = Field("w").In(64, 16384).Or(0, "never");
  EXPECT_TRUE(special.Accepts(0));
  EXPECT_TRUE(special.Accepts(64));
  EXPECT_FALSE(special.Accepts(63));
  EXPECT_EQ(special.Problem(63), "w: must be 0 (never) or in [64, 16384] (got 63)");
}

enum class Colour { kRed, kGreen };

struct Inner {
  double gain = 0.5;
  std::vector<std::string> Validate() const { return Check(*this); }
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Number(s.gain, Field("gain", "dB", "the gain").In(0, 1));
  }
};

struct Outer {
  int count = 3;
  bool on = true;
  std::optional<double> limit;
  std::vector<int> levels = {1, 2};
  Colour colour = Colour::kGreen;
  std::string label = "a";
  Inner inner;

  static constexpr ChoiceName<Colour> kColours[] = {{Colour::kRed, "red"},
                                                    {Colour::kGreen, "green"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    v.Number(s.count, Field("count", "", "how many").In(1, 10));
    v.Flag(s.on, Field("on", "", "switch"));
    v.Number(s.limit, Field("limit", "m", "upper bound").Above(0));
    v.List(s.levels, Field("levels", "", "pyramid levels").In(0, 8));
    v.Choice(s.colour, Field("colour", "", "paint"), kColours);
    v.Text(s.label, Field("label", "", "a name"));
    v.Nested(s.inner, Field("inner"));
  }
};

TEST(Check, DefaultsAreValid) { EXPECT_THAT(Check(Outer{}), IsEmpty()); }

TEST(Check, NamesEveryBadField) {
  Outer o;
  o.count = 0;
  o.limit = -1;
  o.levels = {1, 9};
  o.colour = static_cast<Colour>(7);
  o.inner.gain = 2;
  EXPECT_THAT(Check(o),
              ElementsAre("count: must be in [1, 10] (got 0)", "limit: must be > 0 m (got -1)",
                          "levels: must be in [0, 8] (got 9)", "colour: unknown value 7",
                          "inner.gain: must be in [0, 1] dB (got 2)"));
  o = Outer{};
  o.levels.clear();
  EXPECT_THAT(Check(o), ElementsAre("levels: must not be empty"));
  o = Outer{};
  o.limit.reset();  // unset optionals are not checked
  EXPECT_THAT(Check(o), IsEmpty());
}

TEST(Table, OneRowPerLeafWithDottedPaths) {
  const std::vector<Row> rows = Table(Outer{});
  ASSERT_EQ(rows.size(), 7u);
  EXPECT_EQ(rows[0].path, "count");
  EXPECT_EQ(rows[0].value, "3");
  EXPECT_EQ(rows[0].valid, "in [1, 10]");
  EXPECT_EQ(rows[2].value, "unset");
  EXPECT_EQ(rows[3].value, "1 2");
  EXPECT_EQ(rows[3].valid, "each in [0, 8]");
  EXPECT_EQ(rows[4].value, "green");
  EXPECT_EQ(rows[4].valid, "red, green");
  EXPECT_EQ(rows[6].path, "inner.gain");
  EXPECT_EQ(rows[6].unit, "dB");
  EXPECT_EQ(MarkdownTable({rows[6]}),
            "| field | default | unit | valid | meaning |\n|---|---|---|---|---|\n"
            "| `inner.gain` | 0.5 | dB | in [0, 1] | the gain |\n");
}

TEST(Assign, SetsEachKindOfFieldByItsDottedPath) {
  Outer o;
  EXPECT_EQ(Assign(o, "count", "7"), std::nullopt);
  EXPECT_EQ(Assign(o, "on", "false"), std::nullopt);
  EXPECT_EQ(Assign(o, "limit", "2.5"), std::nullopt);
  EXPECT_EQ(Assign(o, "levels", "0,4,8"), std::nullopt);
  EXPECT_EQ(Assign(o, "colour", "red"), std::nullopt);
  EXPECT_EQ(Assign(o, "label", "b c"), std::nullopt);
  EXPECT_EQ(Assign(o, "inner.gain", "0.25"), std::nullopt);
  EXPECT_EQ(o.count, 7);
  EXPECT_FALSE(o.on);
  EXPECT_EQ(o.limit, 2.5);
  EXPECT_THAT(o.levels, ElementsAre(0, 4, 8));
  EXPECT_EQ(o.colour, Colour::kRed);
  EXPECT_EQ(o.label, "b c");
  EXPECT_EQ(o.inner.gain, 0.25);
}

TEST(Assign, RefusesBadTextAndLeavesTheStructAsItWas) {
  Outer o;
  EXPECT_EQ(Assign(o, "count", "11"), "count: must be in [1, 10] (got '11')");
  EXPECT_EQ(Assign(o, "count", "2.5"), "count: must be a whole number (got '2.5')");
  EXPECT_EQ(Assign(o, "count", "3x"), "count: must be in [1, 10] (got '3x')");
  EXPECT_EQ(Assign(o, "inner.gain", "nan"), "inner.gain: must be in [0, 1] dB (got 'nan')");
  EXPECT_EQ(Assign(o, "on", "yes"), "on: must be true or false (got 'yes')");
  EXPECT_EQ(Assign(o, "colour", "blue"), "colour: must be one of red, green (got 'blue')");
  EXPECT_EQ(Assign(o, "levels", "1,,2"), "levels: each must be in [0, 8] (got '1,,2')");
  EXPECT_EQ(Assign(o, "inner", "1"), "inner: no such setting");
  EXPECT_EQ(Assign(o, "inner.gainx", "1"), "inner.gainx: no such setting");
  EXPECT_EQ(Assign(o, "", "1"), ": no such setting");
  const Outer fresh;
  EXPECT_EQ(o.count, fresh.count);
  EXPECT_EQ(o.inner.gain, fresh.inner.gain);
  EXPECT_THAT(o.levels, ElementsAre(1, 2));
}

}  // namespace
}  // namespace stevi::fields
