#include "core/pipeline/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/pipeline/annotate.h"
#include "core/pipeline/config.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/truth_match.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::pipeline {
namespace {

// Checks the depth of every detection matched (IoU >= 0.3) to an isolated obstacle whose truth
// disparity is at least 8 px; returns how many were checked. The tolerance is `tol` of the depth,
// or, when quantisation_px > 0 and the disparity is below 16 px, the larger of that and the
// quantisation bound Z^2 / (f B) * quantisation_px.
int ExpectDepthsWithin(const FrameResult& result, const drivers::FrameTruth& truth, double tol,
                       const std::string& label = "", double quantisation_px = 0) {
  const double fb = result.rig->f_px() * result.rig->baseline_m();
  int checked = 0;
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    if (o.bbox.empty() || o.visible_px < 60) continue;
    bool touches = false;
    for (const drivers::ObstacleTruth& other : truth.obstacles) {
      if (other.id != o.id && !other.bbox.empty() &&
          ((o.bbox + cv::Size(2, 2) - cv::Point(1, 1)) & other.bbox).area() > 0) {
        touches = true;
      }
    }
    const double truth_d = testing::MedianOverId(truth.object_id, truth.disparity_px, o.id);
    if (touches || truth_d < 8.0) continue;
    for (const detection::Detection& d : result.detections) {
      if (testing::IoU(d.bbox, o.bbox) < 0.3) continue;
      const double truth_depth = fb / truth_d;
      double allowed = tol * truth_depth;
      if (quantisation_px > 0 && truth_d < 16.0) {
        allowed = std::max(allowed, truth_depth * truth_depth / fb * quantisation_px);
      }
      EXPECT_NEAR(d.depth_m, truth_depth, allowed)
          << label << " frame " << truth.index << " " << o.name;
      ++checked;
    }
  }
  return checked;
}

double TimingMs(const FrameResult& result, const std::string& stage) {
  for (const StageTiming& t : result.timings) {
    if (t.stage == stage) return t.ms;
  }
  return -1;
}

struct Fixture {
  drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  std::shared_ptr<const geometry::StereoRig> rig =
      std::make_shared<const geometry::StereoRig>(renderer.Rig());
};

TEST(PipelineProcess, SyntheticFramesGiveDetectionsAndTimings) {
  Fixture fx;
  ConfigStore store;
  Pipeline pipeline;
  int detections = 0, checked = 0;
  cv::Mat previous_left;
  for (int64_t index : {0, 10, 20}) {
    drivers::FrameTruth truth;
    const StereoFrame frame = fx.renderer.Render(index, &truth);
    Result<FrameResult> result = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
    ASSERT_TRUE(result.ok()) << result.error().message;
    EXPECT_EQ(result->frame_id, static_cast<uint64_t>(index / 10 + 1));
    EXPECT_EQ(result->source_index, frame.index);
    EXPECT_EQ(result->capture_time_ns, frame.t_ns);
    EXPECT_EQ(result->algorithm, Algorithm::kCanonical);
    EXPECT_EQ(result->rig, fx.rig);
    EXPECT_EQ(result->disparity.fixed.size(), fx.rig->image_size());
    ASSERT_EQ(result->rectified_left.type(), CV_8UC1);
    EXPECT_EQ(cv::norm(result->rectified_left, frame.left, cv::NORM_INF), 0.0);
    // The published image is the pipeline's own copy, not the caller's buffer, and not the
    // buffer of the previous result.
    EXPECT_NE(result->rectified_left.data, frame.left.data);
    EXPECT_NE(result->rectified_left.data, previous_left.data);
    previous_left = result->rectified_left;
    std::printf("frame %lld:", static_cast<long long>(index));
    for (const char* stage : {"rectify", "disparity", "extract", "track", "total"}) {
      const double ms = TimingMs(*result, stage);
      EXPECT_GE(ms, 0.0) << stage;
      std::printf(" %s %.2f ms", stage, ms);
    }
    std::printf(", %zu detections\n", result->detections.size());
    EXPECT_GE(TimingMs(*result, "total"), TimingMs(*result, "disparity"));
    detections += static_cast<int>(result->detections.size());
    checked += ExpectDepthsWithin(*result, truth, 0.02);
  }
  EXPECT_GT(detections, 0);
  EXPECT_GT(checked, 0);
}

