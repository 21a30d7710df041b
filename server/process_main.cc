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
#include "server/runtime/preview_hub.h"
#include "drivers/mcap/flight_log.h"
#include "drivers/recording/replay_source.h"

namespace {

constexpr char kUsage[] = R"(usage: stevi-process [flags]

Runs the detection pipeline over every frame of a source (no drops) and writes one
stevi.v1.TrackFrame per line as protobuf JSON (proto field names).

  --source KIND          synthetic (default), images, replay, video or gst
  --replay DIR           replay: a recording (stevi-server --record DIR or StartRecording); its
                         frames, timestamps, vehicle states and calibration are used as recorded,
                         so that the same recording and config always give the same output
  --left PATTERN|VIDEO   images: left images as a printf pattern ("left_%04d.png") or a video file
  --right PATTERN|VIDEO  images: right images, likewise
  --calibration FILE     images, video, gst: calibration YAML (OpenCV FileStorage)
  --file VIDEO           video: a video file with both views (--layout side-by-side, the
                         default, or top-bottom; two: --left and --right files)
  --layout L             video, gst: side-by-side, top-bottom or two
  --size WxH             video, gst: the size of one view expected (default: as it comes)
  --pipeline P           gst: a gst-launch-1.0 pipeline up to the frames (not live: every frame)
  --fps N                the sequence's frame rate, for capture times (default 10)
  --algorithm NAME       canonical (default), stevie or stevis
  --config FILE          stevi.v1.ServerConfig (text format or JSON): its source and pipeline
  --frames N             process at most N frames (synthetic: default 100; images: all)
  --out FILE             write the frames here instead of stdout
  --mcap FILE            also write the flight as an MCAP file for Foxglove: the station's
                         channels (tracks, annotations, scene, vehicle) and the left and
                         disparity images (FILE must not exist)
  --mcap-image-hz N      images per second of each kind in the MCAP file, on capture time
                         (default 5; 0 = none)
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

// --frames N (>= 1); by default 100 of the endless synthetic rig, all of the others (-1).
int64_t MaxFrames(const server::Flags& flags, bool synthetic, std::vector<std::string>& problems) {
  int64_t max_frames = synthetic ? 100 : -1;
  if (auto it = flags.values.find("frames"); it != flags.values.end()) {
    try {
      size_t used = 0;
      max_frames = std::stoll(it->second, &used);
      if (used != it->second.size() || max_frames < 1) throw std::invalid_argument("frames");
    } catch (const std::exception&) {
      problems.push_back("--frames: must be a whole number >= 1 (got '" + it->second + "')");
    }
  }
  return max_frames;
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

}  // namespace

int main(int argc, char** argv) {
  stevi::KeepFrameMemory();  // first: before any thread starts
  using namespace stevi;
  const std::set<std::string> known = {
      "source", "left",     "right",         "calibration",    "fps",  "algorithm",     "config",
      "frames", "out",      "truth",         "replay",         "mcap", "mcap-image-hz", "layout",
      "file",   "pipeline", "left-pipeline", "right-pipeline", "size"};
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
  if (auto it = flags->values.find("mcap"); it != flags->values.end()) {
    config.mutable_record_mcap()->set_file(it->second);
  }
  std::vector<std::string> problems = server::ValidateServerConfig(config);
  if (flags->values.count("mcap-image-hz") && !config.record_mcap().has_file()) {
    problems.push_back("--mcap-image-hz: needs --mcap FILE");
  }
  const v1::SourceKind kind = config.source().kind();
  OfflineSource(*config.mutable_source(), problems);
  const bool synthetic = kind == v1::SOURCE_KIND_SYNTHETIC || kind == v1::SOURCE_KIND_UNSPECIFIED;
  const int64_t max_frames = MaxFrames(*flags, synthetic, problems);
  const bool timings = flags->values.count("timings") > 0;
  const std::string truth_path = flags->values.count("truth") ? flags->values.at("truth") : "";
  if (!truth_path.empty() && !synthetic) {
    problems.push_back("--truth: only the synthetic source knows the truth");
  }
  Result<pipeline::PipelineConfig> pipeline_config = server::BuildPipelineConfig(config.pipeline());
  if (!pipeline_config.ok()) problems.push_back(pipeline_config.error().message);
  if (!problems.empty()) return Fail(InvalidArgument(problems).message);

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
  // The MCAP flight log: --mcap FILE is the server's record_mcap.file (--mcap-image-hz is the
  // server's flag), checked by ValidateServerConfig above.
  std::vector<std::string> checked_above;
  const server::McapRecordingOptions mcap_options =
      server::McapRecordingOptionsFrom(config.record_mcap(), checked_above);
  std::unique_ptr<drivers::FlightLog> flight;
  if (config.has_record_mcap()) {
    Result<std::unique_ptr<drivers::FlightLog>> created = drivers::FlightLog::Create(
        mcap_options.file, mcap_options.log,
        {{"source", (*source)->Describe()}, {"writer", "stevi-process --mcap"}});
    if (!created.ok()) return Fail("--mcap: " + created.error().message, 1);
    flight = std::move(created).value();
  }
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
    if (flight) {
      if (Status s = WriteFlight(*flight, *result, track_frame, mcap_options); !s.ok()) {
        return Fail("--mcap: " + s.error().message, 1);
      }
    }
    if (const drivers::FrameTruth* truth = (*source)->LastTruth();
        truth_file.is_open() && truth != nullptr) {
      truth_file << server::ToJsonLine(server::ToTruthFrame(*truth, frame->t_ns)) << "\n";
    }
  }
  out.flush();
  if (!out) return Fail("cannot write the output", 1);
  if (flight) {
    if (Status s = flight->Close(); !s.ok()) return Fail("--mcap: " + s.error().message, 1);
    const drivers::FlightLogCounts c = flight->counts();
    std::cerr << "stevi-process: wrote " << flight->path() << ": " << c.track_frames << " frames, "
              << c.images << " images, " << c.messages << " messages, " << c.bytes << " bytes\n";
  }
  return 0;
}
