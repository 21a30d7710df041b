#include "server/app_config.h"

#include "core/common/format.h"

#include "server/field_mapping.h"

#include "drivers/synthetic/chessboard_source.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/message.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <fstream>
#include <sstream>

#include "drivers/aravis/aravis_source.h"
#include "drivers/files/image_source.h"
#include "drivers/recording/recorder.h"
#include "drivers/recording/replay_source.h"
#include "drivers/synthetic/scenarios.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/auth.h"
#include "server/convert.h"
#include "server/server_options.h"

namespace stevi::server {
namespace {

constexpr uintmax_t kMaxConfigBytes = 1 << 20;

// Collects the text-format parser's messages instead of logging them.
class CollectingErrors : public google::protobuf::io::ErrorCollector {
 public:
  void AddError(int line, google::protobuf::io::ColumnNumber column,
                const std::string& message) override {
    problems.push_back("line " + std::to_string(line + 1) + ", column " +
                       std::to_string(column + 1) + ": " + message);
  }
  void AddWarning(int, google::protobuf::io::ColumnNumber, const std::string&) override {}
  std::vector<std::string> problems;
};

// True when `text` is well-formed UTF-8 (no overlong forms, surrogates or values past U+10FFFF).
bool IsUtf8(const std::string& text) {
  const auto* p = reinterpret_cast<const unsigned char*>(text.data());
  const auto* end = p + text.size();
  while (p < end) {
    const unsigned char c = *p;
    int length = 0;
    unsigned char lo = 0x80, hi = 0xBF;  // the range of the second byte
    if (c < 0x80) {
      ++p;
      continue;
    }
    if (c >= 0xC2 && c <= 0xDF) {
      length = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
      length = 3;
      if (c == 0xE0) lo = 0xA0;
      if (c == 0xED) hi = 0x9F;
    } else if (c >= 0xF0 && c <= 0xF4) {
      length = 4;
      if (c == 0xF0) lo = 0x90;
      if (c == 0xF4) hi = 0x8F;
    } else {
      return false;
    }
    if (end - p < length || p[1] < lo || p[1] > hi) return false;
    for (int i = 2; i < length; ++i) {
      if ((p[i] & 0xC0) != 0x80) return false;
    }
    p += length;
  }
  return true;
}

// Names every string field (not bytes) of `message` that is not UTF-8, as "PATH: not valid
// UTF-8". The text format parser takes any bytes (raw, or escapes such as "\260") into a string
// field, which a proto3 string must not hold: serialising it fails, JSON drops the bytes.
void CheckUtf8(const google::protobuf::Message& message, const std::string& path,
               std::vector<std::string>& problems) {
  using google::protobuf::FieldDescriptor;
  const google::protobuf::Reflection* reflection = message.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);
  for (const FieldDescriptor* field : fields) {
    const std::string name = path + field->name();
    const int count = field->is_repeated() ? reflection->FieldSize(message, field) : 1;
    for (int i = 0; i < count; ++i) {
      const std::string where = field->is_repeated() ? name + "[" + std::to_string(i) + "]" : name;
      if (field->type() == FieldDescriptor::TYPE_STRING) {
        const std::string value = field->is_repeated()
                                      ? reflection->GetRepeatedString(message, field, i)
                                      : reflection->GetString(message, field);
        if (!IsUtf8(value)) problems.push_back(where + ": not valid UTF-8");
      } else if (field->cpp_type() == FieldDescriptor::CPPTYPE_MESSAGE) {
        CheckUtf8(field->is_repeated() ? reflection->GetRepeatedMessage(message, field, i)
                                       : reflection->GetMessage(message, field),
                  where + ".", problems);
      }
    }
  }
}

}  // namespace

Result<std::unique_ptr<PoseSource>> MakePoseSource(
    const v1::GeoConfig& config, const std::optional<geo::VehicleState>& synthetic_default) {
  geo::PoseBufferOptions options;
  if (std::vector<std::string> problems = FieldsFromProto(config, options, "geo.");
      !problems.empty()) {
    return InvalidArgument(problems);
  }
  std::optional<geo::VehicleState> fixed = synthetic_default;
  if (config.has_fixed_pose()) fixed = FromProto(config.fixed_pose());
  return PoseSource::Create(options, fixed);
}

Result<v1::ServerConfig> LoadServerConfig(const std::string& path) {
  std::error_code ec;
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return NotFound("config " + path + ": " + ec.message());
  if (size > kMaxConfigBytes) {
    return ResourceExhausted("config " + path + ": " + std::to_string(size) +
                             " bytes, the limit is 1 MiB");
  }
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  if (!in.good() && !in.eof()) return InvalidArgument("config " + path + ": cannot read");
  v1::ServerConfig config;
  if (Status parsed = ParseConfigText(buffer.str(), "config " + path, config); !parsed.ok()) {
    return parsed.error();
  }
  return config;
}