// Consecutive frames: every detection is tracked, and the obstacles keep their ids from frame to
// frame (the tracker itself is tested in tests/core/tracking).
TEST(PipelineProcess, ConsecutiveFramesKeepTrackIds) {
  Fixture fx;
  ConfigStore store;
  Pipeline pipeline;
  std::map<int, std::map<uint64_t, int>> ids;  // truth id -> track id -> frames
  int confirmed = 0;
  for (int64_t index = 0; index < 12; ++index) {
    drivers::FrameTruth truth;
    const StereoFrame frame = fx.renderer.Render(index, &truth);
    Result<FrameResult> result = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
    ASSERT_TRUE(result.ok()) << result.error().message;
    // Each detection of this frame is tracked: it lies within the box of a track measured in
    // this frame (a track's box also takes in the fragments that join it, and a track hidden
    // behind a nearer one may take its position from the blob that covers both).
    for (const tracking::Track& t : result->tracks) {
      if (t.state == tracking::TrackState::kConfirmed) ++confirmed;
    }
    // (A blob that covers two obstacles is split between their tracks: count the union.)
    cv::Mat1b measured_boxes(frame.left.size(), uchar{0});
    for (const tracking::Track& t : result->tracks) {
      if (t.misses == 0)
        measured_boxes(t.detection.bbox & cv::Rect(cv::Point(), frame.left.size())).setTo(255);
    }
    for (const detection::Detection& d : result->detections) {
      const int covered = cv::countNonZero(measured_boxes(d.bbox));
      EXPECT_GE(covered, 0.5 * d.bbox.area())
          << "frame " << index << ": detection " << d.bbox << " untracked";
    }
    std::vector<cv::Rect> boxes, truth_boxes;
    std::vector<uint64_t> track_ids;
    std::vector<int> truth_ids;
    for (const tracking::Track& t : result->tracks) {
      if (t.misses > 0) continue;
      boxes.push_back(t.detection.bbox);
      track_ids.push_back(t.id);
    }
    for (const drivers::ObstacleTruth& o : truth.obstacles) {
      if (o.visible_px < 300) continue;
      truth_boxes.push_back(o.bbox);
      truth_ids.push_back(o.id);
    }
    for (const auto& [d, t] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
      ++ids[truth_ids[t]][track_ids[d]];
    }
  }
  EXPECT_GT(confirmed, 0);
  ASSERT_FALSE(ids.empty());
  for (const auto& [truth_id, counts] : ids) {
    EXPECT_EQ(counts.size(), 1u) << "obstacle " << truth_id << " changed track id";
  }
}

TEST(PipelineProcess, BadTrackingOptionsAreInvalidArgumentNamingTheField) {
  Fixture fx;
  PipelineConfig config;
  config.tracking.gates.max_depth_ratio = 0.5;
  Pipeline pipeline;
  const StereoFrame frame = fx.renderer.Render(0);
  Result<FrameResult> result =
      pipeline.Process(frame, Snapshot{std::make_shared<const PipelineConfig>(config), fx.rig});
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result, IsError(ErrorCode::kInvalidArgument));
  EXPECT_NE(result.error().message.find("tracking.gates.max_depth_ratio"), std::string::npos)
      << result.error().message;
}

TEST(AnnotateTracks, DrawsEachTrackBoxInItsStateColourAndLeavesTheRest) {
  FrameResult result;
  result.rectified_left = cv::Mat1b(120, 200, uchar{100});
  tracking::Track confirmed, coasting;
  confirmed.id = 7;
  confirmed.state = tracking::TrackState::kConfirmed;
  confirmed.detection.bbox = cv::Rect(20, 60, 40, 30);
  coasting.id = 9;
  coasting.state = tracking::TrackState::kCoasting;
  coasting.detection.bbox = cv::Rect(120, 60, 40, 30);
  coasting.position_cam_m = cv::Vec3d(0, 0, 30);
  result.tracks = {confirmed, coasting};
  const cv::Mat3b out = AnnotateTracks(result);
  ASSERT_EQ(out.size(), result.rectified_left.size());
  EXPECT_EQ(out(89, 40), cv::Vec3b(0, 200, 255)) << "confirmed: the bottom edge, orange";
  EXPECT_EQ(out(89, 140), cv::Vec3b(200, 160, 120)) << "coasting: blue-grey";
  EXPECT_EQ(out(75, 100), cv::Vec3b(100, 100, 100)) << "between the boxes: untouched";
  EXPECT_EQ(out(75, 40), cv::Vec3b(100, 100, 100)) << "inside a box: untouched";
}

