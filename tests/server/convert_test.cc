#include "server/convert.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/server/proto_fields.h"

namespace stevi::server {
namespace {

using ::testing::HasSubstr;

TEST(ToProto, FillsEveryField) {
  std::vector<std::string> unset;
  proto_fields::UnsetFields(ToProto(pipeline::PipelineConfig{}), "", unset);
  EXPECT_THAT(unset, ::testing::IsEmpty());
}

// One field at a time: every scalar and enum field of PipelineConfig, set alone in an update to a
// valid value other than the default, must arrive in the core config (read back through ToProto).
// A field left out of the core structs' field lists fails here, by name.
TEST(MergeFromProto, EveryFieldSetAloneArrives) {
  using namespace proto_fields;
  const v1::PipelineConfig defaults = ToProto(pipeline::PipelineConfig{});
  const int checked = ExpectEveryLeafArrives<v1::PipelineConfig>(
      defaults, [](const v1::PipelineConfig& update) -> std::optional<v1::PipelineConfig> {
        pipeline::PipelineConfig config;
        if (!MergeFromProto(update, config).empty() || !config.Validate().empty()) {
          return std::nullopt;
        }
        return ToProto(config);
      });
  EXPECT_GT(checked, 100);  // the whole tree was walked
}

// The lists (the saliency scales and radii): the default with its last entry dropped arrives.
TEST(MergeFromProto, EveryListSetAloneArrives) {
  using namespace proto_fields;
  std::vector<std::vector<const FieldDescriptor*>> leaves;
  std::vector<const FieldDescriptor*> prefix;
  Leaves(v1::PipelineConfig::descriptor(), prefix, leaves);
  const v1::PipelineConfig defaults = ToProto(pipeline::PipelineConfig{});
  int lists = 0;
  for (const auto& path : leaves) {
    const std::string name = PathName(path);
    const FieldDescriptor* f = path.back();
    if (!f->is_repeated()) continue;
    ++lists;
    ASSERT_EQ(f->cpp_type(), FieldDescriptor::CPPTYPE_INT32)
        << name << ": a list this test does not know";
    const Message& from = Holder(defaults, path);
    const int size = from.GetReflection()->FieldSize(from, f);
    ASSERT_GE(size, 2) << name;
    v1::PipelineConfig update;
    Message* holder = MutableHolder(&update, path);
    for (int i = 0; i + 1 < size; ++i) {
      holder->GetReflection()->AddInt32(holder, f,
                                        from.GetReflection()->GetRepeatedInt32(from, f, i));
    }
    pipeline::PipelineConfig config;
    ASSERT_THAT(MergeFromProto(update, config), ::testing::IsEmpty()) << name;
    ASSERT_THAT(config.Validate(), ::testing::IsEmpty()) << name;
    const v1::PipelineConfig back = ToProto(config);
    EXPECT_EQ(Holder(back, path).GetReflection()->FieldSize(Holder(back, path), f), size - 1)
        << name;
  }
  EXPECT_EQ(lists, 2);
}

TEST(MergeFromProto, FullRoundTripKeepsEveryField) {
  pipeline::PipelineConfig original;
  original.matcher.kind = stereo::MatcherKind::kSemiGlobal;
  original.matcher.block_matching.block_size = 21;
  original.matcher.block_matching.local_texture_threshold = 0;
  original.matcher.semi_global.p1 = 100;
  original.matcher.semi_global.p2 = 400;
  original.matcher.semi_global.mode = stereo::SemiGlobalOptions::Mode::kHH4;
  original.range.min_disparity_px = 3;
  original.range.max_range_m = 250;
  original.canonical.threshold_range_m = 42;
  original.canonical.open_size_px = 5;
  original.max_width_px = 0;

  pipeline::PipelineConfig copy;  // defaults, then everything from the proto
  EXPECT_THAT(MergeFromProto(ToProto(original), copy), ::testing::IsEmpty());
  EXPECT_EQ(ToProto(copy).SerializeAsString(), ToProto(original).SerializeAsString());
  EXPECT_EQ(copy.matcher.kind, stereo::MatcherKind::kSemiGlobal);
  EXPECT_EQ(copy.matcher.semi_global.mode, stereo::SemiGlobalOptions::Mode::kHH4);
  EXPECT_EQ(copy.canonical.threshold_range_m, 42);
  EXPECT_EQ(copy.max_width_px, 0);  // set to 0 is not "unset"
}

TEST(MergeFromProto, SelectingStixelsWithoutAMatcherKindSelectsTheDenseMatcher) {
  pipeline::PipelineConfig config;
  ASSERT_EQ(config.matcher.kind, stereo::MatcherKind::kBlockMatching);
  v1::PipelineConfig update;
  update.set_algorithm(v1::ALGORITHM_STIXELS);
  ASSERT_TRUE(MergeFromProto(update, config).empty());
  EXPECT_EQ(config.algorithm, pipeline::Algorithm::kStixels);
  EXPECT_EQ(config.matcher.kind, stereo::MatcherKind::kDense);
  // A kind named alongside wins.
  pipeline::PipelineConfig named;
  update.mutable_matcher()->set_kind(v1::MATCHER_KIND_SEMI_GLOBAL);
  ASSERT_TRUE(MergeFromProto(update, named).empty());
  EXPECT_EQ(named.matcher.kind, stereo::MatcherKind::kSemiGlobal);
  // An update that leaves the algorithm alone leaves the matcher alone.
  v1::PipelineConfig other;
  other.mutable_range()->set_max_range_m(50);
  pipeline::PipelineConfig kept;
  ASSERT_TRUE(MergeFromProto(other, kept).empty());
  EXPECT_EQ(kept.matcher.kind, stereo::MatcherKind::kBlockMatching);
}

TEST(MergeFromProto, UnsetFieldsKeepTheirValues) {
  pipeline::PipelineConfig config;
  config.canonical.threshold_range_m = 33;
  config.matcher.block_matching.num_disparities = 96;
  v1::PipelineConfig update;
  update.mutable_canonical()->mutable_blobs()->set_min_area_px(200);
  EXPECT_THAT(MergeFromProto(update, config), ::testing::IsEmpty());
  EXPECT_EQ(config.canonical.blobs.min_area_px, 200);
  EXPECT_EQ(config.canonical.threshold_range_m, 33);
  EXPECT_EQ(config.matcher.block_matching.num_disparities, 96);
  EXPECT_EQ(config.algorithm, pipeline::Algorithm::kCanonical);
}

TEST(MergeFromProto, OutOfRangeEnumsAreNamed) {
  pipeline::PipelineConfig config;
  v1::PipelineConfig update;
  update.set_algorithm(static_cast<v1::Algorithm>(77));
  update.mutable_matcher()->set_kind(static_cast<v1::MatcherKind>(9));
  const std::vector<std::string> problems = MergeFromProto(update, config);
  ASSERT_EQ(problems.size(), 2u);
  EXPECT_THAT(problems[0], HasSubstr("algorithm"));
  EXPECT_THAT(problems[1], HasSubstr("matcher.kind"));
}

TEST(MergeFromProto, FullRoundTripKeepsEveryStevieAndStevisField) {
  pipeline::PipelineConfig original;
  original.algorithm = pipeline::Algorithm::kSteViS;
  detection::SteViEOptions& e = original.stevie;
  e.edges.blur_size = 5;
  e.edges.blur_sigma = 1.25;
  e.edges.canny_low = 33;
  e.edges.canny_high = 150;
  e.edges.canny_aperture = 5;
  e.edges.l2_gradient = false;
  e.morphology.shape = extraction::StructuringShape::kCross;
  e.morphology.close_size = 9;
  e.morphology.fill_holes = false;
  e.ground.enabled = false;
  e.ground.min_support_rows = 33;
  e.ground.margin_fraction = 0.12;
  e.ground.min_row_pixels = 25;
  e.ground.min_mode_px = 3;
  e.blobs.min_area_px = 120;
  e.blobs.interior_erode_px = 2;
  detection::SteViSOptions& s = original.stevis;
  s.saliency.centre_level = 1;
  s.saliency.scales = {1, 3};
  s.saliency.surround_radii = {2, 5, 9};
  s.saliency.uniqueness_weight = false;
  s.saliency.peak_fraction = 0.7;
  s.saliency.min_contrast = 4.5;
  s.segmentation = detection::SteViSOptions::Segmentation::kGraph;
  s.saliency_threshold = 0.25;
  s.morphology.shape = extraction::StructuringShape::kRect;
  s.morphology.open_size = 5;
  s.graph.k = 500;
  s.graph.sigma = 0.8;
  s.graph.min_size = 80;
  s.graph_level = 2;
  s.ground.inlier_px = 2;
  s.ground.min_span_px = 6;
  s.ground.min_row_spread = 0.4;
  s.blobs.max_width_fraction = 0.6;
  s.blobs.max_depth_per_height = 0;
  e.blobs.min_terrain_height_m = 5;
  e.blobs.max_attached_fraction = 0.7;
  e.blobs.join_within_region = false;  // non-defaults: SteViE joins within regions, at any gap
  s.blobs.region_gap_fraction = 3.5;
  original.tracking.kalman.process_noise = 0.5;
  original.tracking.kalman.occluded_measurement_noise = 1e5;
  original.tracking.gates.max_depth_ratio = 1.5;
  original.tracking.gates.max_distance_px = 40;
  original.tracking.confirm_hits = 5;
  original.tracking.delete_misses = 20;
  original.tracking.fading_beta = 0.5;
  original.tracking.min_score = 0.25;
  original.mount.pitch_deg = -30;
  original.mount.lever_arm_m = Eigen::Vector3d(0.5, -0.1, 0.2);

  const v1::PipelineConfig proto = ToProto(original);
  EXPECT_EQ(proto.stevie().morphology().shape(), v1::STRUCTURING_SHAPE_CROSS);
  EXPECT_EQ(proto.stevis().segmentation(), v1::SEGMENTATION_GRAPH);
  EXPECT_THAT(proto.stevis().saliency().surround_radii(), ::testing::ElementsAre(2, 5, 9));

  pipeline::PipelineConfig copy;  // defaults, then everything from the proto
  EXPECT_THAT(MergeFromProto(proto, copy), ::testing::IsEmpty());
  EXPECT_EQ(ToProto(copy).SerializeAsString(), proto.SerializeAsString());
  EXPECT_EQ(copy.algorithm, pipeline::Algorithm::kSteViS);
  EXPECT_EQ(copy.stevie.edges.canny_aperture, 5);
  EXPECT_FALSE(copy.stevie.edges.l2_gradient);
  EXPECT_EQ(copy.stevie.morphology.shape, extraction::StructuringShape::kCross);
  EXPECT_FALSE(copy.stevie.ground.enabled);
  EXPECT_EQ(copy.stevie.blobs.min_area_px, 120);
  EXPECT_EQ(copy.stevis.saliency.scales, (std::vector<int>{1, 3}));
  EXPECT_EQ(copy.stevis.saliency.surround_radii, (std::vector<int>{2, 5, 9}));
  EXPECT_EQ(copy.stevis.segmentation, detection::SteViSOptions::Segmentation::kGraph);
  EXPECT_EQ(copy.stevis.morphology.shape, extraction::StructuringShape::kRect);
  EXPECT_EQ(copy.stevis.morphology.close_size, detection::SteViSOptions().morphology.close_size)
      << "SteViS keeps its own morphology default";
  EXPECT_DOUBLE_EQ(copy.stevis.graph.k, 500);
  EXPECT_EQ(copy.stevis.graph_level, 2);
  EXPECT_DOUBLE_EQ(copy.stevis.blobs.max_width_fraction, 0.6);
  EXPECT_DOUBLE_EQ(copy.stevis.blobs.max_depth_per_height, 0);
  EXPECT_DOUBLE_EQ(copy.stevie.blobs.min_terrain_height_m, 5);
  EXPECT_DOUBLE_EQ(copy.stevie.blobs.max_attached_fraction, 0.7);
  EXPECT_FALSE(copy.stevie.blobs.join_within_region);
  EXPECT_DOUBLE_EQ(copy.stevis.blobs.region_gap_fraction, 3.5);
  EXPECT_TRUE(copy.tracking == original.tracking);
  EXPECT_DOUBLE_EQ(copy.tracking.min_score, 0.25);
  EXPECT_TRUE(copy.mount == original.mount);
  EXPECT_EQ(copy.stevie.ground.min_row_pixels, 25);
  EXPECT_DOUBLE_EQ(copy.stevis.ground.min_row_spread, 0.4);
  EXPECT_THAT(copy.Validate(), ::testing::IsEmpty());
}

TEST(MergeFromProto, UnsetStevieAndStevisFieldsKeepTheirValues) {
  pipeline::PipelineConfig config;
  config.stevie.edges.canny_high = 90;
  config.stevie.morphology.shape = extraction::StructuringShape::kRect;
  config.stevis.segmentation = detection::SteViSOptions::Segmentation::kGraph;
  config.stevis.saliency.scales = {2, 4};
  config.stevis.ground.margin_px = 2;
  v1::PipelineConfig update;
  update.mutable_stevie()->mutable_edges()->set_canny_low(10);
  update.mutable_stevie()->mutable_ground()->set_enabled(false);
  update.mutable_stevis()->mutable_saliency()->add_surround_radii(5);
  update.mutable_stevis()->mutable_blobs()->set_min_area_px(30);
  EXPECT_THAT(MergeFromProto(update, config), ::testing::IsEmpty());
  EXPECT_DOUBLE_EQ(config.stevie.edges.canny_low, 10);
  EXPECT_DOUBLE_EQ(config.stevie.edges.canny_high, 90);
  EXPECT_EQ(config.stevie.morphology.shape, extraction::StructuringShape::kRect)
      << "STRUCTURING_SHAPE_UNSPECIFIED keeps the shape";
  EXPECT_FALSE(config.stevie.ground.enabled);
  EXPECT_EQ(config.stevie.ground.min_support_rows, detection::GroundOptions().min_support_rows);
  EXPECT_EQ(config.stevis.segmentation, detection::SteViSOptions::Segmentation::kGraph)
      << "SEGMENTATION_UNSPECIFIED keeps the mode";
  EXPECT_EQ(config.stevis.saliency.scales, (std::vector<int>{2, 4})) << "an empty list keeps";
  EXPECT_EQ(config.stevis.saliency.surround_radii, (std::vector<int>{5})) << "a list replaces";
  EXPECT_DOUBLE_EQ(config.stevis.ground.margin_px, 2);
  EXPECT_EQ(config.stevis.blobs.min_area_px, 30);
  EXPECT_EQ(config.stevie.blobs.min_area_px, detection::StereoBlobOptions().min_area_px);
  EXPECT_EQ(config.canonical.blobs.min_area_px, detection::StereoBlobOptions().min_area_px);
  EXPECT_EQ(config.stevis.morphology.close_size, detection::SteViSOptions().morphology.close_size);
}

TEST(MergeFromProto, OutOfRangeStevieAndStevisEnumsAreNamed) {
  pipeline::PipelineConfig config;
  v1::PipelineConfig update;
  update.mutable_stevie()->mutable_morphology()->set_shape(static_cast<v1::StructuringShape>(9));
  update.mutable_stevis()->set_segmentation(static_cast<v1::Segmentation>(5));
  update.mutable_stevis()->mutable_morphology()->set_shape(static_cast<v1::StructuringShape>(-1));
  const std::vector<std::string> problems = MergeFromProto(update, config);
  ASSERT_EQ(problems.size(), 3u);
  EXPECT_EQ(problems[0], "stevie.morphology.shape: unknown value 9");
  EXPECT_EQ(problems[1], "stevis.segmentation: unknown value 5");
  EXPECT_EQ(problems[2], "stevis.morphology.shape: unknown value -1");
}

TEST(ToTrackFrame, CopiesEveryTrackWithItsStateAndKinematics) {
  pipeline::FrameResult result;
  result.frame_id = 7;
  result.capture_time_ns = 123456789;
  result.source_index = 41;
  result.timings = {{"disparity", 4.5}, {"total", 9.0}};
  tracking::Track confirmed;
  confirmed.id = 12;
  confirmed.state = tracking::TrackState::kConfirmed;
  confirmed.age_frames = 9;
  confirmed.hits = 8;
  confirmed.detection.bbox = cv::Rect(10, 20, 30, 40);
  confirmed.detection.depth_m = 25;
  confirmed.detection.range_m = 26;
  confirmed.detection.range_sigma_m = 0.4;
  confirmed.detection.disparity_px = 16.8;
  confirmed.detection.score = 0.9;
  confirmed.detection.extractor = "stevie";
  confirmed.position_cam_m = cv::Vec3d(1, -2, 25.1);
  confirmed.velocity_cam_mps = cv::Vec3d(0.5, 0, -10);
  confirmed.position_sigma_m = cv::Vec3d(0.01, 0.01, 0.3);
  confirmed.range_rate_mps = -9.9;
  confirmed.smoothed_range_m = 25.9;
  confirmed.time_to_collision_s = 2.5;
  confirmed.closest_approach_m = 1.2;
  tracking::Track coasting = confirmed;
  coasting.id = 30;
  coasting.state = tracking::TrackState::kCoasting;
  coasting.misses = 2;
  coasting.position_cam_m = cv::Vec3d(0, 3, 4);  // predicted: depth 4, range 5
  coasting.time_to_collision_s.reset();
  coasting.closest_approach_m.reset();
  result.tracks = {confirmed, coasting};

  const v1::TrackFrame f = ToTrackFrame(result);
  EXPECT_EQ(f.frame_id(), 7u);
  EXPECT_EQ(f.capture_time_ns(), 123456789);
  EXPECT_EQ(f.source_index(), 41);
  EXPECT_EQ(f.algorithm(), v1::ALGORITHM_CANONICAL);
  ASSERT_EQ(f.tracks_size(), 2);
  const v1::Track& a = f.tracks(0);
  EXPECT_EQ(a.track_id(), 12u);
  EXPECT_EQ(a.state(), v1::TRACK_STATE_CONFIRMED);
  EXPECT_EQ(a.age_frames(), 9u);
  EXPECT_EQ(a.hits(), 8u);
  EXPECT_EQ(a.misses(), 0u);
  EXPECT_EQ(a.bbox().width(), 30);
  EXPECT_DOUBLE_EQ(a.depth_m(), 25);
  EXPECT_DOUBLE_EQ(a.range_m(), 26);
  EXPECT_DOUBLE_EQ(a.position_cam().z_m(), 25.1);
  EXPECT_DOUBLE_EQ(a.velocity_cam().z_mps(), -10);
  EXPECT_DOUBLE_EQ(a.position_sigma_cam().z_m(), 0.3);
  EXPECT_DOUBLE_EQ(a.range_rate_mps(), -9.9);
  EXPECT_DOUBLE_EQ(a.smoothed_range_m(), 25.9);
  ASSERT_TRUE(a.has_time_to_collision_s());
  EXPECT_DOUBLE_EQ(a.time_to_collision_s(), 2.5);
  EXPECT_DOUBLE_EQ(a.closest_approach_m(), 1.2);
  EXPECT_EQ(a.extractor(), "stevie");
  const v1::Track& b = f.tracks(1);
  EXPECT_EQ(b.state(), v1::TRACK_STATE_COASTING);
  EXPECT_EQ(b.misses(), 2u);
  EXPECT_DOUBLE_EQ(b.depth_m(), 4) << "a coasting track reports its predicted depth";
  EXPECT_DOUBLE_EQ(b.range_m(), 5);
  EXPECT_FALSE(b.has_time_to_collision_s());
  EXPECT_FALSE(b.has_closest_approach_m());
  ASSERT_EQ(f.timings_size(), 2);
  EXPECT_EQ(f.timings(1).stage(), "total");
}

// The boxes' image: the processed one, with the camera's binning.
TEST(ToTrackFrame, NamesTheImageTheBoxesAreIn) {
  pipeline::FrameResult result;
  const geometry::StereoRig camera =
      geometry::StereoRig::Ideal({1280, 1024}, 1400, 0.6, 640, 512, "wide");
  result.rig = std::make_shared<const geometry::StereoRig>(camera.Binned(2));
  result.binning = 2;
  v1::TrackFrame f = ToTrackFrame(result);
  EXPECT_EQ(f.image_width(), 640);
  EXPECT_EQ(f.image_height(), 512);
  EXPECT_EQ(f.binning(), 2);
  EXPECT_EQ(f.calibration_id(), "wide");

  result.rig = std::make_shared<const geometry::StereoRig>(camera);
  result.binning = 1;
  f = ToTrackFrame(result);
  EXPECT_EQ(f.image_width(), 1280);
  EXPECT_EQ(f.binning(), 1);
}

// The range scan and each track's body-frame position, computed in core, are copied as they are.
TEST(ToTrackFrame, CopiesTheRangeScanAndTheTracksBodyPositions) {
  pipeline::FrameResult result;
  tracking::Track a, b;
  a.id = 1;
  b.id = 2;
  result.tracks = {a, b};
  result.track_position_body_m = {cv::Vec3d(10, -2, 0.5), cv::Vec3d(30, 4, -1)};
  detection::RangeScan scan;
  scan.start_azimuth_deg = -25;
  scan.bin_width_deg = 1;
  scan.range_m = {0.0F, 12.5F, 13.0F, 0.0F};
  scan.min_range_m = 6.67;
  scan.max_range_m = 168;
  result.range_scan = scan;
  v1::TrackFrame f = ToTrackFrame(result);
  ASSERT_TRUE(f.has_range_scan());
  EXPECT_DOUBLE_EQ(f.range_scan().start_azimuth_deg(), -25);
  EXPECT_DOUBLE_EQ(f.range_scan().bin_width_deg(), 1);
  EXPECT_THAT(f.range_scan().range_m(), ::testing::ElementsAre(0.0F, 12.5F, 13.0F, 0.0F));
  EXPECT_DOUBLE_EQ(f.range_scan().min_range_m(), 6.67);
  EXPECT_DOUBLE_EQ(f.range_scan().max_range_m(), 168);
  ASSERT_EQ(f.tracks_size(), 2);
  EXPECT_DOUBLE_EQ(f.tracks(0).position_body().x_m(), 10);
  EXPECT_DOUBLE_EQ(f.tracks(0).position_body().y_m(), -2);
  EXPECT_DOUBLE_EQ(f.tracks(1).position_body().z_m(), -1);

  // Without a scan (disabled) or body positions (a result built by hand), neither is set.
  result.range_scan.reset();
  result.track_position_body_m.clear();
  f = ToTrackFrame(result);
  EXPECT_FALSE(f.has_range_scan());
  EXPECT_FALSE(f.tracks(0).has_position_body());
}

TEST(ToJsonLine, UsesProtoFieldNamesOnOneLine) {
  v1::TrackFrame f;
  f.set_frame_id(3);
  f.add_tracks()->set_range_sigma_m(0.5);
  const std::string json = ToJsonLine(f);
  EXPECT_THAT(json, HasSubstr("\"frame_id\""));
  EXPECT_THAT(json, HasSubstr("\"range_sigma_m\""));
  EXPECT_EQ(json.find('\n'), std::string::npos);
}

TEST(VehicleStateConversion, RoundTripsEveryField) {
  geo::VehicleState s;
  s.t_ns = 1'700'000'000'123'456'789;
  s.lat_deg = 43.6839;
  s.lon_deg = 10.3925;
  s.alt_m = 89.5;
  s.roll_deg = -2;
  s.pitch_deg = 3;
  s.yaw_deg = 43;
  s.velocity_ned_mps = Eigen::Vector3d(20, -1, 0.5);
  s.sigma = {1.5, 3.0, 0.2, 0.8};
  const v1::VehicleState p = ToProto(s);
  EXPECT_EQ(p.unix_time_ns(), s.t_ns);
  EXPECT_DOUBLE_EQ(p.position().alt_m(), 89.5);
  EXPECT_DOUBLE_EQ(p.velocity().e_mps(), -1);
  EXPECT_TRUE(FromProto(p) == s);
}

TEST(ToTrackFrame, GeoreferencedTracksCarryTheirPositionAndTheFrameItsStatus) {
  pipeline::FrameResult result;
  tracking::Track a, b;
  a.id = 1;
  b.id = 2;
  result.tracks = {a, b};
  geo::GeoPoint g;
  g.lat_deg = 43.7;
  g.lon_deg = 10.4;
  g.alt_m = 120;
  g.velocity_ned_mps = Eigen::Vector3d(3, 4, -1);
  g.sigma.horizontal_m = 0.6;
  g.sigma.vertical_m = 0.9;
  result.track_geo = {g, std::nullopt};
  geo::PoseLookup lookup;
  lookup.status = geo::GeoStatus::kOk;
  lookup.message = "fixed pose";
  lookup.pose = geo::VehiclePose{};
  lookup.pose->state.lat_deg = 43.6839;
  result.pose = lookup;
  const v1::TrackFrame f = ToTrackFrame(result);
  EXPECT_EQ(f.geo_status(), v1::GEO_STATUS_OK);
  EXPECT_EQ(f.geo_message(), "fixed pose");
  EXPECT_DOUBLE_EQ(f.vehicle().position().lat_deg(), 43.6839);
  ASSERT_EQ(f.tracks_size(), 2);
  ASSERT_TRUE(f.tracks(0).has_geodetic());
  EXPECT_DOUBLE_EQ(f.tracks(0).geodetic().alt_m(), 120);
  EXPECT_DOUBLE_EQ(f.tracks(0).velocity_ned().e_mps(), 4);
  EXPECT_DOUBLE_EQ(f.tracks(0).position_sigma_m().vertical_m(), 0.9);
  EXPECT_FALSE(f.tracks(1).has_geodetic());

  geo::PoseLookup stale;
  stale.status = geo::GeoStatus::kPoseTooOld;
  stale.message = "pose too old (0.82 s)";
  result.pose = stale;
  result.track_geo = {std::nullopt, std::nullopt};
  const v1::TrackFrame g2 = ToTrackFrame(result);
  EXPECT_EQ(g2.geo_status(), v1::GEO_STATUS_POSE_TOO_OLD);
  EXPECT_EQ(g2.geo_message(), "pose too old (0.82 s)");
  EXPECT_FALSE(g2.has_vehicle());
  EXPECT_FALSE(g2.tracks(0).has_geodetic());
}

}  // namespace
}  // namespace stevi::server
