// Fuzz target: the configuration files stevi-server and stevi-process read (stevi.v1.ServerConfig,
// and stevi.v1.PipelineConfig, which SetPipelineConfig and the config's pipeline section carry),
// in protobuf text format and in JSON, through ParseConfigText (LoadServerConfig's parser) and on
// to validation: ValidateServerConfig, MakePoseSource, and BuildPipelineConfig (the proto mapped
// by name onto the core options by server/convert.cc, then the core's Validate()).
//
// Input: byte 0 picks the format (bit 0: JSON, else text format; an input whose first non-blank
// character does not match the format is skipped) and the message (bit 1: PipelineConfig, else
// ServerConfig); the rest is the config text.
// Checked besides the sanitizers:
//   - a config that parses, written back as text format and as JSON, parses to an equal message
//     (NaN equal to NaN) that validates with the same result, word for word;
//   - a pipeline config that builds maps back (ToProto) to a config that builds to the same
//     options (the proto-to-core mapping is stable);
//   - nothing throws out.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <google/protobuf/text_format.h>
#include <google/protobuf/util/field_comparator.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/message_differencer.h>

#include "server/app_config.h"
#include "server/convert.h"
#include "tests/fuzz/require.h"

namespace v1 = stevi::v1;
namespace server = stevi::server;

namespace {

using stevi::fuzz::Require;

bool Equal(const google::protobuf::Message& a, const google::protobuf::Message& b) {
  google::protobuf::util::DefaultFieldComparator comparator;
  comparator.set_treat_nan_as_equal(true);
  google::protobuf::util::MessageDifferencer differencer;
  differencer.set_field_comparator(&comparator);
  std::string differences;
  differencer.ReportDifferencesToString(&differences);
  if (differencer.Compare(a, b)) return true;
  std::fprintf(stderr, "the messages differ:\n%s", differences.c_str());
  return false;
}

// What validation says about a config: every problem, in order, or the built options.
std::vector<std::string> Verdict(const v1::PipelineConfig& config) {
  const stevi::Result<stevi::pipeline::PipelineConfig> built = server::BuildPipelineConfig(config);
  if (!built.ok()) return {"error: " + built.error().message};
  // The options map back to a config that builds to the same options.
  const v1::PipelineConfig mapped = server::ToProto(*built);
  const stevi::Result<stevi::pipeline::PipelineConfig> again = server::BuildPipelineConfig(mapped);
  Require(again.ok());
  Require(Equal(server::ToProto(*again), mapped));
  return {"ok: " + mapped.ShortDebugString()};
}

std::vector<std::string> Verdict(const v1::ServerConfig& config) {
  std::vector<std::string> verdict = server::ValidateServerConfig(config);
  for (std::string& line : Verdict(config.pipeline())) verdict.push_back(std::move(line));
  const auto pose = server::MakePoseSource(config.geo(), std::nullopt);
  verdict.push_back(pose.ok() ? std::string("pose ok") : pose.error().message);
  return verdict;
}

template <class Config>
void RoundTrip(const Config& config) {
  const std::vector<std::string> verdict = Verdict(config);

  std::string text;
  google::protobuf::TextFormat::Printer printer;
  Require(printer.PrintToString(config, &text));
  Config from_text;
  Require(server::ParseConfigText(text, "text", from_text).ok());
  Require(Equal(config, from_text));
  Require(Verdict(from_text) == verdict);

  std::string json;
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  Require(google::protobuf::util::MessageToJsonString(config, &json, options).ok());
  Config from_json;
  Require(server::ParseConfigText(json, "json", from_json).ok());
  Require(Equal(config, from_json));
  Require(Verdict(from_json) == verdict);
}

template <class Config>
void Run(const std::string& text) {
  Config config;
  if (!server::ParseConfigText(text, "fuzz", config).ok()) return;
  RoundTrip(config);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const bool json = (data[0] & 1) != 0;
  const bool pipeline = (data[0] & 2) != 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  const size_t first = text.find_first_not_of(" \t\r\n");
  const bool looks_json = first != std::string::npos && text[first] == '{';
  if (json != looks_json) return 0;
  // An exception escaping the parsers or validation ends the run (std::terminate).
  if (pipeline) {
    Run<v1::PipelineConfig>(text);
  } else {
    Run<v1::ServerConfig>(text);
  }
  return 0;
}
