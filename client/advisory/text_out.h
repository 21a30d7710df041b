// Small text writers shared by the advisory JSON and the trajectory exports: locale-independent
// number formatting and JSON/XML string escaping.
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

namespace stevi::client::text {

// Appends `value` with exactly `decimals` digits after the point ("12.50"), whatever the C locale
// (printf would write "12,50" under some). Negative zero is written without its sign. A non-finite
// value is written as "null", JSON's only way to say "no number".
inline void AppendFixed(std::string& out, double value, int decimals) {
  if (!std::isfinite(value)) {
    out += "null";
    return;
  }
  // 309 integer digits for the largest double, a sign, a point and the decimals.
  char buffer[400];
  std::to_chars_result r =
      std::to_chars(buffer, buffer + sizeof(buffer), value, std::chars_format::fixed, decimals);
  std::string_view s(buffer, static_cast<std::size_t>(r.ptr - buffer));
  // -0.0 or a small negative rounded to zero ("-0.00"): drop the sign.
  if (!s.empty() && s.front() == '-' && s.find_first_not_of("-0.") == std::string_view::npos) {
    s.remove_prefix(1);
  }
  out += s;
}

inline void AppendInt(std::string& out, std::int64_t value) {
  char buffer[24];
  std::to_chars_result r = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out.append(buffer, r.ptr);
}

inline void AppendUint(std::string& out, std::uint64_t value) {
  char buffer[24];
  std::to_chars_result r = std::to_chars(buffer, buffer + sizeof(buffer), value);
  out.append(buffer, r.ptr);
}

// Appends `s` as a quoted JSON string (RFC 8259): quote, backslash and control characters are
// escaped; other bytes, UTF-8 included, pass through.
inline void AppendJsonString(std::string& out, std::string_view s) {
  static constexpr char kHex[] = "0123456789abcdef";
  out += '"';
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    switch (c) {
      case '"': out += "\\\""; break;
      case '\\': out += "\\\\"; break;
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      case '\b': out += "\\b"; break;
      case '\f': out += "\\f"; break;
      default:
        if (u < 0x20) {
          out += "\\u00";
          out += kHex[u >> 4];
          out += kHex[u & 0xf];
        } else {
          out += c;
        }
    }
  }
  out += '"';
}

// Appends `s` as XML character data or an attribute value: & < > " ' become entities. Control
// characters other than tab, newline and carriage return are not allowed in XML 1.0 at all, so
// they are replaced by a space.
inline void AppendXmlEscaped(std::string& out, std::string_view s) {
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += (u < 0x20 && c != '\t' && c != '\n' && c != '\r') ? ' ' : c;
    }
  }
}

}  // namespace stevi::client::text
