#include "server/app_config.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <optional>
#include <set>

#include "server/field_mapping.h"
#include "server/server_flags.h"
#include "tests/server/proto_fields.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;
using stevi::testing::IsOk;

namespace stevi::server {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;

std::string WriteFile(const std::string& name, const std::string& text) {
  const std::string path = testing::MakeTempDir("stevi-config") + "/" + name;
  std::ofstream(path) << text;
  return path;
}

// stevi-server's command line over `config`: its problem, a bad flag value's, or none.
Status ApplyArgs(std::vector<const char*> args, v1::ServerConfig& config) {
  args.insert(args.begin(), "prog");
  ServerCommandLine line("stevi-server", [](const SettingFlag&) { return true; });
  if (std::string problem = line.Parse(static_cast<int>(args.size()), args.data());
      !problem.empty()) {
    return InvalidArgument(problem);
  }
  return line.ApplyTo(config);
}

TEST(LoadServerConfig, ReadsTextFormat) {
  const std::string path = WriteFile("server.textproto", R"(
    listen: "127.0.0.1:6000"
    source { kind: SOURCE_KIND_SYNTHETIC fps: 25 synthetic { baseline_m: 0.8 } }
    pipeline { canonical { threshold_range_m: 55 } matcher { kind: MATCHER_KIND_SEMI_GLOBAL } }
  )");
  Result<v1::ServerConfig> config = LoadServerConfig(path);
  ASSERT_TRUE(config.ok()) << config.error().message;
  EXPECT_EQ(config->listen(), "127.0.0.1:6000");
  EXPECT_DOUBLE_EQ(config->source().synthetic().baseline_m(), 0.8);
  Result<pipeline::PipelineConfig> pipeline = BuildPipelineConfig(config->pipeline());
  ASSERT_TRUE(pipeline.ok()) << pipeline.error().message;
  EXPECT_DOUBLE_EQ(pipeline->canonical.threshold_range_m, 55);
  EXPECT_EQ(pipeline->matcher.kind, stereo::MatcherKind::kSemiGlobal);
  EXPECT_EQ(pipeline->canonical.blobs.min_area_px, detection::StereoBlobOptions().min_area_px);
}

TEST(LoadServerConfig, ReadsJson) {
  const std::string path = WriteFile(
      "server.json",
      R"({"listen": "127.0.0.1:6001", "pipeline": {"algorithm": "ALGORITHM_CANONICAL"}})");
  Result<v1::ServerConfig> config = LoadServerConfig(path);
  ASSERT_TRUE(config.ok()) << config.error().message;
  EXPECT_EQ(config->listen(), "127.0.0.1:6001");
}

TEST(LoadServerConfig, NamesTheFileLineAndProblem) {
  const std::string path = WriteFile("bad.textproto", "listen: \"x:1\"\nsource { speed: 3 }\n");
  Result<v1::ServerConfig> config = LoadServerConfig(path);
  ASSERT_FALSE(config.ok());
  EXPECT_THAT(config, IsError(ErrorCode::kInvalidArgument));
  EXPECT_THAT(config.error().message,
              AllOf(HasSubstr(path), HasSubstr("line 2"), HasSubstr("speed")));

  Result<v1::ServerConfig> json = LoadServerConfig(WriteFile("bad.json", "{\"listen\": 5,"));
  ASSERT_FALSE(json.ok());
  EXPECT_THAT(json.error().message, HasSubstr("JSON"));

  Result<v1::ServerConfig> missing = LoadServerConfig("/nonexistent/stevi.textproto");
  ASSERT_FALSE(missing.ok());
  EXPECT_THAT(missing, IsError(ErrorCode::kNotFound, HasSubstr("/nonexistent/stevi.textproto")));
}

// Fuzz regression (tests/fuzz/corpus/config/regression-invalid-utf8): the text format parser
// took bytes that are not UTF-8 into string fields, which JSON then dropped ("192.168.1\260.12"
// came back as "192.168.1.12") and binary serialisation refuses.
TEST(ParseConfigText, RefusesStringsThatAreNotUtf8) {
  v1::ServerConfig config;
  const Status raw = ParseConfigText("source { right: \"192.168.1\xb0.12\" }", "config c", config);
  ASSERT_FALSE(raw.ok());
  EXPECT_THAT(raw, IsError(ErrorCode::kInvalidArgument,
                           HasSubstr("config c: source.right: not valid UTF-8")));
  const Status escaped = ParseConfigText(
      "auth { allowed_client_names: \"ok\" allowed_client_names: \"\\355\\240\\200\" }", "config c",
      config);
  ASSERT_FALSE(escaped.ok());
  EXPECT_THAT(escaped.error().message,
              HasSubstr("config c: auth.allowed_client_names[1]: not valid UTF-8"));
  const Status json = ParseConfigText("{\"listen\": \"caf\xc3\"}", "config j", config);
  EXPECT_FALSE(json.ok());

  v1::PipelineConfig pipeline;
  EXPECT_TRUE(ParseConfigText("", "empty", pipeline).ok());
  ASSERT_TRUE(ParseConfigText("source { left: \"caf\xc3\xa9 \xe2\x9c\x93\" }", "c", config).ok());
  EXPECT_EQ(config.source().left(), "caf\xc3\xa9 \xe2\x9c\x93");
}

TEST(BuildPipelineConfig, NamesEveryBadField) {
  v1::PipelineConfig config;
  config.mutable_matcher()->mutable_block_matching()->set_num_disparities(50);
  config.mutable_canonical()->set_threshold_range_m(-1);
  config.mutable_range()->set_min_disparity_px(0);
  config.set_max_width_px(-640);
  Result<pipeline::PipelineConfig> built = BuildPipelineConfig(config);
  ASSERT_FALSE(built.ok());
  EXPECT_THAT(
      built.error().message,
      AllOf(HasSubstr("pipeline.matcher.block_matching.num_disparities"),
            HasSubstr("pipeline.canonical.threshold_range_m"),
            HasSubstr("pipeline.range.min_disparity_px"),
            HasSubstr("pipeline.max_width_px: must be 0 (never bin) or in [64, 16384] pixels "
                      "(got -640)")));
}

TEST(BuildPipelineConfig, ReadsStevieAndStevisFromTextFormat) {
  const std::string path = WriteFile("stevie.textproto", R"(
    pipeline {
      algorithm: ALGORITHM_STEVIE
      stevie { edges { canny_low: 30 } morphology { shape: STRUCTURING_SHAPE_RECT } }
      stevis { segmentation: SEGMENTATION_GRAPH saliency { scales: [1, 2] } graph { k: 400 } }
    }
  )");
  Result<v1::ServerConfig> config = LoadServerConfig(path);
  ASSERT_TRUE(config.ok()) << config.error().message;
  Result<pipeline::PipelineConfig> pipeline = BuildPipelineConfig(config->pipeline());
  ASSERT_TRUE(pipeline.ok()) << pipeline.error().message;
  EXPECT_EQ(pipeline->algorithm, pipeline::Algorithm::kSteViE);
  EXPECT_DOUBLE_EQ(pipeline->stevie.edges.canny_low, 30);
  EXPECT_DOUBLE_EQ(pipeline->stevie.edges.canny_high, extraction::EdgeOptions().canny_high);
  EXPECT_EQ(pipeline->stevie.morphology.shape, extraction::StructuringShape::kRect);
  EXPECT_EQ(pipeline->stevis.segmentation, detection::SteViSOptions::Segmentation::kGraph);
  EXPECT_EQ(pipeline->stevis.saliency.scales, (std::vector<int>{1, 2}));
  EXPECT_EQ(pipeline->stevis.saliency.surround_radii, extraction::SaliencyOptions().surround_radii);
  EXPECT_DOUBLE_EQ(pipeline->stevis.graph.k, 400);
}

TEST(BuildPipelineConfig, NamesBadStevieAndStevisFields) {
  const std::string path = WriteFile("bad-stevis.textproto", R"(
    pipeline {
      algorithm: ALGORITHM_STEVIS
      stevis { saliency_threshold: 0 saliency { surround_radii: [3, 3] } }
      stevie { edges { canny_aperture: 4 } ground { min_support_rows: 1 } }
    }
  )");
  Result<v1::ServerConfig> config = LoadServerConfig(path);
  ASSERT_TRUE(config.ok()) << config.error().message;
  Result<pipeline::PipelineConfig> built = BuildPipelineConfig(config->pipeline());
  ASSERT_FALSE(built.ok());
  EXPECT_THAT(built, IsError(ErrorCode::kInvalidArgument));
  EXPECT_THAT(built.error().message, AllOf(HasSubstr("pipeline.stevis.saliency_threshold"),
                                           HasSubstr("pipeline.stevis.saliency.surround_radii[1]"),
                                           HasSubstr("pipeline.stevie.edges.canny_aperture"),
                                           HasSubstr("pipeline.stevie.ground.min_support_rows")));

  v1::PipelineConfig bad_enum;
  bad_enum.mutable_stevis()->set_segmentation(static_cast<v1::Segmentation>(7));
  Result<pipeline::PipelineConfig> unknown = BuildPipelineConfig(bad_enum);
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.error().message, HasSubstr("pipeline.stevis.segmentation: unknown value 7"));
}

