// The track-level scoring (track_level.h) and the odometry scores (odometry_sequence.h) on
// hand-made frames.
#include "tests/testing/track_level.h"

#include <gtest/gtest.h>

#include "tests/testing/odometry_sequence.h"

namespace stevi::testing {
namespace {

TlFrame Frame(bool expected, const std::vector<TlTrack>& tracks) {
  TlFrame f;
  f.truths.push_back({1, cv::Rect(100, 100, 40, 40), expected, true, 50.0});
  f.tracks = tracks;
  return f;
}

TEST(TrackLevelTest, ConfirmedWithinTheWindowCountsFramesFromMeasurable) {
  const TlTrack tentative{7, false, cv::Rect(100, 100, 40, 40), 51.0, 1.0};
  const TlTrack confirmed{7, true, cv::Rect(102, 100, 40, 40), 51.0, 1.0};
  // Not measurable in frame 0; measurable from frame 1; confirmed in frame 3.
  const std::vector<TlFrame> frames = {Frame(false, {tentative}), Frame(true, {tentative}),
                                       Frame(true, {tentative}),  Frame(true, {confirmed}),
                                       Frame(true, {confirmed}),  Frame(true, {confirmed})};
  const TrackLevelTotals t = ScoreTrackLevel(frames);
  EXPECT_EQ(t.obstacles, 1);
  EXPECT_EQ(t.scored, 1);
  EXPECT_EQ(t.confirmed_in_window, 1);
  EXPECT_DOUBLE_EQ(t.MedianFramesToConfirm(), 2.0);
  EXPECT_EQ(t.false_tracks, 0);
  EXPECT_NEAR(t.ErrorOverSigmaRms(), 1.0, 1e-9);
}

TEST(TrackLevelTest, ShortSequenceIsCensoredAndFalseTracksCountOnce) {
  const TlTrack ghost{9, true, cv::Rect(400, 300, 30, 30), 20.0, 1.0};
  const std::vector<TlFrame> frames = {Frame(true, {ghost}), Frame(true, {ghost}),
                                       Frame(true, {ghost})};
  const TrackLevelTotals t = ScoreTrackLevel(frames);
  EXPECT_EQ(t.obstacles, 1);
  EXPECT_EQ(t.scored, 0);
  EXPECT_EQ(t.censored, 1);
  EXPECT_EQ(t.confirmed_tracks, 1);
  EXPECT_EQ(t.false_tracks, 1);
  EXPECT_NEAR(t.FalsePer1000Frames(), 1000.0 / 3, 1e-9);
}

TEST(OdometryScoresTest, HeightAbovePlaneOfALevelCamera) {
  // A level camera 1.65 m up: d = B (v - cy) / h.
  const double f = 700, b = 0.5, cx = 600, cy = 180, h = 1.65;
  GroundPlane plane;
  plane.b = b / h;
  plane.c = -b * cy / h;
  EXPECT_NEAR(HeightAbovePlane(plane, f, b, cx, cy, cv::Vec3d(0, 0, 0)), h, 1e-9);
  EXPECT_NEAR(HeightAbovePlane(plane, f, b, cx, cy, cv::Vec3d(2, h, 20)), 0.0, 1e-9);
  EXPECT_NEAR(HeightAbovePlane(plane, f, b, cx, cy, cv::Vec3d(2, 0.65, 20)), 1.0, 1e-9);
}

TEST(OdometryScoresTest, StaticWorldAndCars) {
  std::vector<CamPose> poses(3);
  for (int k = 0; k < 3; ++k) poses[static_cast<size_t>(k)].t = cv::Vec3d(0, 0, k);
  // A static point 20 m ahead of frame 0's camera, seen as the camera drives 1 m a frame; the
  // last frame's point is 3 m off.
  std::vector<OdoTrackFrame> tracks = {
      {0, 1, cv::Rect(10, 10, 20, 20), cv::Vec3d(0, 0, 20), cv::Vec3d(0.1, 0.1, 0.3)},
      {1, 1, cv::Rect(10, 10, 20, 20), cv::Vec3d(0, 0, 19), cv::Vec3d(0.1, 0.1, 0.3)},
      {2, 1, cv::Rect(10, 10, 20, 20), cv::Vec3d(0, 0, 21), cv::Vec3d(0.1, 0.1, 0.3)}};
  const StaticWorldScore w = ScoreStaticWorld(tracks, poses, StaticWorldOptions{});
  EXPECT_EQ(w.track_frames, 3);
  EXPECT_EQ(w.consistent, 2);
  const std::vector<LabelledBox> labels = {{1, 0, cv::Rect(10, 10, 20, 20)},
                                           {1, 1, cv::Rect(10, 10, 20, 20)},
                                           {1, 2, cv::Rect(12, 10, 20, 20)},
                                           {1, 3, cv::Rect(12, 10, 20, 20)}};
  const std::vector<CarScore> cars = ScoreCars(tracks, labels, 2);
  ASSERT_EQ(cars.size(), 1u);
  EXPECT_EQ(cars[0].scored_frames, 2);
  EXPECT_EQ(cars[0].confirmed_frames, 1);
  EXPECT_EQ(cars[0].confirmed_iou_frames, 1);
  EXPECT_EQ(cars[0].missed, std::vector<int>{3});
}

}  // namespace
}  // namespace stevi::testing