TEST(PipelineProcess, WrongSizeIsInvalidArgument) {
  Fixture fx;
  ConfigStore store;
  Pipeline pipeline;
  StereoFrame frame = fx.renderer.Render(0);
  cv::resize(frame.left, frame.left, cv::Size(320, 240));
  Result<FrameResult> result = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result, IsError(ErrorCode::kInvalidArgument));
  EXPECT_NE(result.error().message.find("320x240"), std::string::npos) << result.error().message;
  EXPECT_NE(result.error().message.find("640x480"), std::string::npos) << result.error().message;
  EXPECT_NE(result.error().message.find("left"), std::string::npos) << result.error().message;

  frame.left = cv::Mat();
  result = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result, IsError(ErrorCode::kInvalidArgument));

  // No rig: refused, not a crash.
  result = pipeline.Process(fx.renderer.Render(0), Snapshot{store.Get(), nullptr});
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result, IsError(ErrorCode::kInvalidArgument));
}

// A 1280x960 camera with the field of view of the default 640x480 one (f 1400 px): by default
// (max_width_px 800) the pipeline bins it by 2 and finds the obstacles as well as at 640x480; the
// boxes, tracks, images and rig it publishes are the binned ones. max_width_px 0 processes the
// full frames.
TEST(PipelineProcess, WideFramesAreBinnedAndKeepTheirQuality) {
  drivers::SyntheticOptions options;
  options.width = 1280;
  options.height = 960;
  options.f_px = 1400;
  const drivers::SyntheticRenderer renderer(options);
  const auto rig = std::make_shared<const geometry::StereoRig>(renderer.Rig());
  const double fb = options.f_px * options.baseline_m;

  struct Score {
    int expected = 0, matched = 0, detections = 0, depths = 0;
  };
  const auto run = [&](int max_width_px, Score& score) {
    PipelineConfig config;
    config.algorithm = Algorithm::kSteViE;
    config.max_width_px = max_width_px;
    const Snapshot snapshot{std::make_shared<const PipelineConfig>(config), rig};
    const int k = max_width_px == 0 ? 1 : 2;
    Pipeline pipeline;
    cv::Mat previous_left;
    for (int64_t index = 0; index < 60; index += 6) {
      drivers::FrameTruth truth;
      const StereoFrame frame = renderer.Render(index, &truth);
      Result<FrameResult> result = pipeline.Process(frame, snapshot);
      ASSERT_TRUE(result.ok()) << result.error().message;
      // The published left image is the camera's, binned, in a buffer of its own.
      cv::Mat expected_left;
      geometry::BinImage(frame.left, k, expected_left);
      EXPECT_EQ(cv::norm(result->rectified_left, expected_left, cv::NORM_INF), 0.0);
      EXPECT_NE(result->rectified_left.data, frame.left.data);
      EXPECT_NE(result->rectified_left.data, previous_left.data);
      previous_left = result->rectified_left;
      const cv::Size processed(1280 / k, 960 / k);
      EXPECT_EQ(result->binning, k);
      ASSERT_NE(result->rig, nullptr);
      EXPECT_EQ(result->rig->image_size(), processed);
      EXPECT_DOUBLE_EQ(result->rig->f_px(), 1400.0 / k);
      EXPECT_EQ(result->rig->calibration_id(), rig->calibration_id());
      EXPECT_EQ(result->rectified_left.size(), processed);
      EXPECT_EQ(result->disparity.fixed.size(), processed);
      if (k == 1) {
        EXPECT_EQ(result->rig, rig);
      }
      // The tracks measured this frame carry their detection's box, in the processed pixels.
      for (const tracking::Track& track : result->tracks) {
        if (track.state == tracking::TrackState::kCoasting) continue;
        EXPECT_EQ(track.detection.bbox & cv::Rect(cv::Point(), processed), track.detection.bbox);
      }
      // Boxes in the camera's pixels, scored as stevi-eval does at this size.
      std::vector<cv::Rect> boxes, truth_boxes;
      std::vector<const drivers::ObstacleTruth*> expected;
      for (const detection::Detection& d : result->detections) {
        boxes.emplace_back(d.bbox.x * k, d.bbox.y * k, d.bbox.width * k, d.bbox.height * k);
      }
      for (const drivers::ObstacleTruth& o : truth.obstacles) {
        if (o.visible_px < 400 || fb / o.depth_m < 16.0) continue;
        expected.push_back(&o);
        truth_boxes.push_back(o.bbox);
      }
      score.expected += static_cast<int>(expected.size());
      score.detections += static_cast<int>(boxes.size());
      for (const auto& [d, t] : testing::MatchByIoU(boxes, truth_boxes, 0.3)) {
        ++score.matched;
        if (k == 2) {
          EXPECT_NEAR(result->detections[d].depth_m, expected[t]->depth_m,
                      0.03 * expected[t]->depth_m)
              << "frame " << index << " " << expected[t]->name;
          ++score.depths;
        }
      }
    }
  };
  Score binned, full;
  run(PipelineConfig{}.max_width_px, binned);
  run(0, full);
  std::printf(
      "1280x960 SteViE: binned by 2 (default) %d/%d expected found, %d detections; "
      "unbinned %d/%d found, %d detections\n",
      binned.matched, binned.expected, binned.detections, full.matched, full.expected,
      full.detections);
  ASSERT_GT(binned.expected, 20);
  EXPECT_GE(binned.matched, 0.9 * binned.expected);    // recall
  EXPECT_GE(binned.matched, 0.9 * binned.detections);  // precision
  EXPECT_EQ(binned.depths, binned.matched);
}

