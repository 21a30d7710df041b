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

Result<Flags> ParseFlags(int argc, const char* const* argv, const std::set<std::string>& known,
                         const std::set<std::string>& switches) {
  Flags flags;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg.rfind("--", 0) != 0) {
      flags.positional.push_back(arg);
      continue;
    }
    std::string name = arg.substr(2);
    std::optional<std::string> value;
    if (const size_t eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
    }
    if (switches.count(name) != 0) {
      if (value.has_value()) return InvalidArgument("--" + name + " takes no value");
      flags.values[name] = "true";
      continue;
    }
    if (known.count(name) == 0) {
      return InvalidArgument("unknown flag --" + name + " (see --help)");
    }
    if (!value.has_value()) {
      if (i + 1 >= argc) return InvalidArgument("--" + name + " needs a value");
      value = argv[++i];
    }
    if (!flags.values.emplace(name, *value).second) {
      return InvalidArgument("--" + name + " given twice");
    }
  }
  return flags;
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

namespace {

// The GStreamer sources' flags (gst, uvc, rtsp, video) onto `gst`.
void ApplyGstFlags(const std::function<const std::string*(const std::string&)>& get,
                   v1::GstConfig& config, std::vector<std::string>& problems) {
  v1::GstConfig* gst = &config;
  if (const std::string* v = get("layout")) {
    const std::optional<drivers::GstLayout> layout = drivers::ParseGstLayout(*v);
    if (!layout) {
      problems.push_back("--layout: side-by-side, top-bottom or two (got '" + *v + "')");
    } else {
      gst->set_layout(*layout == drivers::GstLayout::kTwo         ? v1::GST_LAYOUT_TWO
                      : *layout == drivers::GstLayout::kTopBottom ? v1::GST_LAYOUT_TOP_BOTTOM
                                                                  : v1::GST_LAYOUT_SIDE_BY_SIDE);
    }
  }
  if (const std::string* v = get("pipeline")) gst->set_pipeline(*v);
  if (const std::string* v = get("left-pipeline")) gst->set_left_pipeline(*v);
  if (const std::string* v = get("right-pipeline")) gst->set_right_pipeline(*v);
  if (const std::string* v = get("device")) gst->set_device(*v);
  if (const std::string* v = get("url")) gst->set_url(*v);
  if (const std::string* v = get("file")) gst->set_file(*v);
  if (const std::string* v = get("size")) {
    const size_t x = v->find('x');
    const std::optional<double> w =
        x == std::string::npos ? std::nullopt : ParseNumber(v->substr(0, x));
    const std::optional<double> h =
        x == std::string::npos ? std::nullopt : ParseNumber(v->substr(x + 1));
    const auto side_ok = [](double s) { return s >= 16 && s <= 16384 && s == std::floor(s); };
    if (!w || !h || !side_ok(*w) || !side_ok(*h)) {
      problems.push_back(
          "--size: expected WIDTHxHEIGHT of one view in pixels, 16..16384 each "
          "(got '" +
          *v + "')");
    } else {
      gst->set_width(static_cast<int32_t>(*w));
      gst->set_height(static_cast<int32_t>(*h));
    }
  }
  if (const std::string* v = get("latency-ms")) {
    const std::optional<double> ms = ParseNumber(*v);
    if (!ms || *ms < 0 || *ms > 5000 || *ms != std::floor(*ms)) {
      problems.push_back("--latency-ms: must be a whole number of ms in 0..5000 (got '" + *v +
                         "')");
    } else {
      gst->set_latency_ms(static_cast<uint32_t>(*ms));
    }
  }
}

// --record, --record-mcap and --mcap-image-hz onto `config`.
void ApplyRecordingFlags(const std::function<const std::string*(const std::string&)>& get,
                         v1::ServerConfig& config, std::vector<std::string>& problems) {
  if (const std::string* v = get("record")) config.mutable_record()->set_dir(*v);
  if (const std::string* v = get("record-mcap")) config.mutable_record_mcap()->set_file(*v);
  if (const std::string* v = get("mcap-image-hz")) {
    const std::optional<double> hz = ParseNumber(*v);
    if (!hz) {
      problems.push_back("--mcap-image-hz: must be a number of images per second (got '" + *v +
                         "')");
    } else {
      config.mutable_record_mcap()->set_image_hz(*hz);
    }
  }
}

// ApplyFlags' work, on a copy it may leave half changed.
Status ApplyFlagsToCopy(const Flags& flags, v1::ServerConfig& config) {
  std::vector<std::string> problems;
  const auto get = [&](const std::string& name) -> const std::string* {
    auto it = flags.values.find(name);
    return it == flags.values.end() ? nullptr : &it->second;
  };
  if (const std::string* v = get("listen")) config.set_listen(*v);
  v1::SourceConfig* source = config.mutable_source();
  if (const std::string* v = get("source")) {
    std::string value_name = "SOURCE_KIND_";
    for (char c : *v) value_name += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    v1::SourceKind kind = v1::SOURCE_KIND_UNSPECIFIED;
    if (FindSourceKind(*v) != nullptr && v1::SourceKind_Parse(value_name, &kind)) {
      source->set_kind(kind);
    } else {
      problems.push_back("--source: unknown source '" + *v + "' (" + SourceKindNames() + ")");
    }
  }
  if (const std::string* v = get("replay")) source->mutable_replay()->set_dir(*v);
  if (flags.values.count("allow-insecure")) config.set_allow_insecure(true);
  if (const std::string* v = get("tls-cert")) config.mutable_tls()->set_cert_file(*v);
  if (const std::string* v = get("tls-key")) config.mutable_tls()->set_key_file(*v);
  if (const std::string* v = get("tls-client-ca")) config.mutable_tls()->set_client_ca_file(*v);
  if (const std::string* v = get("token-file")) config.mutable_auth()->set_token_file(*v);
  if (const std::string* v = get("rate")) {
    const std::optional<double> rate = *v == "max" ? std::optional<double>(0.0) : ParseNumber(*v);
    if (!rate || *rate < 0 || *rate > 1000) {
      problems.push_back("--rate: must be a speed in (0, 1000] or 'max' (got '" + *v + "')");
    } else {
      source->mutable_replay()->set_rate(*rate);
    }
  }
  ApplyRecordingFlags(get, config, problems);
  if (const std::string* v = get("roi")) {
    const size_t x = v->find('x');
    const std::optional<double> w =
        x == std::string::npos ? std::nullopt : ParseNumber(v->substr(0, x));
    const std::optional<double> h =
        x == std::string::npos ? std::nullopt : ParseNumber(v->substr(x + 1));
    const auto side_ok = [](double s) {
      return s >= drivers::kMinRoiPx && s <= drivers::kMaxRoiPx && s == std::floor(s);
    };
    if (!w || !h || !side_ok(*w) || !side_ok(*h)) {
      problems.push_back("--roi: expected WIDTHxHEIGHT in pixels, " +
                         std::to_string(drivers::kMinRoiPx) + ".." +
                         std::to_string(drivers::kMaxRoiPx) + " each (got '" + *v + "')");
    } else {
      source->mutable_aravis()->set_width(static_cast<uint32_t>(*w));
      source->mutable_aravis()->set_height(static_cast<uint32_t>(*h));
    }
  }
  if (const std::string* v = get("exposure-us")) {
    const std::optional<double> e = ParseNumber(*v);
    if (!e || *e <= 0) {
      problems.push_back("--exposure-us: must be a time in microseconds > 0 (got '" + *v + "')");
    } else {
      source->mutable_aravis()->set_exposure_us(*e);
    }
  }
  if (const std::string* v = get("gain-db")) {
    const std::optional<double> g = ParseNumber(*v);
    if (!g) {
      problems.push_back("--gain-db: must be a number of dB (got '" + *v + "')");
    } else {
      source->mutable_aravis()->set_gain_db(*g);
    }
  }
  if (const std::string* v = get("timestamps")) {
    if (*v == "camera") {
      source->mutable_aravis()->set_timestamps(v1::TIMESTAMP_SOURCE_CAMERA);
    } else if (*v == "host") {
      source->mutable_aravis()->set_timestamps(v1::TIMESTAMP_SOURCE_HOST);
    } else {
      problems.push_back("--timestamps: camera or host (got '" + *v + "')");
    }
  }
  if (const std::string* v = get("trigger")) {
    v1::AravisConfig* aravis = source->mutable_aravis();
    if (*v == "free") {
      aravis->set_trigger(v1::TRIGGER_MODE_FREE_RUN);
    } else if (*v == "software") {
      aravis->set_trigger(v1::TRIGGER_MODE_SOFTWARE);
    } else if (v->rfind("hardware:", 0) == 0 && v->size() > 9) {
      aravis->set_trigger(v1::TRIGGER_MODE_HARDWARE);
      aravis->set_trigger_line(v->substr(9));
    } else {
      problems.push_back("--trigger: free, software or hardware:LINE (got '" + *v + "')");
    }
  }
  ApplyGstFlags(get, *source->mutable_gst(), problems);
  if (const std::string* v = get("left")) source->set_left(*v);
  if (const std::string* v = get("right")) source->set_right(*v);
  if (const std::string* v = get("calibration")) source->set_calibration(*v);
  if (const std::string* v = get("data-dir")) config.set_data_dir(*v);
  if (const std::string* v = get("scene")) source->mutable_synthetic()->set_scene(*v);
  if (const std::string* v = get("fps")) {
    const std::optional<double> fps = ParseNumber(*v);
    if (!fps || *fps <= 0 || *fps > 1000) {
      problems.push_back("--fps: must be a number in (0, 1000] (got '" + *v + "')");
    } else {
      source->set_fps(*fps);
    }
  }
  if (const std::string* v = get("algorithm")) {
    const std::optional<pipeline::Algorithm> algorithm = pipeline::AlgorithmFromName(*v);
    if (!algorithm) {
      problems.push_back("--algorithm: unknown algorithm '" + *v + "' (canonical, stevie, stevis)");
    } else {
      config.mutable_pipeline()->set_algorithm(ToProto(*algorithm));
    }
  }
  if (!problems.empty()) return InvalidArgument(problems);
  return Status::Ok();
}

}  // namespace

