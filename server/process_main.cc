// stevi-process: the pipeline in-process over a file or synthetic source, every frame, as JSON
// lines.
#include <fstream>
#include <iostream>
#include <memory>
#include <string>

#include "core/common/allocator.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/scenarios.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/app_config.h"
#include "server/server_flags.h"
#include "server/convert.h"
#include "server/runtime/pose_source.h"
#include "server/runtime/preview_hub.h"
#include "drivers/mcap/flight_log.h"
#include "drivers/recording/replay_source.h"

namespace {

constexpr char kAbout[] =
    R"(Runs the detection pipeline over every frame of a source (no drops) and writes one
stevi.v1.TrackFrame per line as protobuf JSON (proto field names). Sources: synthetic (default),
images, replay (frames, timestamps, vehicle states and calibration as recorded), video or gst (not
live: every frame). Each setting flag sets the config field named after it.)";

// The settings stevi-process takes: the source's and the pipeline's, but no camera's (record
// cameras with stevi-server --record DIR), and the MCAP file's image rate.
bool OfflineSetting(const stevi::server::SettingFlag& flag) {
  const std::string& path = flag.paths.front();
  if (path.rfind("pipeline.", 0) == 0 || path == "record_mcap.image_hz") return true;
  return path.rfind("source.", 0) == 0 && path.rfind("source.aravis.", 0) != 0 &&
         path != "source.gst.device" && path != "source.gst.url" &&
         path != "source.gst.latency_ms" && path != "source.replay.rate";
}

// stevi-process's own flags.
struct ProcessFlags {
  int64_t frames = 0;  // 0: not given
  std::string out, truth, mcap;
  bool timings = false;
};

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

// What stevi-process reads, and how: every frame of a recorded or generated source, in order, as
// fast as it goes (a replay unpaced, a video or gst pipeline not live); no cameras.
void OfflineSource(v1::SourceConfig& source, std::vector<std::string>& problems) {
  const v1::SourceKind kind = source.kind();
  if (kind == v1::SOURCE_KIND_ARAVIS || kind == v1::SOURCE_KIND_UVC ||
      kind == v1::SOURCE_KIND_RTSP) {
    problems.push_back(
        "--source: stevi-process runs recorded or generated frames (synthetic, "
        "images, replay, video, gst); record cameras with stevi-server --record DIR");
  }
  if ((kind == v1::SOURCE_KIND_VIDEO || kind == v1::SOURCE_KIND_GST) && !source.gst().has_live()) {
    source.mutable_gst()->set_live(false);
  }
  if (kind == v1::SOURCE_KIND_REPLAY) source.mutable_replay()->set_rate(0);
}

// One frame into the flight log: its channels, and its images when due (rendered and encoded as
// the server's preview hub does).
Status WriteFlight(drivers::FlightLog& flight, const pipeline::FrameResult& result,
                   const v1::TrackFrame& frame, const server::McapRecordingOptions& options) {
  if (Status s = flight.AddFrame(frame); !s.ok()) return s;
  const std::pair<v1::PreviewKind, server::PreviewKind> kinds[] = {
      {v1::PREVIEW_KIND_LEFT, server::PreviewKind::kLeft},
      {v1::PREVIEW_KIND_DISPARITY, server::PreviewKind::kDisparity}};
  for (const auto& [proto_kind, kind] : kinds) {
    if (!flight.ImageDue(proto_kind, frame)) continue;
    std::optional<server::Preview> image =
        server::EncodePreview(result, kind, options.image_max_width_px, options.image_jpeg_quality);
    if (!image) continue;  // a frame without that image (no disparity yet)
    if (Status s = flight.AddImage(server::ToProto(*image)); !s.ok()) return s;
  }
  return Status::Ok();
}

// Closes the flight log, if any, and says what it holds.
int CloseFlight(drivers::FlightLog* flight) {
  if (flight == nullptr) return 0;
  if (Status s = flight->Close(); !s.ok()) return Fail("--mcap: " + s.error().message, 1);
  const drivers::FlightLogCounts c = flight->counts();
  std::cerr << "stevi-process: wrote " << flight->path() << ": " << c.track_frames << " frames, "
            << c.images << " images, " << c.messages << " messages, " << c.bytes << " bytes\n";
  return 0;
}

// The outputs of --out and --truth (stdout without --out); "" or the problem.
struct Outputs {
  std::ofstream out_file, truth_file;
  std::ostream& out() {
    return out_file.is_open() ? static_cast<std::ostream&>(out_file) : std::cout;
  }
};

std::string OpenOutputs(const ProcessFlags& own, Outputs& outputs) {
  if (!own.out.empty()) {
    outputs.out_file.open(own.out, std::ios::trunc);
    if (!outputs.out_file) return "--out: cannot write " + own.out;
  }
  if (!own.truth.empty()) {
    outputs.truth_file.open(own.truth, std::ios::trunc);
    if (!outputs.truth_file) return "--truth: cannot write " + own.truth;
  }
  return "";
}

// The MCAP flight log of --mcap FILE (the server's record_mcap.file, checked with the config),
// or null without it.
Result<std::unique_ptr<drivers::FlightLog>> OpenFlight(const v1::ServerConfig& config,
                                                       const server::McapRecordingOptions& options,
                                                       const drivers::StereoSource& source) {
  if (!config.has_record_mcap()) return std::unique_ptr<drivers::FlightLog>();
  Result<std::unique_ptr<drivers::FlightLog>> created = drivers::FlightLog::Create(
      options.file, options.log,
      {{"source", source.Describe()}, {"writer", "stevi-process --mcap"}});
  if (!created.ok()) return created.error().Prefixed("--mcap: ");
  return created;
}

