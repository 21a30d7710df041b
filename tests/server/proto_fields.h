// Walks the fields of a stevi.v1 message by reflection, for the tests that check that every field
// of a config arrives in the core options and back (server/convert_test, server/app_config_test).
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <gtest/gtest.h>

namespace stevi::server::proto_fields {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

// The leaf fields of a message type, as paths of field descriptors.
inline void Leaves(const google::protobuf::Descriptor* d,
                   std::vector<const FieldDescriptor*>& prefix,
                   std::vector<std::vector<const FieldDescriptor*>>& out) {
  for (int i = 0; i < d->field_count(); ++i) {
    const FieldDescriptor* f = d->field(i);
    prefix.push_back(f);
    if (f->type() == FieldDescriptor::TYPE_MESSAGE) {
      Leaves(f->message_type(), prefix, out);
    } else {
      out.push_back(prefix);
    }
    prefix.pop_back();
  }
}

inline std::string PathName(const std::vector<const FieldDescriptor*>& path) {
  std::string name;
  for (const FieldDescriptor* f : path) name += (name.empty() ? "" : ".") + f->name();
  return name;
}

// The message holding the path's last field (created on the way when `mutable_path`).
inline const Message& Holder(const Message& root, const std::vector<const FieldDescriptor*>& path) {
  const Message* m = &root;
  for (size_t i = 0; i + 1 < path.size(); ++i) m = &m->GetReflection()->GetMessage(*m, path[i]);
  return *m;
}
inline Message* MutableHolder(Message* root, const std::vector<const FieldDescriptor*>& path) {
  Message* m = root;
  for (size_t i = 0; i + 1 < path.size(); ++i) m = m->GetReflection()->MutableMessage(m, path[i]);
  return m;
}

inline double NumberOf(const Message& m, const FieldDescriptor* f) {
  const google::protobuf::Reflection* r = m.GetReflection();
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32: return r->GetInt32(m, f);
    case FieldDescriptor::CPPTYPE_UINT32: return r->GetUInt32(m, f);
    case FieldDescriptor::CPPTYPE_INT64: return static_cast<double>(r->GetInt64(m, f));
    case FieldDescriptor::CPPTYPE_UINT64: return static_cast<double>(r->GetUInt64(m, f));
    case FieldDescriptor::CPPTYPE_DOUBLE: return r->GetDouble(m, f);
    case FieldDescriptor::CPPTYPE_FLOAT: return r->GetFloat(m, f);
    case FieldDescriptor::CPPTYPE_BOOL: return r->GetBool(m, f) ? 1 : 0;
    case FieldDescriptor::CPPTYPE_ENUM: return r->GetEnumValue(m, f);
    default: return 0;
  }
}

inline void SetNumber(Message* m, const FieldDescriptor* f, double v) {
  const google::protobuf::Reflection* r = m->GetReflection();
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_INT32: r->SetInt32(m, f, static_cast<int32_t>(v)); break;
    case FieldDescriptor::CPPTYPE_UINT32: r->SetUInt32(m, f, static_cast<uint32_t>(v)); break;
    case FieldDescriptor::CPPTYPE_INT64: r->SetInt64(m, f, static_cast<int64_t>(v)); break;
    case FieldDescriptor::CPPTYPE_UINT64: r->SetUInt64(m, f, static_cast<uint64_t>(v)); break;
    case FieldDescriptor::CPPTYPE_DOUBLE: r->SetDouble(m, f, v); break;
    case FieldDescriptor::CPPTYPE_FLOAT: r->SetFloat(m, f, static_cast<float>(v)); break;
    case FieldDescriptor::CPPTYPE_BOOL: r->SetBool(m, f, v != 0); break;
    case FieldDescriptor::CPPTYPE_ENUM: r->SetEnumValue(m, f, static_cast<int>(v)); break;
    default: break;
  }
}

