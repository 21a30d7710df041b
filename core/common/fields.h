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

  // The field is a command-line flag of the servers: --NAME, by default the field's name with '-'
  // for '_' ("exposure_us" is --exposure-us). `metavar` names its value in the usage ("FILE");
  // by default "N" for a number, "VALUE" for text, the names for a choice, none for a bool.
  constexpr Field Flag(std::string_view name = {}, std::string_view metavar = {}) const {
    Field f = *this;
    f.has_flag_ = true;
    f.flag_ = name;
    f.metavar_ = metavar;
    return f;
  }
  // The field has no counterpart in the stevi.v1 messages (a driver's own setting, or one the
  // server fills from elsewhere): the proto mapping skips it, the checks and tables do not.
  constexpr Field NoProto() const {
    Field f = *this;
    f.no_proto_ = true;
    return f;
  }

  std::string_view name() const { return name_; }
  std::string_view unit() const { return unit_; }
  std::string_view doc() const { return doc_; }
  bool has_flag() const { return has_flag_; }
  // "exposure-us" (without the dashes in front); empty when the field is no flag.
  std::string flag() const;
  std::string_view metavar() const { return metavar_; }
  bool in_proto() const { return !no_proto_; }
  // The value accepted besides the bounds, and its meaning ("off", "max"), if any.
  std::optional<double> special() const { return special_; }
  std::string_view special_meaning() const { return special_meaning_; }

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
  bool has_flag_ = false;
  std::string_view flag_;
  std::string_view metavar_;
  bool no_proto_ = false;
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

namespace internal {

// Sets the one field at a dotted path from text (fields::Assign).
class Assigner {
 public:
  Assigner(std::string_view path, std::string_view text) : path_(path), text_(text) {}

  template <class T>
  void Number(T& value, const Field& f) {
    if (!Mine(f)) return;
    const std::optional<double> x = stevi::ParseNumber(text_);
    if (!x || !f.Accepts(*x)) return Fail(f, "must be " + f.Describe(true));
    using U = std::remove_cvref_t<decltype(Unwrap(value))>;
    if constexpr (std::is_integral_v<U>) {
      if (*x != std::floor(*x)) return Fail(f, "must be a whole number");
    }
    Unwrap(value) = static_cast<U>(*x);
  }
  template <class T>
  void List(std::vector<T>& values, const Field& f) {
    if (!Mine(f)) return;
    std::vector<T> parsed;
    std::string_view rest = text_;
    while (!rest.empty()) {
      const size_t comma = rest.find(',');
      const std::optional<double> x = stevi::ParseNumber(rest.substr(0, comma));
      if (!x || !f.Accepts(*x)) return Fail(f, "each must be " + f.Describe(true));
      parsed.push_back(static_cast<T>(*x));
      rest = comma == std::string_view::npos ? std::string_view{} : rest.substr(comma + 1);
    }
    if (parsed.empty()) return Fail(f, "must not be empty");
    values = std::move(parsed);
  }
  void Flag(bool& value, const Field& f) {
    if (!Mine(f)) return;
    if (text_ == "true" || text_ == "1") {
      value = true;
    } else if (text_ == "false" || text_ == "0") {
      value = false;
    } else {
      Fail(f, "must be true or false");
    }
  }
  void Text(std::string& value, const Field& f) {
    if (Mine(f)) value = std::string(text_);
  }
  template <class E, std::size_t N>
  void Choice(E& value, const Field& f, const ChoiceName<E> (&names)[N]) {
    if (!Mine(f)) return;
    std::string valid;
    for (const ChoiceName<E>& n : names) {
      if (n.name == text_) {
        value = n.value;
        return;
      }
      valid += (valid.empty() ? "" : ", ") + std::string(n.name);
    }
    Fail(f, "must be one of " + valid);
  }
  template <class T>
  void Nested(T& nested, const Field& f) {
    const std::string saved = prefix_;
    prefix_ += std::string(f.name()) + ".";
    if (path_.starts_with(prefix_)) Visit(nested, *this);
    prefix_ = saved;
  }

  bool found() const { return found_; }
  const std::optional<std::string>& problem() const { return problem_; }

 private:
  template <class T>
  static auto& Unwrap(T& value) {
    if constexpr (requires { value.emplace(); }) {
      if (!value) value.emplace();
      return *value;
    } else {
      return value;
    }
  }
  bool Mine(const Field& f) {
    if (found_ || path_ != prefix_ + std::string(f.name())) return false;
    found_ = true;
    return true;
  }
  void Fail(const Field&, const std::string& why) {
    problem_ = std::string(path_) + ": " + why + " (got '" + std::string(text_) + "')";
  }

  std::string_view path_, text_;
  std::string prefix_;
  bool found_ = false;
  std::optional<std::string> problem_;
};

}  // namespace internal

// Sets the field of `s` at the dotted path `path` ("stixels.segment_penalty") from `text`: a
// number within the field's bounds (whole for integer fields), true/false, a choice's name, a
// comma-separated list or a string. On any problem `s` is left as it was and the problem, naming
// the path, is returned. Checks between fields stay with the struct's Validate().
template <class S>
std::optional<std::string> Assign(S& s, std::string_view path, std::string_view text) {
  S copy = s;
  internal::Assigner assigner(path, text);
  Visit(copy, assigner);
  if (!assigner.found()) return std::string(path) + ": no such setting";
  if (assigner.problem()) return assigner.problem();
  s = std::move(copy);
  return std::nullopt;
}

// The rows as a Markdown table (path, default, unit, valid values, meaning).
std::string MarkdownTable(const std::vector<Row>& rows);
// `text` for a Markdown table's cell: each '|' escaped, or the cell would end there.
std::string MarkdownCell(const std::string& text);

}  // namespace stevi::fields