TEST(ApplySettings, SetsByPathThenValidatesTheWholeOrChangesNothing) {
  PipelineConfig config;
  EXPECT_THAT(ApplySettings(config, {"algorithm=stixels", "matcher.kind=dense",
                                     "stixels.split=edges", "tracking.confirm_window=7"}),
              ::testing::IsEmpty());
  EXPECT_EQ(config.algorithm, Algorithm::kStixels);
  EXPECT_EQ(config.matcher.kind, stereo::MatcherKind::kDense);
  EXPECT_EQ(config.stixels.split, detection::StixelOptions::Split::kEdges);
  EXPECT_EQ(config.tracking.confirm_window, 7);

  const PipelineConfig before = config;
  EXPECT_THAT(ApplySettings(config, {"algorithm=canonical", "stixels.segment_penalty",
                                     "stixels.nope=1", "max_width_px=10"}),
              ::testing::ElementsAre("'stixels.segment_penalty': expected path=value",
                                     "stixels.nope: no such setting",
                                     "max_width_px: must be 0 (never bin) or in [64, 16384] "
                                     "pixels (got '10')"));
  EXPECT_EQ(config.algorithm, before.algorithm);
  // Each value in bounds, the whole not: refused by the whole's validation.
  EXPECT_THAT(ApplySettings(config, {"matcher.block_matching.num_disparities=50"}),
              ::testing::Not(::testing::IsEmpty()));
  EXPECT_EQ(config.matcher.block_matching.num_disparities,
            before.matcher.block_matching.num_disparities);
}

