#include "client/lib/config_edit.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/text_format.h>

#include <algorithm>
#include <cctype>
#include <sstream>

namespace stevi::client {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::EnumDescriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

std::string Upper(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::toupper(c); });
  return s;
}

std::string FieldNames(const Descriptor& d) {
  std::string out;
  for (int i = 0; i < d.field_count(); ++i) {
    if (!out.empty()) out += ", ";
    out += d.field(i)->name();
  }
  return out;
}

std::string EnumNames(const EnumDescriptor& e) {
  std::string out;
  for (int i = 0; i < e.value_count(); ++i) {
    if (e.value(i)->number() == 0) continue;
    if (!out.empty()) out += ", ";
    out += e.value(i)->name();
  }
  return out;
}

}  // namespace

std::string SetFieldByPath(Message& message, const std::string& path, const std::string& value) {
  Message* current = &message;
  std::stringstream parts(path);
  std::string part, walked;
  const FieldDescriptor* field = nullptr;
  while (std::getline(parts, part, '.')) {
    if (field != nullptr) {
      if (field->type() != FieldDescriptor::TYPE_MESSAGE) {
        return walked + ": is a value, it has no field '" + part + "'";
      }
      current = current->GetReflection()->MutableMessage(current, field);
    }
    const Descriptor* d = current->GetDescriptor();
    field = d->FindFieldByName(part);
    walked += (walked.empty() ? "" : ".") + part;
    if (field == nullptr) {
      return walked + ": unknown field (valid here: " + FieldNames(*d) + ")";
    }
    if (field->is_repeated()) return walked + ": repeated fields cannot be set this way";
  }
  if (field == nullptr) return "empty key";
  if (field->type() == FieldDescriptor::TYPE_MESSAGE) {
    return walked + ": is a group of settings (fields: " + FieldNames(*field->message_type()) + ")";
  }
  const google::protobuf::Reflection* reflection = current->GetReflection();
  if (field->type() == FieldDescriptor::TYPE_ENUM) {
    const EnumDescriptor* e = field->enum_type();
    const std::string wanted = Upper(value);
    for (int i = 0; i < e->value_count(); ++i) {
      const std::string& name = e->value(i)->name();
      const bool suffix = name.size() > wanted.size() &&
                          name.compare(name.size() - wanted.size(), wanted.size(), wanted) == 0 &&
                          name[name.size() - wanted.size() - 1] == '_';
      if (e->value(i)->number() != 0 && (name == wanted || suffix)) {
        reflection->SetEnum(current, field, e->value(i));
        return "";
      }
    }
    return walked + ": unknown value '" + value + "' (one of " + EnumNames(*e) + ")";
  }
  if (!google::protobuf::TextFormat::ParseFieldValueFromString(value, field, current)) {
    return walked + ": '" + value + "' is not a valid " + field->type_name();
  }
  return "";
}

}  // namespace stevi::client