Status ParseConfigText(const std::string& text, const std::string& name,
                       google::protobuf::Message& config) {
  if (text.size() > kMaxConfigBytes) {
    return ResourceExhausted(name + ": " + std::to_string(text.size()) +
                             " bytes, the limit is 1 MiB");
  }
  const size_t first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && text[first] == '{') {
    google::protobuf::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    const auto status = google::protobuf::util::JsonStringToMessage(text, &config, options);
    if (!status.ok()) {
      return InvalidArgument(name + " (JSON): " + std::string(status.message()));
    }
  } else {
    google::protobuf::TextFormat::Parser parser;
    CollectingErrors errors;
    parser.RecordErrorsTo(&errors);
    if (!parser.ParseFromString(text, &config)) {
      std::vector<std::string> problems;
      for (const std::string& p : errors.problems) problems.push_back(name + ": " + p);
      if (problems.empty()) problems.push_back(name + ": cannot parse");
      return InvalidArgument(problems);
    }
  }
  std::vector<std::string> problems;
  CheckUtf8(config, "", problems);
  if (!problems.empty()) {
    for (std::string& p : problems) p = name + ": " + p;
    return InvalidArgument(problems);
  }
  return Status::Ok();
}

drivers::AravisOptions AravisOptionsFrom(const v1::SourceConfig& source,
                                         std::vector<std::string>& problems) {
  drivers::AravisOptions options;
  options.left_id = source.left();
  options.right_id = source.right();
  if (source.has_fps()) options.frame_rate_hz = source.fps();
  AppendPrefixed(problems, "", FieldsFromProto(source.aravis(), options, "source.aravis."));
  return options;
}

namespace {

// A synthetic scene's options: source.synthetic's fields over `base`, at source.fps.
template <class Options>
Options SyntheticFieldsOver(Options base, const v1::SourceConfig& source,
                            std::vector<std::string>& problems) {
  base.fps = source.has_fps() ? source.fps() : SourceOptions{}.fps;
  AppendPrefixed(problems, "", FieldsFromProto(source.synthetic(), base, "source.synthetic."));
  return base;
}

}  // namespace

drivers::SyntheticOptions SyntheticOptionsFrom(const v1::SourceConfig& source,
                                               std::vector<std::string>& problems) {
  // The named scenario's rig, noise, seed and scene (the loop repeats it), else the default.
  const std::optional<drivers::Scenario> scenario =
      drivers::FindScenario(source.synthetic().scene());
  return SyntheticFieldsOver(scenario ? scenario->options : drivers::SyntheticOptions{}, source,
                             problems);
}

drivers::ChessboardSourceOptions ChessboardOptionsFrom(const v1::SourceConfig& source,
                                                       std::vector<std::string>& problems) {
  return SyntheticFieldsOver(drivers::ChessboardSourceOptions{}, source, problems);
}

drivers::ReplayOptions ReplayOptionsFrom(const v1::SourceConfig& source,
                                         std::vector<std::string>& problems) {
  drivers::ReplayOptions options;
  AppendPrefixed(problems, "", FieldsFromProto(source.replay(), options, "source.replay."));
  return options;
}

