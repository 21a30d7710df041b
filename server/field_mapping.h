// Core options structs to and from their stevi.v1 messages, by field name through protobuf
// reflection: each struct's field list (core/common/fields.h) names its proto fields, so no pair of
// fields is kept by hand. Fields marked NoProto() are skipped; any other field of the list that its
// message lacks is a bug: std::logic_error naming both (server/convert_test walks every field).
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include <google/protobuf/message.h>

#include "core/common/fields.h"

namespace stevi::server {
namespace field_mapping {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

// The field `f` of `m`'s type; throws std::logic_error when the message has none.
const FieldDescriptor* Find(const Message& m, const fields::Field& f);

void SetNumber(Message& m, const FieldDescriptor* d, double value);
void AddNumber(Message& m, const FieldDescriptor* d, double value);
// Sets the enum field to the value whose name ends in "_" + upper-case `choice`.
void SetChoice(Message& m, const FieldDescriptor* d, std::string_view choice);

double GetDouble(const Message& m, const FieldDescriptor* d, int index = -1);
// Integer fields; false when the value does not fit an int64 (a uint64 over 2^63).
bool GetInteger(const Message& m, const FieldDescriptor* d, int64_t& out, int index = -1);
// Whether the proto enum value `number` of `d` is named "<PREFIX>_" + upper-case `choice`.
bool ChoiceMatches(const FieldDescriptor* d, int number, std::string_view choice);

// Writes every field of the list (std::optional members only when they hold a value).
class Writer {
 public:
  explicit Writer(Message& m) : m_(m) {}

  template <class T>
  void Number(const T& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    if constexpr (requires { value.has_value(); }) {
      if (value) Number(*value, f);
    } else {
      SetNumber(m_, Find(m_, f), static_cast<double>(value));
    }
  }
  template <class T>
  void List(const std::vector<T>& values, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    m_.GetReflection()->ClearField(&m_, d);
    for (const T& v : values) AddNumber(m_, d, static_cast<double>(v));
  }
  void Flag(const bool& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    m_.GetReflection()->SetBool(&m_, Find(m_, f), value);
  }
  void Text(const std::string& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    m_.GetReflection()->SetString(&m_, Find(m_, f), value);
  }
  template <class E, std::size_t N>
  void Choice(const E& value, const fields::Field& f, const fields::ChoiceName<E> (&names)[N]) {
    if (!f.in_proto()) return;
    if (auto name = fields::NameOf(value, std::span<const fields::ChoiceName<E>>(names))) {
      SetChoice(m_, Find(m_, f), *name);
    }
  }
  template <class T>
  void Nested(const T& nested, const fields::Field& f) {
    if (!f.in_proto()) return;
    Writer sub(*m_.GetReflection()->MutableMessage(&m_, Find(m_, f)));
    fields::Visit(nested, sub);
  }

 private:
  Message& m_;
};

// Reads the fields that are set (an unset scalar, a zero enum, an empty list or an absent message
// keep the struct's value). Values the struct's type cannot hold, and enum values without a name,
// are problems named by their dotted path.
class Reader {
 public:
  Reader(const Message& m, std::string path, std::vector<std::string>& problems)
      : m_(m), path_(std::move(path)), problems_(problems) {}

  template <class T>
  void Number(T& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    if (!m_.GetReflection()->HasField(m_, d)) return;
    if constexpr (requires { value.has_value(); }) {
      typename T::value_type v{};
      if (Read(d, -1, f, v)) value = v;
    } else {
      T v{};
      if (Read(d, -1, f, v)) value = v;
    }
  }
  template <class T>
  void List(std::vector<T>& values, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    const int size = m_.GetReflection()->FieldSize(m_, d);
    if (size == 0) return;
    std::vector<T> read(size);
    for (int i = 0; i < size; ++i) {
      if (!Read(d, i, f, read[i])) return;
    }
    values = std::move(read);
  }
  void Flag(bool& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    if (m_.GetReflection()->HasField(m_, d)) value = m_.GetReflection()->GetBool(m_, d);
  }
  void Text(std::string& value, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    if (m_.GetReflection()->HasField(m_, d)) value = m_.GetReflection()->GetString(m_, d);
  }
  template <class E, std::size_t N>
  void Choice(E& value, const fields::Field& f, const fields::ChoiceName<E> (&names)[N]) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    const int number = m_.GetReflection()->GetEnumValue(m_, d);
    if (number == 0) return;  // *_UNSPECIFIED: keep
    for (const fields::ChoiceName<E>& n : names) {
      if (ChoiceMatches(d, number, n.name)) {
        value = n.value;
        return;
      }
    }
    problems_.push_back(path_ + std::string(f.name()) + ": unknown value " +
                        std::to_string(number));
  }
  template <class T>
  void Nested(T& nested, const fields::Field& f) {
    if (!f.in_proto()) return;
    const FieldDescriptor* d = Find(m_, f);
    if (!m_.GetReflection()->HasField(m_, d)) return;
    Reader sub(m_.GetReflection()->GetMessage(m_, d), path_ + std::string(f.name()) + ".",
               problems_);
    fields::Visit(nested, sub);
  }

 private:
  // One value of the field (index -1: a singular field) into `out`; false, with the problem
  // named, when the type cannot hold it.
  template <class T>
  bool Read(const FieldDescriptor* d, int index, const fields::Field& f, T& out) {
    if constexpr (std::is_floating_point_v<T>) {
      out = static_cast<T>(GetDouble(m_, d, index));
      return true;
    } else {
      int64_t v = 0;
      const bool fits = GetInteger(m_, d, v, index) &&
                        v >= static_cast<int64_t>(std::numeric_limits<T>::min()) &&
                        (v < 0 || static_cast<uint64_t>(v) <=
                                      static_cast<uint64_t>(std::numeric_limits<T>::max()));
      if (!fits) {
        problems_.push_back(path_ + std::string(f.name()) + ": out of range");
        return false;
      }
      out = static_cast<T>(v);
      return true;
    }
  }

  const Message& m_;
  std::string path_;
  std::vector<std::string>& problems_;
};

}  // namespace field_mapping

// Every field of `options`' list into `out`.
template <class T>
void FieldsToProto(const T& options, google::protobuf::Message& out) {
  field_mapping::Writer writer(out);
  fields::Visit(options, writer);
}

// The fields set in `in` onto `options`. Returns the problems the proto itself carries (an enum
// value without a name, a number the struct's type cannot hold), each naming its field; `options`
// is then partly updated and must be discarded. Range checks are the struct's Validate().
template <class T>
std::vector<std::string> FieldsFromProto(const google::protobuf::Message& in, T& options,
                                         std::string path = "") {
  std::vector<std::string> problems;
  field_mapping::Reader reader(in, std::move(path), problems);
  fields::Visit(options, reader);
  return problems;
}

}  // namespace stevi::server