TEST(ServerCommandLine, AcceptsBothSpellingsAndRejectsTheUnknown) {
  v1::ServerConfig config;
  ASSERT_THAT(ApplyArgs({"--listen", "127.0.0.1:7", "--fps=12.5"}, config), IsOk());
  EXPECT_EQ(config.listen(), "127.0.0.1:7");
  EXPECT_DOUBLE_EQ(config.source().fps(), 12.5);
  ASSERT_THAT(ApplyArgs({"--fps", "1", "--fps", "2"}, config), IsOk());
  EXPECT_DOUBLE_EQ(config.source().fps(), 2) << "a later repeat wins, as in every stevi tool";

  EXPECT_THAT(ApplyArgs({"--bogus", "1"}, config),
              IsError(ErrorCode::kInvalidArgument, HasSubstr("'--bogus'")));
  EXPECT_THAT(ApplyArgs({"--listen"}, config),
              IsError(ErrorCode::kInvalidArgument, HasSubstr("--listen: needs a value")));
  EXPECT_THAT(ApplyArgs({"--allow-insecure=yes"}, config),
              IsError(ErrorCode::kInvalidArgument, HasSubstr("--allow-insecure=yes")));
  ServerCommandLine help("stevi-server", [](const SettingFlag&) { return true; });
  const char* args[] = {"prog", "--help", "--bogus"};
  EXPECT_EQ(help.Parse(3, args), "") << "--help ends the walk";
  EXPECT_TRUE(help.help());
}