std::string SourceKindName(v1::SourceKind kind) {
  if (kind == v1::SOURCE_KIND_UNSPECIFIED) return std::string(SourceKinds().front().name);
  const std::string prefix = "SOURCE_KIND_";
  std::string name = v1::SourceKind_Name(kind);
  if (name.rfind(prefix, 0) != 0) return std::to_string(static_cast<int>(kind));
  name.erase(0, prefix.size());
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

SourceSpec SourceSpecFrom(const v1::SourceConfig& source, bool loop_images,
                          std::vector<std::string>& problems) {
  SourceSpec spec;
  spec.kind = SourceKindName(source.kind());
  spec.left = source.left();
  spec.right = source.right();
  spec.calibration = source.calibration();
  spec.scene = source.synthetic().scene();
  spec.synthetic = SyntheticOptionsFrom(source, problems);
  std::vector<std::string> board_problems;  // the same fields as synthetic's: named once
  spec.chessboard = ChessboardOptionsFrom(source, board_problems);
  spec.images.left = source.left();
  spec.images.right = source.right();
  spec.images.calibration = source.calibration();
  spec.images.fps = source.has_fps() ? source.fps() : SourceOptions{}.fps;
  spec.images.loop = source.has_loop() ? source.loop() : loop_images;
  spec.aravis = AravisOptionsFrom(source, problems);
  spec.replay_dir = source.replay().dir();
  spec.replay = ReplayOptionsFrom(source, problems);
  spec.gst = GstOptionsFrom(source, loop_images, problems);
  GstInputs inputs;  // the proto's problems are ValidateServerConfig's (ServerOptions)
  FieldsFromProto(source.gst(), inputs);
  spec.gst_inputs = inputs;
  return spec;
}

drivers::GstOptions GstOptionsFrom(const v1::SourceConfig& source, bool loop_files,
                                   std::vector<std::string>& problems) {
  drivers::GstOptions options;
  // The defaults that depend on the rest of the source: a video file is not live, and loops as
  // image files do; the source's fps is the expected rate.
  options.live = source.kind() != v1::SOURCE_KIND_VIDEO;
  if (source.has_fps()) options.fps = source.fps();
  AppendPrefixed(problems, "", FieldsFromProto(source.gst(), options, "source.gst."));
  // A file loops as image files do (SourceConfig.loop, else the caller's default); a live source
  // only if asked, which its checks then refuse.
  if (!source.gst().has_loop()) {
    options.loop = source.has_loop() ? source.loop() : (!options.live && loop_files);
  }
  return options;
}

namespace {

// The source's drivers: the options of every kind from their fields, and the chosen kind's checks.
void ValidateSource(const v1::SourceConfig& source, std::vector<std::string>& problems) {
  const SourceSpec spec = SourceSpecFrom(source, /*loop_images=*/true, problems);
  AppendPrefixed(problems, "", CheckSource(spec));
}

}  // namespace

Result<ServerOptions> ServerOptionsFrom(const v1::ServerConfig& config) {
  ServerOptions options;
  std::vector<std::string> problems = FieldsFromProto(config, options);
  if (problems.empty()) problems = options.Validate();
  if (!problems.empty()) return InvalidArgument(problems);
  return options;
}

std::vector<std::string> ValidateServerConfig(const v1::ServerConfig& config) {
  std::vector<std::string> problems;
  // The server's own settings: their bounds (server/server_options.h), the listen address and
  // who may reach the server.
  ServerOptions options;
  AppendPrefixed(problems, "", FieldsFromProto(config, options));
  AppendPrefixed(problems, "", options.Validate());
  ValidateSource(config.source(), problems);
  if (!config.auth().allowed_client_names().empty() && !config.tls().has_client_ca_file()) {
    problems.push_back(
        "auth.allowed_client_names: needs tls.client_ca_file (client certificates "
        "exist only with mutual TLS)");
  }
  if (config.record().has_dir() && config.record().dir().empty()) {
    problems.push_back("record.dir: must not be empty");
  }
  drivers::RecorderOptions record;  // checked by the recorder's own field list
  AppendPrefixed(problems, "", FieldsFromProto(config.record(), record, "record."));
  AppendPrefixed(problems, "record.", record.Validate());
  if (config.has_record_mcap()) McapRecordingOptionsFrom(config.record_mcap(), problems);
  return problems;
}

McapRecordingOptions McapRecordingOptionsFrom(const v1::McapRecordConfig& config,
                                              std::vector<std::string>& problems) {
  McapRecordingOptions options;
  options.file = config.file();
  if (options.file.empty()) {
    problems.push_back("record_mcap.file: required (the MCAP file to write)");
  } else if (std::error_code ec; std::filesystem::exists(options.file, ec)) {
    problems.push_back("record_mcap.file: " + options.file +
                       " exists (a flight log is never overwritten)");
  } else {
    const std::filesystem::path parent = std::filesystem::path(options.file).parent_path().empty()
                                             ? std::filesystem::path(".")
                                             : std::filesystem::path(options.file).parent_path();
    if (!std::filesystem::is_directory(parent, ec)) {
      problems.push_back("record_mcap.file: the folder " + parent.string() + " does not exist");
    }
  }
  AppendPrefixed(problems, "", FieldsFromProto(config, options.log, "record_mcap."));
  switch (config.compression()) {
    case v1::MCAP_COMPRESSION_NONE: options.log.mcap.compression = mcap::Compression::kNone; break;
    case v1::MCAP_COMPRESSION_LZ4: options.log.mcap.compression = mcap::Compression::kLz4; break;
    default: options.log.mcap.compression = mcap::Compression::kZstd; break;
  }
  if (config.has_chunk_s()) {
    if (!(config.chunk_s() >= 0.05 && config.chunk_s() <= 60)) {
      problems.push_back("record_mcap.chunk_s: must be in [0.05, 60] s" + Got(config.chunk_s()));
    } else {
      options.log.mcap.chunk_span_ns = static_cast<int64_t>(std::llround(config.chunk_s() * 1e9));
    }
  }
  AppendPrefixed(problems, "record_mcap.", options.log.Validate());
  return options;
}

Result<pipeline::PipelineConfig> BuildPipelineConfig(const v1::PipelineConfig& config) {
  pipeline::PipelineConfig core;
  std::vector<std::string> problems = MergeFromProto(config, core);
  if (problems.empty()) problems = core.Validate();
  if (!problems.empty()) {
    for (std::string& p : problems) p = "pipeline." + p;
    return InvalidArgument(problems);
  }
  return core;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenSource(const v1::SourceConfig& config,
                                                          bool loop_images) {
  std::vector<std::string> problems;
  const SourceSpec spec = SourceSpecFrom(config, loop_images, problems);
  if (!problems.empty()) return InvalidArgument(problems);
  return server::OpenSource(spec);
}

}  // namespace stevi::server
