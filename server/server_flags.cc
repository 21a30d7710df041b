#include "server/server_flags.h"

#include <google/protobuf/descriptor.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <type_traits>

#include "core/common/format.h"
#include "core/pipeline/config.h"
#include "drivers/aravis/aravis_source.h"
#include "drivers/gstreamer/gst_source.h"
#include "drivers/mcap/flight_log.h"
#include "drivers/recording/replay_source.h"
#include "server/app_config.h"
#include "server/field_mapping.h"
#include "server/server_options.h"

namespace stevi::server {
namespace {

using Kind = SettingFlag::Kind;

std::string Dashed(std::string_view name) {
  std::string out(name);
  for (char& c : out) {
    if (c == '_') c = '-';
  }
  return out;
}

// Walks a field list and gathers the fields marked Flag(), with their paths in ServerConfig.
class Collector {
 public:
  explicit Collector(std::vector<SettingFlag>& out) : out_(out) {}

  void Root(std::string prefix) { prefix_ = std::move(prefix); }

  template <class T>
  void Number(const T& value, const fields::Field& f) {
    if (!f.has_flag()) return;
    using U = std::remove_cvref_t<decltype(Unwrapped(value))>;
    std::string shown;  // an unset optional has no default: its meaning says what happens
    if constexpr (requires { value.has_value(); }) {
      if (value) shown = FormatNumber(static_cast<double>(*value));
    } else {
      shown = FormatNumber(static_cast<double>(value));
    }
    SettingFlag* pair = Partner(f);
    if (pair != nullptr) {  // the second number of "WxH"
      pair->kind = Kind::kPair;
      pair->paths.push_back(prefix_ + std::string(f.name()));
      pair->second = f;
      pair->default_value += "x" + shown;
      return;
    }
    SettingFlag& flag = Add(f, Kind::kNumber, "N");
    flag.whole = std::is_integral_v<U>;
    flag.default_value = shown;
  }
  template <class T>
  void List(const std::vector<T>&, const fields::Field&) {}
  void Flag(const bool&, const fields::Field& f) {
    if (f.has_flag()) Add(f, Kind::kSwitch, "");
  }
  void Text(const std::string& value, const fields::Field& f) {
    if (!f.has_flag()) return;
    if (SettingFlag* choice = Partner(f)) {  // the text after "CHOICE:"
      choice->kind = Kind::kChoiceAndText;
      choice->paths.push_back(prefix_ + std::string(f.name()));
      return;
    }
    Add(f, Kind::kText, "VALUE").default_value = value;
  }
  template <class E, std::size_t N>
  void Choice(const E& value, const fields::Field& f, const fields::ChoiceName<E> (&names)[N]) {
    if (!f.has_flag()) return;
    std::string metavar;
    std::vector<std::string> choices;
    for (const fields::ChoiceName<E>& n : names) {
      choices.push_back(Dashed(n.name));
      metavar += (metavar.empty() ? "" : "|") + choices.back();
    }
    SettingFlag& flag = Add(f, Kind::kChoice, metavar);
    flag.choices = std::move(choices);
    flag.default_value =
        Dashed(fields::NameOf(value, std::span<const fields::ChoiceName<E>>(names)).value_or(""));
  }
  template <class T>
  void Nested(const T& nested, const fields::Field& f) {
    const std::string saved = prefix_;
    prefix_ += std::string(f.name()) + ".";
    fields::Visit(nested, *this);
    prefix_ = saved;
  }

 private:
  template <class T>
  static const auto& Unwrapped(const T& value) {
    if constexpr (requires { value.has_value(); }) {
      return *value;
    } else {
      return value;
    }
  }
  // The flag this field shares its name with (the one just before it), if any.
  SettingFlag* Partner(const fields::Field& f) {
    if (out_.empty() || out_.back().flag != f.flag()) return nullptr;
    return &out_.back();
  }
  SettingFlag& Add(const fields::Field& f, Kind kind, std::string_view metavar) {
    SettingFlag flag;
    flag.flag = f.flag();
    flag.paths = {prefix_ + std::string(f.name())};
    flag.kind = kind;
    flag.metavar = std::string(f.metavar().empty() ? metavar : f.metavar());
    flag.field = f;
    out_.push_back(std::move(flag));
    return out_.back();
  }