TEST(ServerCommandLine, OverridesTheFileAndNamesBadValues) {
  v1::ServerConfig config;
  config.set_listen("127.0.0.1:1");
  ASSERT_THAT(
      ApplyArgs({"--listen", "127.0.0.1:2", "--algorithm", "canonical", "--fps", "30"}, config),
      IsOk());
  EXPECT_EQ(config.listen(), "127.0.0.1:2");
  EXPECT_EQ(config.pipeline().algorithm(), v1::ALGORITHM_CANONICAL);
  EXPECT_DOUBLE_EQ(config.source().fps(), 30);

  // Good flags beside bad ones: none is applied (tests/fuzz/flags found the good ones applied).
  const std::string before = config.SerializeAsString();
  const Status applied = ApplyArgs({"--listen", "127.0.0.1:3", "--algorithm", "magic", "--fps",
                                    "-3", "--source", "camera", "--left", "cam7"},
                                   config);
  EXPECT_THAT(applied, IsError(ErrorCode::kInvalidArgument,
                               AllOf(HasSubstr("--algorithm: must be one of canonical, stevie, "
                                               "stevis, stixels (got 'magic')"),
                                     HasSubstr("--fps: must be in (0, 1000] Hz (got '-3')"),
                                     HasSubstr("--source: must be one of synthetic"))));
  EXPECT_EQ(config.listen(), "127.0.0.1:2") << "nothing applied from a bad set of flags";
  EXPECT_EQ(config.SerializeAsString(), before) << "nothing applied from a bad set of flags";
}

