// One field list per options struct: each field declared once, with its name, unit, valid values
// and a line of meaning; its default is the member's initialiser. From that list come the struct's
// validation (fields::Check), the mapping to and from the stevi.v1 protos by field name
// (server/field_mapping.h, through protobuf reflection) and the README's option table
// (fields::Table). core/common/README.md shows how to add a parameter.
//
// A struct takes part by declaring
//
//   template <class Self, class V>
//   static void Fields(Self& s, V& v) {
//     v.Number(s.block_size, fields::Field("block_size", "pixels", "SAD window").In(5, 255).Odd());
//     v.Flag(s.pad_left, fields::Field("pad_left", "", "match the leftmost columns too"));
//     v.Choice(s.kind, fields::Field("kind"), kKindNames);
//     v.Nested(s.ground, fields::Field("ground"));
//   }
//
// where Self is the struct or the const struct, and V a visitor with those four members plus List
// (a vector of numbers, each within the field's bounds) and Text (a string).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/common/error.h"
#include "core/common/format.h"

namespace stevi::fields {

// A field's name, unit, meaning and valid values. Numbers must be finite and lie within [min, max]
// (each end open or closed), be odd or a multiple of some step when asked, or equal one special
// value that is accepted besides ("0 = off").
class Field {
 public:
  // `unit` ("pixels", "m/s", "percent") and `doc` (a line of meaning) go into the option table.
  constexpr explicit Field(std::string_view name, std::string_view unit = {},
                           std::string_view doc = {})
      : name_(name), unit_(unit), doc_(doc) {}

  // Closed interval [lo, hi].
  constexpr Field In(double lo, double hi) const { return AtLeast(lo).AtMost(hi); }
  constexpr Field AtLeast(double lo) const { return WithMin(lo, false); }
  constexpr Field Above(double lo) const { return WithMin(lo, true); }
  constexpr Field AtMost(double hi) const { return WithMax(hi, false); }
  constexpr Field Below(double hi) const { return WithMax(hi, true); }
  constexpr Field Odd() const {
    Field f = *this;
    f.odd_ = true;
    return f;
  }
  constexpr Field MultipleOf(int step) const {
    Field f = *this;
    f.multiple_of_ = step;
    return f;
  }
  // `value` is accepted besides the bounds; `meaning` says what it does ("off", "automatic").
  constexpr Field Or(double value, std::string_view meaning) const {
    Field f = *this;
    f.special_ = value;
    f.special_meaning_ = meaning;
    return f;
  }

  std::string_view name() const { return name_; }
  std::string_view unit() const { return unit_; }
  std::string_view doc() const { return doc_; }

  // Whether `value` is valid (NaN and infinities never are).
  bool Accepts(double value) const;
  // The valid values in words: "in [5, 255] and odd", "> 0", "0 (off) or in [2, 1000]"; empty
  // when any number is valid. `with_unit` puts the unit after the range ("in [5, 255] pixels").
  std::string Describe(bool with_unit = false) const;
  // "NAME: must be DESCRIPTION[ UNIT] (got VALUE)".
  std::string Problem(double value) const;

 private:
  constexpr Field WithMin(double lo, bool open) const {
    Field f = *this;
    f.min_ = lo;
    f.min_open_ = open;
    return f;
  }
  constexpr Field WithMax(double hi, bool open) const {
    Field f = *this;
    f.max_ = hi;
    f.max_open_ = open;
    return f;
  }

