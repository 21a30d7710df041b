// stevi-process: the pipeline in-process over a file or synthetic source, every frame, as JSON
// lines.
#include <fstream>
#include <iostream>
#include <memory>
#include <set>
#include <string>

#include "core/common/allocator.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/scenarios.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/app_config.h"
#include "server/convert.h"
#include "server/runtime/pose_source.h"
#include "drivers/recording/replay_source.h"

namespace {

constexpr char kUsage[] = R"(usage: stevi-process [flags]

Runs the detection pipeline over every frame of a source (no drops) and writes one
stevi.v1.TrackFrame per line as protobuf JSON (proto field names).

  --source KIND          synthetic (default), images or replay
  --replay DIR           replay: a recording (stevi-server --record DIR or StartRecording); its
                         frames, timestamps, vehicle states and calibration are used as recorded,
                         so that the same recording and config always give the same output
  --left PATTERN|VIDEO   images: left images as a printf pattern ("left_%04d.png") or a video file
  --right PATTERN|VIDEO  images: right images, likewise
  --calibration FILE     images: calibration YAML (OpenCV FileStorage)
  --fps N                the sequence's frame rate, for capture times (default 10)
  --algorithm NAME       canonical (default), stevie or stevis
  --config FILE          stevi.v1.ServerConfig (text format or JSON): its source and pipeline
  --frames N             process at most N frames (synthetic: default 100; images: all)
  --out FILE             write the frames here instead of stdout
  --truth FILE           synthetic source: write its truth per frame (stevi.v1.TruthFrame lines)
  --timings              include the stage timings in each frame (wall-clock measurements: the
                         output then differs from run to run)
  --help                 this text
)";

int Fail(const std::string& message, int code = 2) {
  std::cerr << "stevi-process: " << message << "\n";
  return code;
}

using namespace stevi;