TEST(ServerCommandLine, CamerasReplayAndRecording) {
  v1::ServerConfig cameras;
  ASSERT_THAT(ApplyArgs({"--source", "aravis", "--left", "GV01", "--right", "10.0.0.2", "--roi",
                         "800x600", "--exposure-us", "2500", "--gain-db", "0", "--trigger",
                         "hardware:Line1", "--record", "/data/rec", "--timestamps", "host"},
                        cameras),
              IsOk());
  EXPECT_EQ(cameras.source().kind(), v1::SOURCE_KIND_ARAVIS);
  EXPECT_EQ(cameras.source().aravis().width(), 800u);
  EXPECT_EQ(cameras.source().aravis().height(), 600u);
  EXPECT_DOUBLE_EQ(cameras.source().aravis().exposure_us(), 2500);
  EXPECT_TRUE(cameras.source().aravis().has_gain_db());
  EXPECT_EQ(cameras.source().aravis().trigger(), v1::TRIGGER_MODE_HARDWARE);
  EXPECT_EQ(cameras.source().aravis().trigger_line(), "Line1");
  EXPECT_EQ(cameras.source().aravis().timestamps(), v1::TIMESTAMP_SOURCE_HOST);
  EXPECT_EQ(cameras.record().dir(), "/data/rec");
  EXPECT_TRUE(ValidateServerConfig(cameras).empty())
      << ::testing::PrintToString(ValidateServerConfig(cameras));
  v1::ServerConfig free_run;
  ASSERT_THAT(ApplyArgs({"--trigger", "free"}, free_run), IsOk()) << "a choice's first word";
  EXPECT_EQ(free_run.source().aravis().trigger(), v1::TRIGGER_MODE_FREE_RUN);

  v1::ServerConfig replay;
  ASSERT_THAT(ApplyArgs({"--source", "replay", "--replay", "r1", "--rate", "max"}, replay), IsOk());
  EXPECT_EQ(replay.source().kind(), v1::SOURCE_KIND_REPLAY);
  EXPECT_EQ(replay.source().replay().dir(), "r1");
  EXPECT_TRUE(replay.source().replay().has_rate());
  EXPECT_DOUBLE_EQ(replay.source().replay().rate(), 0);

  v1::ServerConfig video;
  ASSERT_THAT(ApplyArgs({"--source", "video", "--layout", "top-bottom", "--size", "640x480",
                         "--latency-ms", "50"},
                        video),
              IsOk());
  EXPECT_EQ(video.source().gst().layout(), v1::GST_LAYOUT_TOP_BOTTOM);
  EXPECT_EQ(video.source().gst().width(), 640);
  EXPECT_EQ(video.source().gst().height(), 480);
  EXPECT_EQ(video.source().gst().latency_ms(), 50u);

  const Status bad = ApplyArgs({"--roi", "640", "--exposure-us", "-1", "--trigger", "manual",
                                "--rate", "fast", "--gain-db", "loud", "--latency-ms", "2.5"},
                               replay);
  EXPECT_THAT(bad, IsError(ErrorCode::kInvalidArgument,
                           AllOf(HasSubstr("--roi: must be WIDTHxHEIGHT, each in [16, 16384] "
                                           "pixels (got '640')"),
                                 HasSubstr("--exposure-us"), HasSubstr("--trigger"),
                                 HasSubstr("--rate"), HasSubstr("--gain-db"),
                                 HasSubstr("--latency-ms: must be in [0, 5000] ms (a whole "
                                           "number) (got '2.5')"))));

  // Cross-field: what each source needs, and ranges.
  v1::ServerConfig incomplete;
  incomplete.mutable_source()->set_kind(v1::SOURCE_KIND_ARAVIS);
  incomplete.mutable_source()->mutable_aravis()->set_trigger(v1::TRIGGER_MODE_HARDWARE);
  incomplete.mutable_source()->mutable_aravis()->set_buffers(1);
  incomplete.mutable_source()->mutable_aravis()->set_frame_rate_hz(0);
  incomplete.mutable_record()->set_max_bytes(1000);
  const std::string problems = ::testing::PrintToString(ValidateServerConfig(incomplete));
  EXPECT_THAT(problems,
              AllOf(HasSubstr("source.left"), HasSubstr("source.right"),
                    HasSubstr("source.aravis.trigger_line"), HasSubstr("source.aravis.buffers"),
                    HasSubstr("source.aravis.frame_rate_hz"), HasSubstr("record.max_bytes")));
  v1::ServerConfig same;
  same.mutable_source()->set_kind(v1::SOURCE_KIND_ARAVIS);
  same.mutable_source()->set_left("GV01");
  same.mutable_source()->set_right("GV01");
  EXPECT_THAT(::testing::PrintToString(ValidateServerConfig(same)),
              HasSubstr("source.right: must be another camera than the left one"));
  v1::ServerConfig nothing;
  nothing.mutable_source()->set_kind(v1::SOURCE_KIND_REPLAY);
  nothing.mutable_source()->set_left("x.png");
  EXPECT_THAT(::testing::PrintToString(ValidateServerConfig(nothing)),
              AllOf(HasSubstr("source.replay.dir"), HasSubstr("do not apply to a replay")));
}