// Values other than `v` to try, nearest first.
inline std::vector<double> Candidates(const FieldDescriptor* f, double v) {
  std::vector<double> out;
  switch (f->cpp_type()) {
    case FieldDescriptor::CPPTYPE_BOOL: return {v != 0 ? 0.0 : 1.0};
    case FieldDescriptor::CPPTYPE_ENUM:
      for (int i = 0; i < f->enum_type()->value_count(); ++i) {
        const int number = f->enum_type()->value(i)->number();
        if (number != 0 && number != v) out.push_back(number);
      }
      return out;
    case FieldDescriptor::CPPTYPE_DOUBLE:
    case FieldDescriptor::CPPTYPE_FLOAT:
      out = {v * 1.1, v * 0.9, v + 0.1, v - 0.1, v + 1, v - 1, v * 2, v * 0.5, 0.5, 0.25, 0.05, 3};
      break;
    default:
      out = {v + 2, v + 1, v - 1, v - 2, v * 2, std::floor(v / 2), 1, 3};
      if (f->cpp_type() == FieldDescriptor::CPPTYPE_UINT32 ||
          f->cpp_type() == FieldDescriptor::CPPTYPE_UINT64) {
        std::erase_if(out, [](double c) { return c < 0; });
      }
      break;
  }
  std::erase_if(out, [v](double c) { return c == v; });
  return out;
}

// Paths of the fields of `m` that are not set: scalars without a value, enums left at 0, empty
// lists. Sub-messages are walked.
inline void UnsetFields(const google::protobuf::Message& m, const std::string& prefix,
                        std::vector<std::string>& unset) {
  const google::protobuf::Descriptor* d = m.GetDescriptor();
  const google::protobuf::Reflection* r = m.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const google::protobuf::FieldDescriptor* f = d->field(i);
    const std::string path = prefix + f->name();
    if (f->is_repeated()) {
      if (r->FieldSize(m, f) == 0) unset.push_back(path);
    } else if (f->type() == google::protobuf::FieldDescriptor::TYPE_MESSAGE) {
      UnsetFields(r->GetMessage(m, f), path + ".", unset);
    } else if (f->has_presence() ? !r->HasField(m, f)
                                 : (f->type() == google::protobuf::FieldDescriptor::TYPE_ENUM &&
                                    r->GetEnumValue(m, f) == 0)) {
      unset.push_back(path);
    }
  }
}

// Every scalar, enum and string leaf of M but the repeated ones and those named in `skip` (or
// under a message named there), set
// alone in an update to a value other than its default in `defaults`, must come back from
// `round_trip` (the core options written back to a message; nullopt when the value is invalid
// there, and the next candidate is tried). A leaf left out of a field list fails, by name.
// Returns the number of leaves checked.
template <class M>
int ExpectEveryLeafArrives(const M& defaults,
                           const std::function<std::optional<M>(const M&)>& round_trip,
                           const std::set<std::string>& skip = {},
                           const std::vector<std::string>& text_values = {"x"}) {
  std::vector<std::vector<const FieldDescriptor*>> leaves;
  std::vector<const FieldDescriptor*> prefix;
  Leaves(M::descriptor(), prefix, leaves);
  int checked = 0;
  for (const auto& path : leaves) {
    const std::string name = PathName(path);
    const FieldDescriptor* f = path.back();
    const bool skipped = std::any_of(skip.begin(), skip.end(), [&](const std::string& s) {
      return name == s || name.rfind(s + ".", 0) == 0;
    });
    if (f->is_repeated() || skipped) continue;
    ++checked;
    if (f->cpp_type() == FieldDescriptor::CPPTYPE_STRING) {
      bool arrived = false;
      for (const std::string& value : text_values) {
        M update;
        Message* holder = MutableHolder(&update, path);
        holder->GetReflection()->SetString(holder, f, value);
        const std::optional<M> back = round_trip(update);
        if (!back) continue;
        EXPECT_EQ(Holder(*back, path).GetReflection()->GetString(Holder(*back, path), f), value)
            << name;
        arrived = true;
        break;
      }
      EXPECT_TRUE(arrived) << name << ": no valid text among the candidates";
      continue;
    }
    const double before = NumberOf(Holder(defaults, path), f);
    bool arrived = false;
    std::string tried;
    for (const double value : Candidates(f, before)) {
      M update;
      SetNumber(MutableHolder(&update, path), f, value);
      const double sent = NumberOf(Holder(update, path), f);  // after the field's own type
      const std::optional<M> back = round_trip(update);
      if (!back) {
        tried += " " + std::to_string(sent);
        continue;  // not a valid value: try the next
      }
      const double got = NumberOf(Holder(*back, path), f);
      EXPECT_NEAR(got, sent, 1e-9 * std::max(1.0, std::abs(sent)))
          << name << ": set alone to " << sent << " (default " << before << "), the options have "
          << got;
      arrived = true;
      break;
    }
    EXPECT_TRUE(arrived) << name << ": no valid value other than the default " << before << " among"
                         << tried;
  }
  return checked;
}

}  // namespace stevi::server::proto_fields
