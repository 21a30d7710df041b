// The servers' settings are declared once, in field lists: every declared server setting has its
// proto field, its flag and its README row, and each flag sets exactly the field it names. A
// setting added to server/server_options.h without its proto field, or without regenerating the
// README's table, fails here.
#include "server/server_flags.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <set>

#include <google/protobuf/descriptor.h>

#include "server/app_config.h"
#include "server/field_mapping.h"
#include "server/runtime/source_factory.h"
#include "server/server_options.h"
#include "tests/testing/readme_section.h"
#include "tests/testing/status_matchers.h"

namespace stevi::server {
namespace {

using stevi::testing::IsError;
using stevi::testing::IsOk;
using ::testing::HasSubstr;

// Every leaf field of a list, with its dotted path.
struct Leaves {
  std::string prefix;
  std::vector<std::pair<std::string, fields::Field>> found;

  template <class T>
  void Number(const T&, const fields::Field& f) {
    Add(f);
  }
  template <class T>
  void List(const std::vector<T>&, const fields::Field& f) {
    Add(f);
  }
  void Flag(const bool&, const fields::Field& f) { Add(f); }
  void Text(const std::string&, const fields::Field& f) { Add(f); }
  template <class E, std::size_t N>
  void Choice(const E&, const fields::Field& f, const fields::ChoiceName<E> (&)[N]) {
    Add(f);
  }
  template <class T>
  void Nested(const T& nested, const fields::Field& f) {
    const std::string saved = prefix;
    prefix += std::string(f.name()) + ".";
    fields::Visit(nested, *this);
    prefix = saved;
  }
  void Add(const fields::Field& f) { found.emplace_back(prefix + std::string(f.name()), f); }
};

// The proto field at a dotted path of ServerConfig, or null.
const google::protobuf::FieldDescriptor* ProtoField(const std::string& path) {
  const google::protobuf::Descriptor* message = v1::ServerConfig::descriptor();
  size_t start = 0;
  while (message != nullptr) {
    const size_t dot = path.find('.', start);
    const google::protobuf::FieldDescriptor* d =
        message->FindFieldByName(path.substr(start, dot == std::string::npos ? dot : dot - start));
    if (d == nullptr || dot == std::string::npos) return d;
    message = d->message_type();
    start = dot + 1;
  }
  return nullptr;
}

bool IsSet(const v1::ServerConfig& config, const std::string& path) {
  const google::protobuf::Message* m = &config;
  size_t start = 0;
  while (true) {
    const size_t dot = path.find('.', start);
    const google::protobuf::FieldDescriptor* d = m->GetDescriptor()->FindFieldByName(
        path.substr(start, dot == std::string::npos ? dot : dot - start));
    if (d == nullptr || !m->GetReflection()->HasField(*m, d)) return false;
    if (dot == std::string::npos) return true;
    m = &m->GetReflection()->GetMessage(*m, d);
    start = dot + 1;
  }
}

TEST(ServerSettings, EveryDeclaredSettingHasItsProtoFieldAndItsFlag) {
  Leaves leaves;
  const ServerOptions defaults;
  fields::Visit(defaults, leaves);
  ASSERT_GE(leaves.found.size(), 25u);
  std::set<std::string> flagged;
  for (const SettingFlag& flag : SettingFlags()) {
    for (const std::string& path : flag.paths) flagged.insert(path);
  }
  for (const auto& [path, field] : leaves.found) {
    EXPECT_NE(ProtoField(path), nullptr) << path << ": declared, but stevi.v1.ServerConfig has "
                                         << "no such field (proto/stevi/v1/config.proto)";
    EXPECT_TRUE(field.has_flag()) << path << ": a server setting without a flag";
    EXPECT_EQ(flagged.count(path), 1u) << path << ": no flag sets it";
  }
}

TEST(ServerSettings, EveryFlagsPathIsAProtoFieldAndTheFlagSetsExactlyIt) {
  std::set<std::string> names;
  for (const SettingFlag& flag : SettingFlags()) {
    EXPECT_TRUE(names.insert(flag.flag).second) << "--" << flag.flag << " declared twice";
    for (const std::string& path : flag.paths) {
      EXPECT_NE(ProtoField(path), nullptr) << "--" << flag.flag << ": no config field " << path;
    }
    // A value the field accepts: its default where it has one, else its first valid value.
    std::string text = flag.default_value;
    if (flag.kind == SettingFlag::Kind::kText || text.empty() || text == "unset" ||
        text.find("unset") != std::string::npos) {
      text = flag.kind == SettingFlag::Kind::kNumber ? "1"
             : flag.kind == SettingFlag::Kind::kPair ? "64x48"
                                                     : "some-value";
    }
    if (flag.kind == SettingFlag::Kind::kChoice) text = flag.choices.back();
    if (flag.kind == SettingFlag::Kind::kChoiceAndText) text = flag.choices.back() + ":x";
    v1::ServerConfig config;
    ASSERT_EQ(ApplySettingFlag(flag, text, config), "") << "--" << flag.flag << " " << text;
    for (const std::string& path : flag.paths) {
      EXPECT_TRUE(IsSet(config, path)) << "--" << flag.flag << " " << text << " left " << path;
    }
  }
}

TEST(ServerSettings, TheDefaultsReadBackThroughTheProto) {
  // Every field of the list maps to its proto field and back (a field the message lacks, not
  // marked NoProto(), throws in the mapper).
  ServerOptions changed;
  changed.listen = "127.0.0.1:6001";
  changed.max_streams = 7;
  changed.pipeline_workers = 3;
  changed.source.kind = SourceKindName::kReplay;
  changed.source.replay.dir = "rec";
  changed.source.gst.latency_ms = 250;
  changed.tls.cert_file = "c.pem";
  v1::ServerConfig config;
  ASSERT_NO_THROW(FieldsToProto(changed, config));
  EXPECT_EQ(config.source().kind(), v1::SOURCE_KIND_REPLAY);
  Result<ServerOptions> back = ServerOptionsFrom(config);
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(back->listen, "127.0.0.1:6001");
  EXPECT_EQ(back->max_streams, 7);
  EXPECT_EQ(back->pipeline_workers, 3);
  EXPECT_EQ(back->source.replay.dir, "rec");
  EXPECT_EQ(back->source.gst.latency_ms, 250);
  EXPECT_EQ(back->tls.cert_file, "c.pem");
  EXPECT_EQ(ServerOptionsFrom(v1::ServerConfig{})->max_streams, 64) << "the default, once";
}

TEST(ServerSettings, EachBoundIsTheFieldsOwn) {
  v1::ServerConfig config;
  config.set_max_streams(0);
  config.set_keepalive_timeout_s(601);
  config.mutable_source()->set_fps(2000);
  config.mutable_source()->mutable_gst()->set_latency_ms(9000);
  EXPECT_THAT(ServerOptionsFrom(config),
              IsError(ErrorCode::kInvalidArgument,
                      ::testing::AllOf(HasSubstr("max_streams: must be in [1, 4096]"),
                                       HasSubstr("keepalive_timeout_s: must be in [1, 600]"),
                                       HasSubstr("source.fps: must be in (0, 1000]"),
                                       HasSubstr("source.gst.latency_ms: must be in [0, 5000]"))));
}

TEST(ServerSettings, SourceKindsAreTheFactorysKinds) {
  std::set<std::string> declared;
  for (const auto& kind : SourceOptions::kKindNames) declared.insert(std::string(kind.name));
  std::set<std::string> factory;
  for (const SourceKind& kind : SourceKinds()) factory.insert(std::string(kind.name));
  EXPECT_EQ(declared, factory);
}

TEST(ServerSettings, UsageNamesEveryFlagAndTheReadmeHasItsTable) {
  ServerCommandLine line("stevi-server", [](const SettingFlag&) { return true; });
  const std::string usage = line.Usage("About.");
  for (const SettingFlag& flag : SettingFlags()) {
    EXPECT_THAT(usage, HasSubstr("  --" + flag.flag + " ")) << "the usage lacks --" << flag.flag;
  }
  EXPECT_THAT(usage, HasSubstr("--config FILE"));
  // Every row of the README's table has its five cells: a '|' inside one ("camera|host") is
  // escaped, or Markdown would split the row there.
  const std::string table = FlagTableMarkdown();
  size_t start = 0;
  while (start < table.size()) {
    const size_t end = table.find('\n', start);
    const std::string row = table.substr(start, end - start);
    int bars = 0;
    for (size_t i = 0; i < row.size(); ++i) bars += row[i] == '|' && (i == 0 || row[i - 1] != '\\');
    EXPECT_EQ(bars, 6) << row;
    start = end + 1;
  }
  stevi::testing::CheckReadmeSection("<!-- flags table: generated from the field lists -->\n",
                                     "<!-- end of the flags table -->\n", FlagTableMarkdown());
}

}  // namespace
}  // namespace stevi::server