  std::vector<SettingFlag>& out_;
  std::string prefix_;
};

template <class T>
void Collect(Collector& collector, const std::string& prefix, const T& options) {
  collector.Root(prefix);
  fields::Visit(options, collector);
}

std::vector<SettingFlag> CollectFlags() {
  std::vector<SettingFlag> out;
  Collector c(out);
  Collect(c, "", ServerOptions{});
  Collect(c, "source.aravis.", drivers::AravisOptions{});
  Collect(c, "source.gst.", drivers::GstOptions{});
  Collect(c, "source.replay.", drivers::ReplayOptions{});
  Collect(c, "record_mcap.", drivers::FlightLogOptions{});
  Collect(c, "pipeline.", pipeline::PipelineConfig{});
  return out;
}

// The message that holds the field at the dotted `path` of `config`, and the field (null, null
// when the path names none: a bug in a field list, which server_flags_test would catch).
std::pair<google::protobuf::Message*, const google::protobuf::FieldDescriptor*> Resolve(
    v1::ServerConfig& config, const std::string& path) {
  google::protobuf::Message* m = &config;
  size_t start = 0;
  while (true) {
    const size_t dot = path.find('.', start);
    const std::string name = path.substr(start, dot == std::string::npos ? dot : dot - start);
    const google::protobuf::FieldDescriptor* d = m->GetDescriptor()->FindFieldByName(name);
    if (d == nullptr) return {nullptr, nullptr};
    if (dot == std::string::npos) return {m, d};
    if (d->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_MESSAGE)
      return {nullptr, nullptr};
    m = m->GetReflection()->MutableMessage(m, d);
    start = dot + 1;
  }
}

std::string Problem(const SettingFlag& flag, const std::string& expected, const std::string& text) {
  return "--" + flag.flag + ": must be " + expected + " (got '" + text + "')";
}

// The number of `text` for the field: within its bounds (or its special word: "max"), whole for
// an integer field; "" and the value, or the problem.
std::string ParseFieldNumber(const SettingFlag& flag, const fields::Field& field,
                             const std::string& text, double& value) {
  if (field.special() && !field.special_meaning().empty() && text == field.special_meaning()) {
    value = *field.special();
    return "";
  }
  const std::optional<double> parsed = ParseNumber(text);
  std::string expected = field.Describe(true);
  if (expected.empty()) expected = "a number";
  if (flag.whole) expected += " (a whole number)";
  if (!parsed || !field.Accepts(*parsed) || (flag.whole && *parsed != std::floor(*parsed))) {
    return Problem(flag, expected, text);
  }
  value = *parsed;
  return "";
}

// The choice named by `text` ('-' or '_' between words; a first word alone when it is unique).
std::optional<std::string> FindChoice(const SettingFlag& flag, const std::string& text) {
  const std::string dashed = Dashed(text);
  std::optional<std::string> found;
  int matches = 0;
  for (const std::string& choice : flag.choices) {
    if (choice == dashed) return choice;
    if (choice.rfind(dashed + "-", 0) == 0) {
      found = choice;
      ++matches;
    }
  }
  return matches == 1 ? found : std::nullopt;
}

std::string SetNumberAt(v1::ServerConfig& config, const std::string& path, double value) {
  auto [m, d] = Resolve(config, path);
  if (m == nullptr) return "no config field " + path;
  field_mapping::SetNumber(*m, d, value);
  return "";
}

// What the flag accepts, in words: "in (0, 1000] Hz", "one of camera, host".
std::string Valid(const SettingFlag& flag) {
  if (flag.kind == Kind::kNumber || flag.kind == Kind::kPair) return flag.field.Describe(true);
  if (flag.kind != Kind::kChoice && flag.kind != Kind::kChoiceAndText) return "";
  std::string valid = "one of ";
  for (const std::string& c : flag.choices) valid += (c == flag.choices.front() ? "" : ", ") + c;
  if (flag.kind == Kind::kChoiceAndText) valid += "; CHOICE:TEXT also sets " + flag.paths.at(1);
  return valid;
}

std::string ApplyPair(const SettingFlag& flag, const std::string& text, v1::ServerConfig& config) {
  const size_t x = text.find('x');
  const std::string expected = "WIDTHxHEIGHT, each " + flag.field.Describe(true);
  if (x == std::string::npos) return Problem(flag, expected, text);
  double w = 0, h = 0;
  if (!ParseFieldNumber(flag, flag.field, text.substr(0, x), w).empty() ||
      !ParseFieldNumber(flag, flag.second, text.substr(x + 1), h).empty()) {
    return Problem(flag, expected, text);
  }
  std::string problem = SetNumberAt(config, flag.paths.at(0), w);
  if (problem.empty()) problem = SetNumberAt(config, flag.paths.at(1), h);
  return problem;
}

std::string ApplyChoice(const SettingFlag& flag, const std::string& text,
                        v1::ServerConfig& config) {
  const size_t colon = flag.kind == Kind::kChoiceAndText ? text.find(':') : std::string::npos;
  const std::string word = text.substr(0, colon);
  const std::optional<std::string> choice = FindChoice(flag, word);
  if (!choice || (colon != std::string::npos && colon + 1 == text.size())) {
    return Problem(flag, Valid(flag), text);
  }
  auto [m, d] = Resolve(config, flag.paths.front());
  if (m == nullptr) return "no config field " + flag.paths.front();
  std::string proto_name = *choice;
  for (char& c : proto_name) {
    if (c == '-') c = '_';
  }
  field_mapping::SetChoice(*m, d, proto_name);
  if (colon != std::string::npos) {
    auto [tm, td] = Resolve(config, flag.paths.at(1));
    if (tm == nullptr) return "no config field " + flag.paths.at(1);
    tm->GetReflection()->SetString(tm, td, text.substr(colon + 1));
  }
  return "";
}

}  // namespace

const std::vector<SettingFlag>& SettingFlags() {
  static const std::vector<SettingFlag> flags = CollectFlags();
  return flags;
}

std::string ApplySettingFlag(const SettingFlag& flag, const std::string& text,
                             v1::ServerConfig& config) {
  switch (flag.kind) {
    case Kind::kNumber: {
      double value = 0;
      if (std::string problem = ParseFieldNumber(flag, flag.field, text, value); !problem.empty()) {
        return problem;
      }
      return SetNumberAt(config, flag.paths.front(), value);
    }
    case Kind::kPair: return ApplyPair(flag, text, config);
    case Kind::kChoice:
    case Kind::kChoiceAndText: return ApplyChoice(flag, text, config);
    case Kind::kText:
    case Kind::kSwitch: {
      auto [m, d] = Resolve(config, flag.paths.front());
      if (m == nullptr) return "no config field " + flag.paths.front();
      if (flag.kind == Kind::kSwitch) {
        m->GetReflection()->SetBool(m, d, true);
      } else {
        m->GetReflection()->SetString(m, d, text);
      }
      return "";
    }
  }
  return "--" + flag.flag + ": unknown kind";
}

Status ApplySettingFlags(const std::vector<std::pair<const SettingFlag*, std::string>>& settings,
                         v1::ServerConfig& config) {
  v1::ServerConfig updated = config;
  std::vector<std::string> problems;
  for (const auto& [flag, text] : settings) {
    if (std::string problem = ApplySettingFlag(*flag, text, updated); !problem.empty()) {
      problems.push_back(std::move(problem));
    }
  }
  if (!problems.empty()) return InvalidArgument(problems);
  config = std::move(updated);
  return Status::Ok();
}

std::string FormatUsageLine(const std::string& head, const std::string& help) {
  // The text in a column from 26, wrapped at 100.
  constexpr size_t kColumn = 25, kWidth = 100;
  std::string out = head;
  if (head.size() >= kColumn) {
    out += "\n" + std::string(kColumn, ' ');
  } else {
    out += std::string(kColumn - head.size(), ' ');
  }
  size_t column = kColumn;
  size_t start = 0;
  while (start < help.size()) {
    size_t end = help.find(' ', start);
    if (end == std::string::npos) end = help.size();
    const std::string word = help.substr(start, end - start);
    if (column > kColumn && column + 1 + word.size() > kWidth) {
      out += "\n" + std::string(kColumn, ' ');
      column = kColumn;
    }
    if (column > kColumn) {
      out += ' ';
      ++column;
    }
    out += word;
    column += word.size();
    start = end + 1;
  }
  return out + "\n";
}

std::string UsageLine(const SettingFlag& flag) {
  std::string help(flag.field.doc());
  std::string notes = Valid(flag);
  if (!flag.default_value.empty() && flag.kind != Kind::kSwitch) {
    notes += (notes.empty() ? "" : "; ") + std::string("default ") + flag.default_value;
  }
  if (!notes.empty()) help += " (" + notes + ")";
  help += " [" + flag.paths.front() + (flag.paths.size() > 1 ? ", " + flag.paths[1] : "") + "]";
  return FormatUsageLine("  --" + flag.flag + (flag.metavar.empty() ? "" : " " + flag.metavar),
                         help);
}

ServerCommandLine::ServerCommandLine(std::string program,
                                     std::function<bool(const SettingFlag&)> accepts)
    : program_(std::move(program)), own_(program_) {
  own_.AllowEquals();
  own_.Text("--config", &config_file_);
  own_.Stop("--help", &help_);
  for (const SettingFlag& flag : SettingFlags()) {
    if (!accepts(flag)) continue;
    accepted_.push_back(&flag);
    const SettingFlag* p = &flag;
    if (flag.kind == Kind::kSwitch) {
      own_.Switch("--" + flag.flag, [this, p] { given_.emplace_back(p, "true"); });
    } else {
      own_.Value("--" + flag.flag, [this, p](const std::string& text) {
        given_.emplace_back(p, text);
        return std::string();
      });
    }
  }
}

void ServerCommandLine::Describe(const std::string& flag, const std::string& metavar,
                                 const std::string& help) {
  own_usage_ += FormatUsageLine("  --" + flag + (metavar.empty() ? "" : " " + metavar), help);
}

std::string ServerCommandLine::Parse(int argc, const char* const* argv) {
  std::vector<std::string> args(argv + std::min(argc, 1), argv + argc);
  given_.clear();
  return own_.Parse(args);
}

std::optional<int> ServerCommandLine::ParseOrExit(int argc, const char* const* argv,
                                                  const std::string& about) {
  if (const std::string problem = Parse(argc, argv); !problem.empty()) {
    std::cerr << problem << " (see --help)\n";
    return 2;
  }
  if (help_) {
    std::cout << Usage(about);
    return 0;
  }
  return std::nullopt;
}

bool ServerCommandLine::Given(std::string_view flag) const {
  return std::any_of(given_.begin(), given_.end(),
                     [flag](const auto& given) { return given.first->flag == flag; });
}

Result<v1::ServerConfig> ServerCommandLine::Config() const {
  v1::ServerConfig config;
  if (!config_file_.empty()) {
    Result<v1::ServerConfig> loaded = LoadServerConfig(config_file_);
    if (!loaded.ok()) return loaded.error();
    config = std::move(loaded).value();
  }
  if (Status applied = ApplyTo(config); !applied.ok()) return applied.error();
  return config;
}

Status ServerCommandLine::ApplyTo(v1::ServerConfig& config) const {
  return ApplySettingFlags(given_, config);
}

std::string ServerCommandLine::Usage(const std::string& about) const {
  std::string out = "usage: " + program_ + " [flags]\n\n" + about + "\n\n";
  out += FormatUsageLine("  --config FILE",
                         "stevi.v1.ServerConfig in protobuf text format or JSON; the flags "
                         "override it");
  out += own_usage_;
  for (const SettingFlag* flag : accepted_) out += UsageLine(*flag);
  out += FormatUsageLine("  --help", "this text");
  return out;
}

std::string FlagTableMarkdown() {
  std::string out = "| flag | config field | default | valid | meaning |\n|---|---|---|---|---|\n";
  for (const SettingFlag& flag : SettingFlags()) {
    std::string paths;
    for (const std::string& p : flag.paths) paths += (paths.empty() ? "" : ", ") + ("`" + p + "`");
    const std::string head = flag.flag + (flag.metavar.empty() ? "" : " " + flag.metavar);
    out += "| `--" + fields::MarkdownCell(head) + "` | " + paths + " | " + flag.default_value +
           " | " + fields::MarkdownCell(Valid(flag)) + " | " +
           fields::MarkdownCell(std::string(flag.field.doc())) + " |\n";
  }
  return out;
}

}  // namespace stevi::server