int Run(const v1::ServerConfig& config, const ProcessFlags& own, bool synthetic, int64_t max_frames,
        pipeline::PipelineConfig pipeline_config) {
  Result<std::unique_ptr<drivers::StereoSource>> source =
      server::OpenSource(config.source(), /*loop_images=*/false);
  if (!source.ok()) return Fail(source.error().message, 1);
  Outputs outputs;
  if (std::string problem = OpenOutputs(own, outputs); !problem.empty()) return Fail(problem, 1);
  std::ostream& out = outputs.out();
  for (const std::string& note : (*source)->Notes()) std::cerr << "stevi-process: " << note << "\n";
  std::vector<std::string> checked_above;
  const server::McapRecordingOptions mcap_options =
      server::McapRecordingOptionsFrom(config.record_mcap(), checked_above);
  Result<std::unique_ptr<drivers::FlightLog>> opened = OpenFlight(config, mcap_options, **source);
  if (!opened.ok()) return Fail(opened.error().message, 1);
  std::unique_ptr<drivers::FlightLog> flight = std::move(opened).value();
  Result<std::unique_ptr<server::PoseSource>> made = MakePoses(config, **source, synthetic);
  if (!made.ok()) return Fail(made.error().message, 1);
  std::unique_ptr<server::PoseSource> poses = std::move(made).value();
  pipeline::Pipeline pipe;
  pipeline::Snapshot snapshot{
      std::make_shared<const pipeline::PipelineConfig>(std::move(pipeline_config)),
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
    if (!own.timings) track_frame.clear_timings();
    out << server::ToJsonLine(track_frame) << "\n";
    if (flight) {
      if (Status s = WriteFlight(*flight, *result, track_frame, mcap_options); !s.ok()) {
        return Fail("--mcap: " + s.error().message, 1);
      }
    }
    if (const drivers::FrameTruth* truth = (*source)->LastTruth();
        outputs.truth_file.is_open() && truth != nullptr) {
      outputs.truth_file << server::ToJsonLine(server::ToTruthFrame(*truth, frame->t_ns)) << "\n";
    }
  }
  out.flush();
  if (!out) return Fail("cannot write the output", 1);
  return CloseFlight(flight.get());
}

// The command line's config, with its problems checked as the server checks them, and the
// offline source's own rules.
Result<v1::ServerConfig> OfflineConfig(const server::ServerCommandLine& command_line,
                                       const ProcessFlags& own, bool mcap_image_hz_given) {
  Result<v1::ServerConfig> configured = command_line.Config();
  if (!configured.ok()) return configured.error();
  v1::ServerConfig config = std::move(configured).value();
  if (!own.mcap.empty()) config.mutable_record_mcap()->set_file(own.mcap);
  std::vector<std::string> problems = server::ValidateServerConfig(config);
  if (mcap_image_hz_given && !config.record_mcap().has_file()) {
    problems.push_back("--mcap-image-hz: needs --mcap FILE");
  }
  OfflineSource(*config.mutable_source(), problems);
  const v1::SourceKind kind = config.source().kind();
  const bool synthetic = kind == v1::SOURCE_KIND_SYNTHETIC || kind == v1::SOURCE_KIND_UNSPECIFIED;
  if (!own.truth.empty() && !synthetic) {
    problems.push_back("--truth: only the synthetic source knows the truth");
  }
  if (!problems.empty()) return InvalidArgument(problems);
  return config;
}

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  using namespace stevi;
  server::ServerCommandLine command_line("stevi-process", OfflineSetting);
  ProcessFlags own;
  command_line.own()
      .Whole("--frames", {1}, [&own](int64_t n) { own.frames = n; })
      .Text("--out", &own.out)
      .Text("--truth", &own.truth)
      .Text("--mcap", &own.mcap)
      .Switch("--timings", &own.timings);
  command_line.Describe("frames", "N",
                        "process at most N frames (synthetic: default 100; others: all)");
  command_line.Describe("out", "FILE", "write the frames here instead of stdout");
  command_line.Describe("truth", "FILE",
                        "synthetic source: write its truth per frame (stevi.v1.TruthFrame lines)");
  command_line.Describe("mcap", "FILE",
                        "also write the flight as an MCAP file for Foxglove: the station's "
                        "channels and the left and disparity images (FILE must not exist)");
  command_line.Describe("timings", "",
                        "include the stage timings in each frame (wall-clock measurements: "
                        "the output then differs from run to run)");
  if (std::optional<int> exit_code = command_line.ParseOrExit(argc, argv, kAbout)) {
    return *exit_code;
  }
  Result<v1::ServerConfig> configured =
      OfflineConfig(command_line, own, command_line.Given("mcap-image-hz"));
  if (!configured.ok()) return Fail(configured.error().message);
  v1::ServerConfig config = std::move(configured).value();
  const v1::SourceKind kind = config.source().kind();
  const bool synthetic = kind == v1::SOURCE_KIND_SYNTHETIC || kind == v1::SOURCE_KIND_UNSPECIFIED;
  const int64_t max_frames = own.frames > 0 ? own.frames : (synthetic ? 100 : -1);
  Result<pipeline::PipelineConfig> pipeline_config = server::BuildPipelineConfig(config.pipeline());
  if (!pipeline_config.ok()) return Fail(pipeline_config.error().message);
  return Run(config, own, synthetic, max_frames, std::move(pipeline_config).value());
}
