// A strict RFC 8259 JSON parser for tests of the client's JSON output: it rejects what a real
// consumer would (NaN, trailing commas, raw control characters, duplicate keys, trailing text) and
// gives back a tree to check the structure with.
#pragma once

#include <charconv>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace stevi::client::testing {

struct Json {
  enum class Kind { kNull, kBool, kNumber, kString, kArray, kObject };
  Kind kind = Kind::kNull;
  bool boolean = false;
  double number = 0;
  std::string string;
  std::vector<Json> items;                            // kArray
  std::vector<std::pair<std::string, Json>> members;  // kObject, in document order

  // The member `key` of an object, or null when absent (or not an object).
  const Json* Find(std::string_view key) const {
    for (const auto& [k, v] : members) {
      if (k == key) return &v;
    }
    return nullptr;
  }
  std::vector<std::string> Keys() const {
    std::vector<std::string> keys;
    for (const auto& member : members) keys.push_back(member.first);
    return keys;
  }
};

class JsonParser {
 public:
  // The value of the whole `text`, or nullopt with `error` saying where and what.
  static std::optional<Json> Parse(std::string_view text, std::string* error = nullptr) {
    JsonParser p(text);
    std::optional<Json> value = p.Value(0);
    if (value) {
      p.SkipSpace();
      if (p.pos_ != text.size()) value = p.Fail("trailing text");
    }
    if (!value && error != nullptr) *error = p.error_;
    return value;
  }

 private:
  explicit JsonParser(std::string_view text) : s_(text) {}

  std::nullopt_t Fail(const std::string& what) {
    if (error_.empty()) error_ = what + " at offset " + std::to_string(pos_);
    return std::nullopt;
  }

  void SkipSpace() {
    while (pos_ < s_.size() &&
           (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\n' || s_[pos_] == '\r')) {
      ++pos_;
    }
  }

  bool Eat(std::string_view token) {
    if (s_.substr(pos_, token.size()) != token) return false;
    pos_ += token.size();
    return true;
  }

  std::optional<Json> Value(int depth) {
    if (depth > 64) return Fail("nesting too deep");
    SkipSpace();
    if (pos_ >= s_.size()) return Fail("unexpected end");
    Json v;
    const char c = s_[pos_];
    if (c == '{') return Object(depth);
    if (c == '[') return Array(depth);
    if (c == '"') {
      std::optional<std::string> str = String();
      if (!str) return std::nullopt;
      v.kind = Json::Kind::kString;
      v.string = std::move(*str);
      return v;
    }
    if (Eat("true")) {
      v.kind = Json::Kind::kBool;
      v.boolean = true;
      return v;
    }
    if (Eat("false")) {
      v.kind = Json::Kind::kBool;
      return v;
    }
    if (Eat("null")) return v;
    return Number();
  }

  std::optional<Json> Number() {
    const std::size_t start = pos_;
    auto digits = [&] {
      const std::size_t from = pos_;
      while (pos_ < s_.size() && s_[pos_] >= '0' && s_[pos_] <= '9') ++pos_;
      return pos_ > from;
    };
    if (pos_ < s_.size() && s_[pos_] == '-') ++pos_;
    if (pos_ < s_.size() && s_[pos_] == '0') {
      ++pos_;
    } else if (!digits()) {
      return Fail("expected a value");
    }
    if (pos_ < s_.size() && s_[pos_] == '.') {
      ++pos_;
      if (!digits()) return Fail("expected digits after the point");
    }
    if (pos_ < s_.size() && (s_[pos_] == 'e' || s_[pos_] == 'E')) {
      ++pos_;
      if (pos_ < s_.size() && (s_[pos_] == '+' || s_[pos_] == '-')) ++pos_;
      if (!digits()) return Fail("expected exponent digits");
    }
    Json v;
    v.kind = Json::Kind::kNumber;
    const std::from_chars_result r = std::from_chars(s_.data() + start, s_.data() + pos_, v.number);
    if (r.ec != std::errc() || r.ptr != s_.data() + pos_) return Fail("bad number");
    return v;
  }

  std::optional<std::string> String() {
    ++pos_;  // the opening quote
    std::string out;
    while (pos_ < s_.size()) {
      const char c = s_[pos_++];
      if (c == '"') return out;
      if (static_cast<unsigned char>(c) < 0x20) return Fail("raw control character in a string");
      if (c != '\\') {
        out += c;
        continue;
      }
      if (pos_ >= s_.size()) break;
      const char e = s_[pos_++];
      switch (e) {
        case '"': out += '"'; break;
        case '\\': out += '\\'; break;
        case '/': out += '/'; break;
        case 'b': out += '\b'; break;
        case 'f': out += '\f'; break;
        case 'n': out += '\n'; break;
        case 'r': out += '\r'; break;
        case 't': out += '\t'; break;
        case 'u': {
          unsigned code = 0;
          if (pos_ + 4 > s_.size()) return Fail("short \\u escape");
          const std::from_chars_result r =
              std::from_chars(s_.data() + pos_, s_.data() + pos_ + 4, code, 16);
          if (r.ptr != s_.data() + pos_ + 4) return Fail("bad \\u escape");
          pos_ += 4;
          if (code >= 0x80) return Fail("non-ASCII \\u escape (not needed by these tests)");
          out += static_cast<char>(code);
          break;
        }
        default: return Fail("bad escape");
      }
    }
    return Fail("unterminated string");
  }

  // The elements of an array or an object, separated by commas up to `close`; `element` reads one
  // into the container, or returns nullopt when it fails (having said why).
  template <class Element>
  std::optional<Json> Elements(Json::Kind kind, std::string_view close, Element element) {
    ++pos_;  // the opening bracket
    Json v;
    v.kind = kind;
    SkipSpace();
    if (Eat(close)) return v;
    while (true) {
      if (!element(v).has_value()) return std::nullopt;
      SkipSpace();
      if (Eat(close)) return v;
      if (!Eat(",")) return Fail("expected , or " + std::string(close));
    }
  }

  std::optional<Json> Array(int depth) {
    return Elements(Json::Kind::kArray, "]", [&](Json& v) -> std::optional<bool> {
      std::optional<Json> item = Value(depth + 1);
      if (!item) return std::nullopt;
      v.items.push_back(std::move(*item));
      return true;
    });
  }

  std::optional<Json> Object(int depth) {
    return Elements(Json::Kind::kObject, "}", [&](Json& v) -> std::optional<bool> {
      SkipSpace();
      if (pos_ >= s_.size() || s_[pos_] != '"') return Fail("expected a key");
      std::optional<std::string> key = String();
      if (!key) return std::nullopt;
      if (v.Find(*key) != nullptr) return Fail("duplicate key " + *key);
      SkipSpace();
      if (!Eat(":")) return Fail("expected :");
      std::optional<Json> value = Value(depth + 1);
      if (!value) return std::nullopt;
      v.members.emplace_back(std::move(*key), std::move(*value));
      return true;
    });
  }

  std::string_view s_;
  std::size_t pos_ = 0;
  std::string error_;
};

}  // namespace stevi::client::testing