TEST(ConfigStoreSet, RejectsABadConfigNamingEveryFieldAndKeepsTheActiveOne) {
  PipelineConfig initial;
  initial.canonical.threshold_range_m = 55.0;
  ConfigStore store(initial);
  const std::shared_ptr<const PipelineConfig> before = store.Get();

  PipelineConfig bad;
  bad.matcher.block_matching.num_disparities = 50;  // not a multiple of 16
  bad.canonical.open_size_px = 2;                   // even
  bad.range.min_disparity_px = -1;
  bad.max_width_px = 10;  // neither 0 nor 64..16384
  Result<std::shared_ptr<const PipelineConfig>> set = store.Set(bad);
  ASSERT_FALSE(set.ok());
  EXPECT_THAT(set, IsError(ErrorCode::kInvalidArgument));
  for (const char* field : {"matcher.block_matching.num_disparities", "canonical.open_size_px",
                            "range.min_disparity_px", "max_width_px"}) {
    EXPECT_NE(set.error().message.find(field), std::string::npos)
        << field << " not in: " << set.error().message;
  }
  EXPECT_EQ(store.Get(), before);
  EXPECT_EQ(store.Get()->canonical.threshold_range_m, 55.0);

  // A bad option of another stage is refused too, named with its stage.
  PipelineConfig stevie;
  stevie.algorithm = Algorithm::kSteViE;
  stevie.stevie.edges.canny_aperture = 4;
  set = store.Set(stevie);
  ASSERT_FALSE(set.ok());
  EXPECT_NE(set.error().message.find("stevie.edges.canny_aperture"), std::string::npos)
      << set.error().message;
  EXPECT_EQ(store.Get(), before);

  PipelineConfig good;
  good.canonical.threshold_range_m = 70.0;
  set = store.Set(good);
  ASSERT_TRUE(set.ok()) << set.error().message;
  EXPECT_EQ(store.Get(), *set);
  EXPECT_EQ(store.Get()->canonical.threshold_range_m, 70.0);
  EXPECT_EQ(before->canonical.threshold_range_m, 55.0);  // the old snapshot is untouched
}

TEST(PipelineProcess, SwitchingTheMatcherBetweenFramesTakesEffect) {
  Fixture fx;
  ConfigStore store;
  Pipeline pipeline;
  drivers::FrameTruth truth;
  const StereoFrame frame = fx.renderer.Render(5, &truth);

  Result<FrameResult> bm = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
  ASSERT_TRUE(bm.ok()) << bm.error().message;

  PipelineConfig sgbm_config;
  sgbm_config.matcher.kind = stereo::MatcherKind::kSemiGlobal;
  ASSERT_TRUE(store.Set(sgbm_config).ok());
  Result<FrameResult> sgbm = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
  ASSERT_TRUE(sgbm.ok()) << sgbm.error().message;

  // A different matcher gives a different disparity map of the same frame.
  EXPECT_GT(cv::norm(bm->disparity.fixed, sgbm->disparity.fixed, cv::NORM_L1), 0.0);
  EXPECT_GT(ExpectDepthsWithin(*bm, truth, 0.02, "BM"), 0);
  // OpenCV's SGBM pulls sub-pixel disparities towards whole pixels by up to about 0.2 px (measured
  // in the matcher tests), which at 8.75 px is 2.2 %: below 16 px it is held to the quantisation
  // bound with a quarter pixel (the default range.disparity_sigma_px) instead of 2 %.
  EXPECT_GT(ExpectDepthsWithin(*sgbm, truth, 0.02, "SGBM", 0.25), 0);

  // Back to block matching: the same result as the first time (the matcher was rebuilt).
  ASSERT_TRUE(store.Set(PipelineConfig{}).ok());
  Result<FrameResult> bm_again = pipeline.Process(frame, Snapshot{store.Get(), fx.rig});
  ASSERT_TRUE(bm_again.ok());
  EXPECT_EQ(cv::norm(bm->disparity.fixed, bm_again->disparity.fixed, cv::NORM_INF), 0.0);
  EXPECT_EQ(bm_again->frame_id, 3u);
}

TEST(AlgorithmFromName, RoundTripsAndIgnoresCase) {
  for (Algorithm a : {Algorithm::kCanonical, Algorithm::kSteViE, Algorithm::kSteViS}) {
    const std::optional<Algorithm> back = AlgorithmFromName(AlgorithmName(a));
    ASSERT_TRUE(back.has_value()) << AlgorithmName(a);
    EXPECT_EQ(*back, a);
  }
  EXPECT_EQ(AlgorithmFromName("SteViE"), Algorithm::kSteViE);
  EXPECT_EQ(AlgorithmFromName("CANONICAL"), Algorithm::kCanonical);
  EXPECT_FALSE(AlgorithmFromName("canon").has_value());
  EXPECT_FALSE(AlgorithmFromName("").has_value());
}

}  // namespace
}  // namespace stevi::pipeline