  std::string_view name_;
  std::string_view unit_;
  std::string_view doc_;
  double min_ = -std::numeric_limits<double>::infinity();
  double max_ = std::numeric_limits<double>::infinity();
  bool min_open_ = false;
  bool max_open_ = false;
  bool odd_ = false;
  int multiple_of_ = 0;
  std::optional<double> special_;
  std::string_view special_meaning_;
};

// One value of an enum and its name: lower case, the proto value's name without the enum's prefix
// ("three_way" is SEMI_GLOBAL_MODE_THREE_WAY).
template <class E>
struct ChoiceName {
  E value;
  std::string_view name;
};

template <class E>
std::optional<std::string_view> NameOf(E value, std::span<const ChoiceName<E>> names) {
  for (const ChoiceName<E>& n : names) {
    if (n.value == value) return n.name;
  }
  return std::nullopt;
}

// Visits the fields of `s` (const or not) with `v`.
template <class S, class V>
void Visit(S& s, V& v) {
  std::remove_const_t<S>::Fields(s, v);
}

namespace internal {

using stevi::FormatNumber;

template <class T>
double AsDouble(const T& value) {
  return static_cast<double>(value);
}

// The checks of fields::Check: bounds of numbers and list entries, known enum values, and each
// nested struct's own Validate() under "name.".
class Checker {
 public:
  template <class T>
  void Number(const T& value, const Field& f) {
    if constexpr (requires { value.has_value(); }) {
      if (value) Number(*value, f);
    } else if (!f.Accepts(AsDouble(value))) {
      problems.push_back(f.Problem(AsDouble(value)));
    }
  }
  template <class T>
  void List(const std::vector<T>& values, const Field& f) {
    if (values.empty()) problems.push_back(std::string(f.name()) + ": must not be empty");
    for (const T& v : values) {
      if (!f.Accepts(AsDouble(v))) problems.push_back(f.Problem(AsDouble(v)));
    }
  }
  void Flag(const bool&, const Field&) {}
  void Text(const std::string&, const Field&) {}
  template <class E, std::size_t N>
  void Choice(const E& value, const Field& f, const ChoiceName<E> (&names)[N]) {
    if (!NameOf(value, std::span<const ChoiceName<E>>(names))) {
      problems.push_back(std::string(f.name()) + ": unknown value " +
                         std::to_string(static_cast<int>(value)));
    }
  }
  template <class T>
  void Nested(const T& nested, const Field& f) {
    AppendPrefixed(problems, std::string(f.name()) + ".", nested.Validate());
  }

  std::vector<std::string> problems;
};

}  // namespace internal

// Every problem of the fields of `s`, each naming its field: numbers out of their bounds, enum
// values without a name, nested structs' problems (their Validate()) prefixed "name.".
// Checks between fields stay in the struct's Validate().
template <class S>
std::vector<std::string> Check(const S& s) {
  internal::Checker checker;
  Visit(s, checker);
  return std::move(checker.problems);
}

// One row of the option table: the field's dotted path, its default (as the struct holds it), unit,
// valid values and meaning.
struct Row {
  std::string path, value, unit, valid, doc;
};

namespace internal {

class Tabler {
 public:
  template <class T>
  void Number(const T& value, const Field& f) {
    if constexpr (requires { value.has_value(); }) {
      Add(f, value ? FormatNumber(AsDouble(*value)) : "unset");
    } else {
      Add(f, FormatNumber(AsDouble(value)));
    }
  }
  template <class T>
  void List(const std::vector<T>& values, const Field& f) {
    std::string text;
    for (const T& v : values) text += (text.empty() ? "" : " ") + FormatNumber(AsDouble(v));
    Add(f, text, "each " + f.Describe());
  }
  void Flag(const bool& value, const Field& f) { Add(f, value ? "true" : "false", ""); }
  void Text(const std::string& value, const Field& f) { Add(f, "\"" + value + "\"", ""); }
  template <class E, std::size_t N>
  void Choice(const E& value, const Field& f, const ChoiceName<E> (&names)[N]) {
    std::string valid;
    for (const ChoiceName<E>& n : names) valid += (valid.empty() ? "" : ", ") + std::string(n.name);
    Add(f, std::string(NameOf(value, std::span<const ChoiceName<E>>(names)).value_or("?")), valid);
  }
  template <class T>
  void Nested(const T& nested, const Field& f) {
    const std::string saved = prefix;
    prefix += std::string(f.name()) + ".";
    Visit(nested, *this);
    prefix = saved;
  }

  std::string prefix;
  std::vector<Row> rows;

 private:
  void Add(const Field& f, std::string value) { Add(f, std::move(value), f.Describe()); }
  void Add(const Field& f, std::string value, std::string valid) {
    rows.push_back(Row{prefix + std::string(f.name()), std::move(value), std::string(f.unit()),
                       std::move(valid), std::string(f.doc())});
  }
};

}  // namespace internal

// The option table of `s`, one row per leaf field, nested structs flattened into dotted paths.
template <class S>
std::vector<Row> Table(const S& s) {
  internal::Tabler tabler;
  Visit(s, tabler);
  return std::move(tabler.rows);
}

// The rows as a Markdown table (path, default, unit, valid values, meaning).
std::string MarkdownTable(const std::vector<Row>& rows);

}  // namespace stevi::fields
