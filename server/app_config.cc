#include "server/app_config.h"

#include "drivers/synthetic/chessboard_source.h"

#include <google/protobuf/io/tokenizer.h>
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/json_util.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "drivers/files/image_source.h"
#include "drivers/synthetic/synthetic_source.h"
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

std::optional<double> ParseDouble(const std::string& text) {
  double value = 0;
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, value);
  if (ec != std::errc() || ptr != end || !std::isfinite(value)) return std::nullopt;
  return value;
}

}  // namespace

std::optional<drivers::Scenario> FindScenario(const std::string& name) {
  if (name == "flight") return drivers::FlightScenario();
  for (std::vector<drivers::Scenario> list : {drivers::EvaluationScenarios(), drivers::TrackingScenarios()}) {
    for (drivers::Scenario& s : list) {
      if (s.name == name) return std::move(s);
    }
  }
  return std::nullopt;
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
      if (value.has_value()) return Error{ErrorCode::kInvalidArgument, "--" + name + " takes no value"};
      flags.values[name] = "true";
      continue;
    }
    if (known.count(name) == 0) {
      return Error{ErrorCode::kInvalidArgument, "unknown flag --" + name + " (see --help)"};
    }
    if (!value.has_value()) {
      if (i + 1 >= argc) return Error{ErrorCode::kInvalidArgument, "--" + name + " needs a value"};
      value = argv[++i];
    }
    if (!flags.values.emplace(name, *value).second) {
      return Error{ErrorCode::kInvalidArgument, "--" + name + " given twice"};
    }
  }
  return flags;
}

Result<v1::ServerConfig> LoadServerConfig(const std::string& path) {
  std::error_code ec;
  const uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) return Error{ErrorCode::kNotFound, "config " + path + ": " + ec.message()};
  if (size > kMaxConfigBytes) {
    return Error{ErrorCode::kResourceExhausted,
                 "config " + path + ": " + std::to_string(size) + " bytes, the limit is 1 MiB"};
  }
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  if (!in.good() && !in.eof()) return Error{ErrorCode::kInvalidArgument, "config " + path + ": cannot read"};
  const std::string text = buffer.str();

  v1::ServerConfig config;
  const size_t first = text.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && text[first] == '{') {
    google::protobuf::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    const auto status = google::protobuf::util::JsonStringToMessage(text, &config, options);
    if (!status.ok()) {
      return Error{ErrorCode::kInvalidArgument,
                   "config " + path + " (JSON): " + std::string(status.message())};
    }
    return config;
  }
  google::protobuf::TextFormat::Parser parser;
  CollectingErrors errors;
  parser.RecordErrorsTo(&errors);
  if (!parser.ParseFromString(text, &config)) {
    std::vector<std::string> problems;
    for (const std::string& p : errors.problems) problems.push_back("config " + path + ": " + p);
    if (problems.empty()) problems.push_back("config " + path + ": cannot parse");
    return Error::Invalid(problems);
  }
  return config;
}