Status ApplyFlags(const Flags& flags, v1::ServerConfig& config) {
  v1::ServerConfig updated = config;
  Status applied = ApplyFlagsToCopy(flags, updated);
  if (applied.ok()) config = std::move(updated);
  return applied;
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
  base.fps = source.has_fps() ? source.fps() : kDefaultFps;
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
  spec.images.fps = source.has_fps() ? source.fps() : kDefaultFps;
  spec.images.loop = source.has_loop() ? source.loop() : loop_images;
  spec.aravis = AravisOptionsFrom(source, problems);
  spec.replay_dir = source.replay().dir();
  spec.replay = ReplayOptionsFrom(source, problems);
  spec.gst = GstOptionsFrom(source, loop_images, problems);
  const v1::GstConfig& gst = source.gst();
  if (gst.has_device()) spec.gst_device = gst.device();
  spec.gst_url = gst.url();
  spec.gst_file = gst.file();
  if (gst.has_latency_ms())
    spec.gst_latency_ms = static_cast<int>(std::min(gst.latency_ms(), 1u << 30));
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

// ValidateServerConfig's parts, each appending to `problems`.
void ValidateListen(const v1::ServerConfig& config, std::vector<std::string>& problems) {
  if (config.has_listen()) {
    const std::string& listen = config.listen();
    const size_t colon = listen.rfind(':');
    if (colon == std::string::npos || colon == 0 || colon + 1 == listen.size()) {
      problems.push_back("listen: expected HOST:PORT (got '" + listen + "')");
    } else {
      const std::string port = listen.substr(colon + 1);
      int value = -1;
      auto [ptr, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
      if (ec != std::errc() || ptr != port.data() + port.size() || value < 0 || value > 65535) {
        problems.push_back("listen: port must be 0..65535 (got '" + port + "')");
      }
    }
  }
}

void ValidateSource(const v1::SourceConfig& source, std::vector<std::string>& problems) {
  if (source.has_fps() && !(source.fps() > 0 && source.fps() <= 1000)) {
    problems.push_back("source.fps: must be in (0, 1000] (got " + std::to_string(source.fps()) +
                       ")");
  }
  const SourceSpec spec = SourceSpecFrom(source, /*loop_images=*/true, problems);
  AppendPrefixed(problems, "", CheckSource(spec));
}

}  // namespace

std::vector<std::string> ValidateServerConfig(const v1::ServerConfig& config) {
  std::vector<std::string> problems;
  ValidateListen(config, problems);
  ValidateSource(config.source(), problems);
  if (config.has_subscriber_queue_frames() &&
      (config.subscriber_queue_frames() < 1 || config.subscriber_queue_frames() > 1024)) {
    problems.push_back("subscriber_queue_frames: must be in 1..1024");
  }
  if (config.has_max_message_bytes() &&
      (config.max_message_bytes() < (64u << 10) || config.max_message_bytes() > (1u << 30))) {
    problems.push_back("max_message_bytes: must be in 64 KiB..1 GiB");
  }
  if (config.has_pipeline_workers() &&
      (config.pipeline_workers() < 1 || config.pipeline_workers() > kMaxPipelineWorkers)) {
    problems.push_back("pipeline_workers: must be in 1.." + std::to_string(kMaxPipelineWorkers) +
                       " (got " + std::to_string(config.pipeline_workers()) + ")");
  }
  if (config.has_opencv_threads() &&
      (config.opencv_threads() < 1 || config.opencv_threads() > kMaxOpenCvThreads)) {
    problems.push_back("opencv_threads: must be in 1.." + std::to_string(kMaxOpenCvThreads) +
                       " (got " + std::to_string(config.opencv_threads()) + ")");
  }
  if (config.has_max_streams() && (config.max_streams() < 1 || config.max_streams() > 4096)) {
    problems.push_back("max_streams: must be in 1..4096");
  }
  if (config.has_data_dir() && config.data_dir().empty()) {
    problems.push_back("data_dir: must not be empty");
  }
  const auto check_seconds = [&](bool has, double value, const char* name, double lo, double hi) {
    if (has && !(value >= lo && value <= hi)) {
      problems.push_back(std::string(name) + ": must be in [" + FormatNumber(lo) + ", " +
                         FormatNumber(hi) + "] s (got " + FormatNumber(value) + ")");
    }
  };
  check_seconds(config.has_keepalive_time_s(), config.keepalive_time_s(), "keepalive_time_s", 1,
                86400);
  check_seconds(config.has_keepalive_timeout_s(), config.keepalive_timeout_s(),
                "keepalive_timeout_s", 1, 600);
  check_seconds(config.has_min_client_ping_interval_s(), config.min_client_ping_interval_s(),
                "min_client_ping_interval_s", 1, 86400);
  // Who can reach the server: without authentication only this machine, unless asked explicitly.
  const bool authenticated = config.auth().has_token_file() || config.tls().has_client_ca_file();
  const std::string listen = config.has_listen() ? config.listen() : kDefaultListen;
  if (!authenticated && !config.allow_insecure() && !IsLoopbackListen(listen)) {
    problems.push_back("listen: '" + listen +
                       "' is not a loopback address, and no authentication "
                       "is configured (auth.token_file, or tls.client_ca_file for mutual TLS): "
                       "anyone on the network could change the pipeline; configure one, or give "
                       "--allow-insecure (allow_insecure: true) to accept that");
  }
  if (config.auth().has_token_file() && !config.tls().has_cert_file() && !config.allow_insecure()) {
    problems.push_back(
        "auth.token_file: a bearer token needs TLS (tls.cert_file and tls.key_file), "
        "else it crosses the network in clear text; or give --allow-insecure");
  }
  if (!config.auth().allowed_client_names().empty() && !config.tls().has_client_ca_file()) {
    problems.push_back(
        "auth.allowed_client_names: needs tls.client_ca_file (client certificates "
        "exist only with mutual TLS)");
  }
  if (config.record().has_dir() && config.record().dir().empty()) {
    problems.push_back("record.dir: must not be empty");
  }
  drivers::RecorderOptions record;  // checked by the recorder's own field list
  if (config.record().has_max_bytes()) record.max_bytes = config.record().max_bytes();
  if (config.record().has_queue_frames()) {
    record.queue_frames = static_cast<int>(
        std::min<uint32_t>(config.record().queue_frames(), std::numeric_limits<int>::max()));
  }
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
  if (config.has_image_hz()) options.log.image_hz = config.image_hz();
  if (config.has_rig()) options.log.rig = config.rig();
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