// The frames' poses: a replay's recorded ones, exactly as live; the synthetic rig's own pose and
// flight, as the server follows them (the tracker carries its tracks through the ego-motion, so
// the same frames give the same tracks offline and live); none for image files.
Result<std::unique_ptr<server::PoseSource>> MakePoses(const v1::ServerConfig& config,
                                                      drivers::StereoSource& source,
                                                      bool synthetic) {
  if (const std::vector<geo::VehicleState> recorded = source.RecordedVehicleStates();
      !recorded.empty()) {
    Result<std::unique_ptr<server::PoseSource>> created =
        server::PoseSource::Create(geo::PoseBufferOptions{}, std::nullopt);
    if (created.ok()) (*created)->SetRecordedStates(recorded);
    return created;
  }
  if (!synthetic) return std::unique_ptr<server::PoseSource>();
  const std::string& scene = config.source().synthetic().scene();
  const std::optional<geo::VehicleState> start = drivers::SceneRigPose(scene);
  Result<std::unique_ptr<server::PoseSource>> created = server::MakePoseSource(config.geo(), start);
  if (created.ok() && start) {
    if (auto path = drivers::SceneRigPath(scene, *start))
      (*created)->SetSyntheticPath(std::move(path));
  }
  return created;
}

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  using namespace stevi;
  const std::set<std::string> known = {"source", "left",      "right",  "calibration",
                                       "fps",    "algorithm", "config", "frames",
                                       "out",    "truth",     "replay"};
  Result<server::Flags> flags = server::ParseFlags(argc, argv, known, {"help", "timings"});
  if (!flags.ok()) return Fail(flags.error().message);
  if (flags->values.count("help")) {
    std::cout << kUsage;
    return 0;
  }
  if (!flags->positional.empty()) return Fail("unexpected argument '" + flags->positional[0] + "'");

  v1::ServerConfig config;
  if (auto it = flags->values.find("config"); it != flags->values.end()) {
    Result<v1::ServerConfig> loaded = server::LoadServerConfig(it->second);
    if (!loaded.ok()) return Fail(loaded.error().message);
    config = std::move(loaded).value();
  }
  if (Status applied = server::ApplyFlags(*flags, config); !applied.ok()) {
    return Fail(applied.error().message);
  }
  std::vector<std::string> problems = server::ValidateServerConfig(config);
  const v1::SourceKind kind = config.source().kind();
  if (kind == v1::SOURCE_KIND_ARAVIS) {
    problems.push_back(
        "--source: stevi-process runs recorded or generated frames (synthetic, "
        "images, replay); record cameras with stevi-server --record DIR");
  }
  // Every frame, as fast as it goes: no pacing.
  if (kind == v1::SOURCE_KIND_REPLAY) config.mutable_source()->mutable_replay()->set_rate(0);
  const bool synthetic = kind == v1::SOURCE_KIND_SYNTHETIC || kind == v1::SOURCE_KIND_UNSPECIFIED;
  int64_t max_frames = synthetic ? 100 : -1;
  if (auto it = flags->values.find("frames"); it != flags->values.end()) {
    try {
      size_t used = 0;
      max_frames = std::stoll(it->second, &used);
      if (used != it->second.size() || max_frames < 1) throw std::invalid_argument("frames");
    } catch (const std::exception&) {
      problems.push_back("--frames: must be a whole number >= 1 (got '" + it->second + "')");
    }
  }
  const bool timings = flags->values.count("timings") > 0;
  const std::string truth_path = flags->values.count("truth") ? flags->values.at("truth") : "";
  if (!truth_path.empty() && !synthetic) {
    problems.push_back("--truth: only the synthetic source knows the truth");
  }
  Result<pipeline::PipelineConfig> pipeline_config = server::BuildPipelineConfig(config.pipeline());
  if (!pipeline_config.ok()) problems.push_back(pipeline_config.error().message);
  if (!problems.empty()) return Fail(Error::Invalid(problems).message);

  Result<std::unique_ptr<drivers::StereoSource>> source =
      server::OpenSource(config.source(), /*loop_images=*/false);
  if (!source.ok()) return Fail(source.error().message, 1);

  std::ofstream out_file, truth_file;
  if (auto it = flags->values.find("out"); it != flags->values.end()) {
    out_file.open(it->second, std::ios::trunc);
    if (!out_file) return Fail("--out: cannot write " + it->second, 1);
  }
  if (!truth_path.empty()) {
    truth_file.open(truth_path, std::ios::trunc);
    if (!truth_file) return Fail("--truth: cannot write " + truth_path, 1);
  }
  std::ostream& out = out_file.is_open() ? static_cast<std::ostream&>(out_file) : std::cout;

  for (const std::string& note : (*source)->Notes()) std::cerr << "stevi-process: " << note << "\n";
  Result<std::unique_ptr<server::PoseSource>> made = MakePoses(config, **source, synthetic);
  if (!made.ok()) return Fail(made.error().message, 1);
  std::unique_ptr<server::PoseSource> poses = std::move(made).value();
  pipeline::Pipeline pipe;
  pipeline::Snapshot snapshot{
      std::make_shared<const pipeline::PipelineConfig>(std::move(pipeline_config).value()),
      (*source)->Rig()};
  if (poses) {
    snapshot.pose_at = [&poses](int64_t t, int64_t unix_t) { return poses->At(t, unix_t); };
  }
  for (int64_t n = 0; max_frames < 0 || n < max_frames; ++n) {
    Result<StereoFrame> frame = (*source)->Next();
    if (!frame.ok()) {
      if (frame.error().code == ErrorCode::kOutOfRange) break;
      return Fail(frame.error().message, 1);
    }
    snapshot.rig = (*source)->Rig();  // a replay follows the calibration changes it recorded
    Result<pipeline::FrameResult> result = pipe.Process(*frame, snapshot);
    if (!result.ok())
      return Fail("frame " + std::to_string(frame->index) + ": " + result.error().message, 1);
    v1::TrackFrame track_frame = server::ToTrackFrame(*result);
    if (!timings) track_frame.clear_timings();
    out << server::ToJsonLine(track_frame) << "\n";
    if (const drivers::FrameTruth* truth = (*source)->LastTruth();
        truth_file.is_open() && truth != nullptr) {
      truth_file << server::ToJsonLine(server::ToTruthFrame(*truth, frame->t_ns)) << "\n";
    }
  }
  out.flush();
  if (!out) return Fail("cannot write the output", 1);
  return 0;
}
