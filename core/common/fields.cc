#include "core/common/fields.h"

#include <cstdio>

namespace stevi::fields {

std::string Field::flag() const {
  if (!has_flag_) return "";
  std::string name(flag_.empty() ? name_ : flag_);
  for (char& c : name) {
    if (c == '_') c = '-';
  }
  return name;
}

bool Field::Accepts(double value) const {
  if (!std::isfinite(value)) return false;
  if (special_ && value == *special_) return true;
  if (min_open_ ? !(value > min_) : !(value >= min_)) return false;
  if (max_open_ ? !(value < max_) : !(value <= max_)) return false;
  if (odd_ && std::fmod(std::abs(value), 2.0) != 1.0) return false;
  if (multiple_of_ > 0 && (value <= 0 || std::fmod(value, multiple_of_) != 0.0)) return false;
  return true;
}

std::string Field::Describe(bool with_unit) const {
  using internal::FormatNumber;
  const bool has_min = std::isfinite(min_), has_max = std::isfinite(max_);
  std::string range;
  if (has_min && has_max) {
    range = std::string("in ") + (min_open_ ? "(" : "[") + FormatNumber(min_) + ", " +
            FormatNumber(max_) + (max_open_ ? ")" : "]");
  } else if (has_min) {
    range = std::string(min_open_ ? "> " : ">= ") + FormatNumber(min_);
  } else if (has_max) {
    range = std::string(max_open_ ? "< " : "<= ") + FormatNumber(max_);
  }
  if (!range.empty() && with_unit && !unit_.empty()) range += " " + std::string(unit_);
  std::string text = range;
  auto add = [&text](const std::string& part) { text += (text.empty() ? "" : " and ") + part; };
  if (odd_) add("odd");
  if (multiple_of_ > 0) add("a positive multiple of " + std::to_string(multiple_of_));
  if (special_) {
    std::string special = FormatNumber(*special_);
    if (!special_meaning_.empty()) special += " (" + std::string(special_meaning_) + ")";
    text = text.empty() ? special : special + " or " + text;
  }
  return text;
}

std::string Field::Problem(double value) const {
  return std::string(name_) + ": must be " + Describe(/*with_unit=*/true) + Got(value);
}

std::string MarkdownCell(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '|') out += '\\';
    out += c;
  }
  return out;
}

std::string MarkdownTable(const std::vector<Row>& rows) {
  std::string out = "| field | default | unit | valid | meaning |\n|---|---|---|---|---|\n";
  for (const Row& r : rows) {
    out += "| `" + r.path + "` | " + MarkdownCell(r.value) + " | " + MarkdownCell(r.unit) + " | " +
           MarkdownCell(r.valid) + " | " + MarkdownCell(r.doc) + " |\n";
  }
  return out;
}

}  // namespace stevi::fields