TEST(ValidateServerConfig, ListsEveryCrossFieldProblem) {
  v1::ServerConfig config;
  config.set_listen("nowhere");
  config.mutable_source()->set_kind(v1::SOURCE_KIND_IMAGES);
  config.set_max_streams(0);
  config.set_keepalive_time_s(0.1);
  config.set_keepalive_timeout_s(std::nan(""));
  config.set_pipeline_workers(0);
  config.set_opencv_threads(65);
  const std::vector<std::string> problems = ValidateServerConfig(config);
  const std::string all = ::testing::PrintToString(problems);
  EXPECT_THAT(all, AllOf(HasSubstr("listen"), HasSubstr("source.left"), HasSubstr("source.right"),
                         HasSubstr("source.calibration"), HasSubstr("max_streams"),
                         HasSubstr("keepalive_time_s: must be in [1, 86400] s (got 0.1)"),
                         HasSubstr("keepalive_timeout_s"),
                         HasSubstr("pipeline_workers: must be in [1, 16] (got 0)"),
                         HasSubstr("opencv_threads: must be in [1, 64] (got 65)")));
  config.set_pipeline_workers(17);
  EXPECT_THAT(::testing::PrintToString(ValidateServerConfig(config)),
              HasSubstr("pipeline_workers: must be in [1, 16] (got 17)"));

  v1::ServerConfig fine;
  fine.set_listen("127.0.0.1:0");
  EXPECT_TRUE(ValidateServerConfig(fine).empty());
  fine.set_pipeline_workers(16);
  fine.set_opencv_threads(1);
  EXPECT_TRUE(ValidateServerConfig(fine).empty());
}

TEST(OpenSource, ReportsSyntheticProblemsWithTheirPrefix) {
  v1::SourceConfig config;
  config.mutable_synthetic()->set_width(-5);
  config.mutable_synthetic()->set_baseline_m(0);
  Result<std::unique_ptr<drivers::StereoSource>> source = OpenSource(config, true);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source.error().message,
              AllOf(HasSubstr("source.synthetic"), HasSubstr("width"), HasSubstr("baseline_m")));
}

}  // namespace
}  // namespace stevi::server