Status ApplyFlags(const Flags& flags, v1::ServerConfig& config) {
  std::vector<std::string> problems;
  const auto get = [&](const std::string& name) -> const std::string* {
    auto it = flags.values.find(name);
    return it == flags.values.end() ? nullptr : &it->second;
  };
  if (const std::string* v = get("listen")) config.set_listen(*v);
  v1::SourceConfig* source = config.mutable_source();
  if (const std::string* v = get("source")) {
    if (*v == "synthetic") {
      source->set_kind(v1::SOURCE_KIND_SYNTHETIC);
    } else if (*v == "images") {
      source->set_kind(v1::SOURCE_KIND_IMAGES);
    } else {
      problems.push_back("--source: unknown source '" + *v + "' (synthetic or images)");
    }
  }
  if (const std::string* v = get("left")) source->set_left(*v);
  if (const std::string* v = get("right")) source->set_right(*v);
  if (const std::string* v = get("calibration")) source->set_calibration(*v);
  if (const std::string* v = get("data-dir")) config.set_data_dir(*v);
  if (const std::string* v = get("scene")) source->mutable_synthetic()->set_scene(*v);
  if (const std::string* v = get("fps")) {
    const std::optional<double> fps = ParseDouble(*v);
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
  if (!problems.empty()) return Error::Invalid(problems);
  return Status::Ok();
}

std::vector<std::string> ValidateServerConfig(const v1::ServerConfig& config) {
  std::vector<std::string> problems;
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
  const v1::SourceConfig& source = config.source();
  if (source.has_fps() && !(source.fps() > 0 && source.fps() <= 1000)) {
    problems.push_back("source.fps: must be in (0, 1000] (got " + std::to_string(source.fps()) + ")");
  }
  switch (source.kind()) {
    case v1::SOURCE_KIND_UNSPECIFIED:
    case v1::SOURCE_KIND_SYNTHETIC:
      if (source.has_left() || source.has_right() || source.has_calibration()) {
        problems.push_back(
            "source: left, right and calibration are for the images source (--source images)");
      }
      if (source.synthetic().has_scene() && source.synthetic().scene() != "airfield" &&
          source.synthetic().scene() != "chessboard" && !FindScenario(source.synthetic().scene())) {
        std::string names = "airfield, flight, chessboard";
        for (const drivers::Scenario& s : drivers::EvaluationScenarios()) names += ", " + s.name;
        for (const drivers::Scenario& s : drivers::TrackingScenarios()) names += ", " + s.name;
        problems.push_back("source.synthetic.scene: unknown scene '" + source.synthetic().scene() +
                           "' (one of: " + names + ")");
      }
      break;
    case v1::SOURCE_KIND_IMAGES:
      if (source.left().empty()) problems.push_back("source.left: required for the images source");
      if (source.right().empty()) problems.push_back("source.right: required for the images source");
      if (source.calibration().empty()) {
        problems.push_back("source.calibration: required for the images source");
      }
      break;
    default:
      problems.push_back("source.kind: unknown value " + std::to_string(source.kind()));
  }
  if (config.has_subscriber_queue_frames() &&
      (config.subscriber_queue_frames() < 1 || config.subscriber_queue_frames() > 1024)) {
    problems.push_back("subscriber_queue_frames: must be in 1..1024");
  }
  if (config.has_max_message_bytes() &&
      (config.max_message_bytes() < (64u << 10) || config.max_message_bytes() > (1u << 30))) {
    problems.push_back("max_message_bytes: must be in 64 KiB..1 GiB");
  }
  if (config.has_max_streams() && (config.max_streams() < 1 || config.max_streams() > 4096)) {
    problems.push_back("max_streams: must be in 1..4096");
  }
  if (config.has_data_dir() && config.data_dir().empty()) {
    problems.push_back("data_dir: must not be empty");
  }
  return problems;
}

Result<pipeline::PipelineConfig> BuildPipelineConfig(const v1::PipelineConfig& config) {
  pipeline::PipelineConfig core;
  std::vector<std::string> problems = MergeFromProto(config, core);
  if (problems.empty()) problems = core.Validate();
  if (!problems.empty()) {
    for (std::string& p : problems) p = "pipeline." + p;
    return Error::Invalid(problems);
  }
  return core;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenSource(const v1::SourceConfig& config,
                                                          bool loop_images) {
  const double fps = config.has_fps() ? config.fps() : kDefaultFps;
  if (config.kind() == v1::SOURCE_KIND_IMAGES) {
    drivers::ImageSourceOptions options;
    options.left = config.left();
    options.right = config.right();
    options.calibration = config.calibration();
    options.fps = fps;
    options.loop = config.has_loop() ? config.loop() : loop_images;
    return drivers::OpenImageSource(options);
  }
  const v1::SyntheticConfig& s = config.synthetic();
  if (s.scene() == "chessboard") {
    drivers::ChessboardSourceOptions board;
    if (s.has_width()) board.width = s.width();
    if (s.has_height()) board.height = s.height();
    if (s.has_f_px()) board.f_px = s.f_px();
    if (s.has_baseline_m()) board.baseline_m = s.baseline_m();
    if (s.has_noise_sigma()) board.noise_sigma = s.noise_sigma();
    if (s.has_seed()) board.seed = s.seed();
    board.fps = fps;
    Result<std::unique_ptr<drivers::ChessboardSource>> source =
        drivers::ChessboardSource::Open(std::move(board));
    if (!source.ok()) {
      Error error = source.error();
      error.message = "source.synthetic: " + error.message;
      return error;
    }
    return std::unique_ptr<drivers::StereoSource>(std::move(source).value());
  }
  drivers::SyntheticOptions options;
  if (std::optional<drivers::Scenario> scenario = FindScenario(s.scene())) {
    options = scenario->options;  // its rig, noise, seed and scene; the loop repeats it
  }
  if (s.has_width()) options.width = s.width();
  if (s.has_height()) options.height = s.height();
  if (s.has_f_px()) options.f_px = s.f_px();
  if (s.has_baseline_m()) options.baseline_m = s.baseline_m();
  if (s.has_noise_sigma()) options.noise_sigma = s.noise_sigma();
  if (s.has_seed()) options.seed = s.seed();
  options.fps = fps;
  Result<std::unique_ptr<drivers::SyntheticSource>> source =
      drivers::OpenSyntheticSource(std::move(options));
  if (!source.ok()) {
    Error error = source.error();
    error.message = "source.synthetic: " + error.message;
    return error;
  }
  return std::unique_ptr<drivers::StereoSource>(std::move(source).value());
}

}  // namespace stevi::server
