#include "server/field_mapping.h"

#include <cctype>
#include <stdexcept>

#include <google/protobuf/descriptor.h>

namespace stevi::server::field_mapping {
namespace {

using google::protobuf::Reflection;

std::string Upper(std::string_view text) {
  std::string out(text);
  for (char& c : out) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

bool EndsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

[[noreturn]] void Unsupported(const FieldDescriptor* d) {
  throw std::logic_error("field_mapping: " + d->full_name() + " is not a number field");
}

}  // namespace

const FieldDescriptor* Find(const Message& m, const fields::Field& f) {
  const FieldDescriptor* d = m.GetDescriptor()->FindFieldByName(std::string(f.name()));
  if (d == nullptr) {
    throw std::logic_error("field_mapping: " + m.GetDescriptor()->full_name() + " has no field " +
                           std::string(f.name()));
  }
  return d;
}

void SetNumber(Message& m, const FieldDescriptor* d, double value) {
  const Reflection* r = m.GetReflection();
  switch (d->cpp_type()) {
    case FieldDescriptor::CPPTYPE_DOUBLE: r->SetDouble(&m, d, value); break;
    case FieldDescriptor::CPPTYPE_FLOAT: r->SetFloat(&m, d, static_cast<float>(value)); break;
    case FieldDescriptor::CPPTYPE_INT32: r->SetInt32(&m, d, static_cast<int32_t>(value)); break;
    case FieldDescriptor::CPPTYPE_INT64: r->SetInt64(&m, d, static_cast<int64_t>(value)); break;
    case FieldDescriptor::CPPTYPE_UINT32: r->SetUInt32(&m, d, static_cast<uint32_t>(value)); break;
    case FieldDescriptor::CPPTYPE_UINT64: r->SetUInt64(&m, d, static_cast<uint64_t>(value)); break;
    default: Unsupported(d);
  }
}

void AddNumber(Message& m, const FieldDescriptor* d, double value) {
  const Reflection* r = m.GetReflection();
  switch (d->cpp_type()) {
    case FieldDescriptor::CPPTYPE_DOUBLE: r->AddDouble(&m, d, value); break;
    case FieldDescriptor::CPPTYPE_FLOAT: r->AddFloat(&m, d, static_cast<float>(value)); break;
    case FieldDescriptor::CPPTYPE_INT32: r->AddInt32(&m, d, static_cast<int32_t>(value)); break;
    case FieldDescriptor::CPPTYPE_INT64: r->AddInt64(&m, d, static_cast<int64_t>(value)); break;
    case FieldDescriptor::CPPTYPE_UINT32: r->AddUInt32(&m, d, static_cast<uint32_t>(value)); break;
    case FieldDescriptor::CPPTYPE_UINT64: r->AddUInt64(&m, d, static_cast<uint64_t>(value)); break;
    default: Unsupported(d);
  }
}

void SetChoice(Message& m, const FieldDescriptor* d, std::string_view choice) {
  const std::string suffix = "_" + Upper(choice);
  const google::protobuf::EnumDescriptor* e = d->enum_type();
  if (e == nullptr) Unsupported(d);
  for (int i = 0; i < e->value_count(); ++i) {
    if (EndsWith(e->value(i)->name(), suffix)) {
      m.GetReflection()->SetEnumValue(&m, d, e->value(i)->number());
      return;
    }
  }
  throw std::logic_error("field_mapping: " + e->full_name() + " has no value *" + suffix);
}

double GetDouble(const Message& m, const FieldDescriptor* d, int index) {
  const Reflection* r = m.GetReflection();
  const bool one = index < 0;
  switch (d->cpp_type()) {
    case FieldDescriptor::CPPTYPE_DOUBLE:
      return one ? r->GetDouble(m, d) : r->GetRepeatedDouble(m, d, index);
    case FieldDescriptor::CPPTYPE_FLOAT:
      return one ? r->GetFloat(m, d) : r->GetRepeatedFloat(m, d, index);
    case FieldDescriptor::CPPTYPE_UINT64:
      return static_cast<double>(one ? r->GetUInt64(m, d) : r->GetRepeatedUInt64(m, d, index));
    default: {
      int64_t v = 0;
      GetInteger(m, d, v, index);
      return static_cast<double>(v);
    }
  }
}

bool GetInteger(const Message& m, const FieldDescriptor* d, int64_t& out, int index) {
  const Reflection* r = m.GetReflection();
  const bool one = index < 0;
  switch (d->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32:
      out = one ? r->GetInt32(m, d) : r->GetRepeatedInt32(m, d, index);
      return true;
    case FieldDescriptor::CPPTYPE_INT64:
      out = one ? r->GetInt64(m, d) : r->GetRepeatedInt64(m, d, index);
      return true;
    case FieldDescriptor::CPPTYPE_UINT32:
      out = one ? r->GetUInt32(m, d) : r->GetRepeatedUInt32(m, d, index);
      return true;
    case FieldDescriptor::CPPTYPE_UINT64: {
      const uint64_t v = one ? r->GetUInt64(m, d) : r->GetRepeatedUInt64(m, d, index);
      if (v > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) return false;
      out = static_cast<int64_t>(v);
      return true;
    }
    default: Unsupported(d);
  }
}

bool ChoiceMatches(const FieldDescriptor* d, int number, std::string_view choice) {
  const google::protobuf::EnumValueDescriptor* v = d->enum_type()->FindValueByNumber(number);
  return v != nullptr && EndsWith(v->name(), "_" + Upper(choice));
}

}  // namespace stevi::server::field_mapping