namespace stevi::server {
namespace {

// Every field of the source's aravis, synthetic (both scenes) and replay configs, set alone to a
// valid value other than the default, arrives in the drivers' options (read back through their
// field lists). A field missing from a driver's list fails here, by name.
template <class M, class Options>
int ExpectSourceFieldsArrive(void (*place)(const M&, v1::SourceConfig&),
                             Options (*from)(const v1::SourceConfig&, std::vector<std::string>&),
                             const std::set<std::string>& skip,
                             const std::vector<std::string>& texts = {"x"}) {
  v1::SourceConfig base;
  place(M{}, base);
  std::vector<std::string> problems;
  M defaults;
  FieldsToProto(from(base, problems), defaults);
  EXPECT_THAT(problems, ::testing::IsEmpty());
  return proto_fields::ExpectEveryLeafArrives<M>(
      defaults,
      [&](const M& update) -> std::optional<M> {
        v1::SourceConfig source;
        place(update, source);
        std::vector<std::string> found;
        const Options options = from(source, found);
        if (!found.empty() || !options.Validate().empty()) return std::nullopt;
        M back;
        FieldsToProto(options, back);
        return back;
      },
      skip, texts);
}

TEST(SourceOptions, EveryFieldSetAloneArrives) {
  const int aravis = ExpectSourceFieldsArrive<v1::AravisConfig>(
      [](const v1::AravisConfig& a, v1::SourceConfig& s) {
        s.set_left("GV01");
        s.set_right("GV02");
        *s.mutable_aravis() = a;
      },
      &AravisOptionsFrom, {}, {"BayerRG8"});
  EXPECT_EQ(aravis, v1::AravisConfig::descriptor()->field_count());

  const int synthetic = ExpectSourceFieldsArrive<v1::SyntheticConfig>(
      [](const v1::SyntheticConfig& c, v1::SourceConfig& s) { *s.mutable_synthetic() = c; },
      &SyntheticOptionsFrom, {"scene"});
  EXPECT_EQ(synthetic, v1::SyntheticConfig::descriptor()->field_count() - 1);

  const int chessboard = ExpectSourceFieldsArrive<v1::SyntheticConfig>(
      [](const v1::SyntheticConfig& c, v1::SourceConfig& s) {
        *s.mutable_synthetic() = c;
        s.mutable_synthetic()->set_scene("chessboard");
      },
      &ChessboardOptionsFrom, {"scene", "loop_frames"});
  EXPECT_EQ(chessboard, v1::SyntheticConfig::descriptor()->field_count() - 2);

  const int replay = ExpectSourceFieldsArrive<v1::ReplayConfig>(
      [](const v1::ReplayConfig& c, v1::SourceConfig& s) { *s.mutable_replay() = c; },
      &ReplayOptionsFrom, {"dir"});
  EXPECT_EQ(replay, v1::ReplayConfig::descriptor()->field_count() - 1);
}

}  // namespace
}  // namespace stevi::server

namespace stevi::server {
namespace {

// Every SourceConfig.kind value is a kind of the runtime's source factory, by name, and the
// other way round: a kind added to the factory without its proto value (or the reverse) fails.
TEST(SourceKinds, MatchTheProtoValuesOneToOne) {
  const google::protobuf::EnumDescriptor* e = v1::SourceKind_descriptor();
  std::set<std::string> from_proto;
  for (int i = 0; i < e->value_count(); ++i) {
    const auto kind = static_cast<v1::SourceKind>(e->value(i)->number());
    if (kind == v1::SOURCE_KIND_UNSPECIFIED) continue;
    const std::string name = SourceKindName(kind);
    EXPECT_NE(FindSourceKind(name), nullptr) << e->value(i)->name() << " has no factory kind";
    from_proto.insert(name);
  }
  for (const SourceKind& kind : SourceKinds()) {
    EXPECT_EQ(from_proto.count(std::string(kind.name)), 1u) << kind.name << " has no proto value";
  }
  EXPECT_EQ(SourceKindName(v1::SOURCE_KIND_UNSPECIFIED), "synthetic");
}

}  // namespace
}  // namespace stevi::server

namespace stevi::server {
namespace {

// GeoConfig's fields but the fixed pose (a VehicleState, converted on its own) are the pose
// buffer's field list.
TEST(GeoConfig, EveryFieldButThePoseArrives) {
  v1::GeoConfig defaults;
  FieldsToProto(geo::PoseBufferOptions{}, defaults);
  const int checked = proto_fields::ExpectEveryLeafArrives<v1::GeoConfig>(
      defaults,
      [](const v1::GeoConfig& update) -> std::optional<v1::GeoConfig> {
        geo::PoseBufferOptions options;
        if (!FieldsFromProto(update, options, "geo.").empty() || !options.Validate().empty()) {
          return std::nullopt;
        }
        v1::GeoConfig back;
        FieldsToProto(options, back);
        return back;
      },
      {"fixed_pose"});
  EXPECT_EQ(checked, v1::GeoConfig::descriptor()->field_count() - 1);
}

}  // namespace
}  // namespace stevi::server
