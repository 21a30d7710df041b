// The randomised scene families: reproducible from the seed, covering the ranges they promise,
// and with truth consistent with what the generator placed.
#include "drivers/synthetic/random_scenes.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "tests/testing/truth_match.h"
#include "tests/drivers/synthetic/frame_hash.h"

namespace stevi::drivers {
namespace {

using fixtures::HashFrame;
using fixtures::kFnvOffset;

// Hash of frame `index`: both images and the truth maps.
uint64_t FrameHash(const Scenario& s, int64_t index, FrameTruth* truth_out = nullptr) {
  const SyntheticRenderer renderer(s.options);
  FrameTruth truth;
  const StereoFrame f = renderer.Render(index, &truth);
  const uint64_t h = HashFrame(kFnvOffset, f, truth);
  if (truth_out != nullptr) *truth_out = truth;
  return h;
}

TEST(RandomScenes, TheSameSeedGivesTheSameFramesAndTruth) {
  for (const std::string& family : RandomSceneFamilies()) {
    const Scenario a = RandomScenario(family, 17);
    const Scenario b = RandomScenario(family, 17);
    FrameTruth ta, tb;
    EXPECT_EQ(FrameHash(a, a.frames - 1, &ta), FrameHash(b, b.frames - 1, &tb)) << family;
    ASSERT_EQ(ta.obstacles.size(), tb.obstacles.size());
    for (size_t i = 0; i < ta.obstacles.size(); ++i) {
      EXPECT_EQ(ta.obstacles[i].bbox, tb.obstacles[i].bbox);
      EXPECT_EQ(ta.obstacles[i].median_disparity_px, tb.obstacles[i].median_disparity_px);
      EXPECT_EQ(ta.obstacles[i].kind, tb.obstacles[i].kind);
    }
  }
}

TEST(RandomScenes, DifferentSeedsAndFamiliesDiffer) {
  std::set<uint64_t> hashes;
  std::set<std::string> descriptions;
  int n = 0;
  for (const std::string& family : RandomSceneFamilies()) {
    for (uint64_t seed : {1u, 2u, 3u}) {
      const Scenario s = RandomScenario(family, seed);
      descriptions.insert(s.description);
      hashes.insert(FrameHash(s, 0));
      ++n;
    }
  }
  EXPECT_EQ(static_cast<int>(hashes.size()), n);
  EXPECT_EQ(static_cast<int>(descriptions.size()), n);
  // RandomScenario(seed) picks a family from the seed: several over 40 seeds.
  std::set<std::string> picked;
  for (uint64_t seed = 1; seed <= 40; ++seed) {
    const std::string name = RandomScenario(seed).name;
    picked.insert(name.substr(0, name.rfind('-')));
  }
  EXPECT_EQ(picked.size(), RandomSceneFamilies().size());
}

TEST(RandomScenes, ParametersCoverTheRanges) {
  double f_min = 1e9, f_max = 0, b_min = 1e9, b_max = 0, noise_min = 1e9, noise_max = 0;
  double contrast_min = 1e9, contrast_max = 0, step_min = 1e9, step_max = -1e9;
  double range_min = 1e9, range_max = 0, extent_min = 1e9, extent_max = 0;
  double gain_min = 1e9, gain_max = 0, vig_max = 0, shift_min = 1e9, shift_max = -1e9;
  double pitch_min = 1e9, pitch_max = -1e9, height_min = 1e9, height_max = 0;
  double blur_max = 0, cell_min = 1e9, cell_max = 0, ground_c_min = 1e9, ground_c_max = 0;
  int blurred = 0, sharp = 0, clouded = 0, overlapping = 0, scenes = 0;
  std::set<std::string> kinds, families;
  std::set<std::pair<int, int>> sizes;
  std::map<size_t, int> obstacle_counts;
  for (const std::string& family : RandomSceneFamilies()) {
    for (uint64_t seed = 1; seed <= 200; ++seed) {
      const RandomScene r = GenerateRandomScene(family, seed);
      const SyntheticOptions& o = r.scenario.options;
      const Scene& sc = o.scene;
      ASSERT_TRUE(o.Validate().empty()) << r.scenario.name << ": " << o.Validate().front();
      ASSERT_EQ(r.obstacles.size(), sc.obstacles.size());
      ++scenes;
      families.insert(r.family);
      EXPECT_GE(r.scenario.frames, 4);
      EXPECT_LE(r.scenario.frames, 6);
      EXPECT_EQ(o.fps, 10.0);
      f_min = std::min(f_min, o.f_px);
      f_max = std::max(f_max, o.f_px);
      b_min = std::min(b_min, o.baseline_m);
      b_max = std::max(b_max, o.baseline_m);
      noise_min = std::min(noise_min, o.noise_sigma);
      noise_max = std::max(noise_max, o.noise_sigma);
      gain_min = std::min(gain_min, o.right_gain);
      gain_max = std::max(gain_max, o.right_gain);
      vig_max = std::max(vig_max, o.vignetting);
      shift_min = std::min(shift_min, o.right_vertical_shift_px);
      shift_max = std::max(shift_max, o.right_vertical_shift_px);
      pitch_min = std::min(pitch_min, sc.camera_pitch_deg);
      pitch_max = std::max(pitch_max, sc.camera_pitch_deg);
      height_min = std::min(height_min, sc.camera_height_m);
      height_max = std::max(height_max, sc.camera_height_m);
      cell_min = std::min(cell_min, sc.ground_texture_cell_m);
      cell_max = std::max(cell_max, sc.ground_texture_cell_m);
      ground_c_min = std::min(ground_c_min, sc.ground_contrast);
      ground_c_max = std::max(ground_c_max, sc.ground_contrast);
      blur_max = std::max(blur_max, o.blur_sigma_px);
      (o.blur_sigma_px > 0 ? blurred : sharp) += 1;
      clouded += sc.cloud_cover > 0 ? 1 : 0;
      sizes.insert({o.width, o.height});
      ++obstacle_counts[sc.obstacles.size()];
      for (const RandomObstacleInfo& info : r.obstacles) {
        kinds.insert(info.kind);
        // The disparity rule at full resolution.
        EXPECT_GE(info.disparity_px, 3.0) << r.scenario.name;
        EXPECT_LE(info.disparity_px, o.width / 12.0 + 1e-9) << r.scenario.name;
        EXPECT_NEAR(info.disparity_px, o.f_px * o.baseline_m / info.depth_m, 1e-9);
        contrast_min = std::min(contrast_min, info.contrast);
        contrast_max = std::max(contrast_max, info.contrast);
        step_min = std::min(step_min, info.grey_step);
        step_max = std::max(step_max, info.grey_step);
        range_min = std::min(range_min, info.range_m);
        range_max = std::max(range_max, info.range_m);
        extent_min = std::min(extent_min, info.extent_m);
        extent_max = std::max(extent_max, info.extent_m);
        overlapping += info.overlapping ? 1 : 0;
      }
    }
  }
  EXPECT_EQ(families.size(), 4u);
  EXPECT_LE(f_min, 330.0);
  EXPECT_GE(f_max, 5000.0);
  EXPECT_LE(b_min, 0.12);
  EXPECT_GE(b_max, 0.95);
  EXPECT_LE(noise_min, 1.2);
  EXPECT_GE(noise_max, 5.8);
  EXPECT_LE(contrast_min, 0.12);
  EXPECT_GE(contrast_max, 0.95);
  EXPECT_LE(step_min, -0.6);  // dark obstacles against bright backgrounds
  EXPECT_GE(step_max, 0.3);   // and bright ones
  EXPECT_LE(range_min, 6.0);
  EXPECT_GE(range_max, 1300.0);
  EXPECT_LE(extent_min, 0.6);
  EXPECT_GE(extent_max, 60.0);
  EXPECT_LE(gain_min, 0.87);
  EXPECT_GE(gain_max, 1.13);
  EXPECT_GE(vig_max, 0.28);
  EXPECT_LE(shift_min, -0.45);
  EXPECT_GE(shift_max, 0.45);
  EXPECT_LE(pitch_min, -9.0);
  EXPECT_GE(pitch_max, 22.0);
  EXPECT_LE(height_min, 2.5);
  EXPECT_GE(height_max, 300.0);
  EXPECT_LE(cell_min, 0.1);
  EXPECT_GE(cell_max, 1.2);
  EXPECT_LE(ground_c_min, 0.06);
  EXPECT_GE(ground_c_max, 0.4);
  EXPECT_GE(blur_max, 1.3);
  EXPECT_GT(blurred, scenes / 4);
  EXPECT_GT(sharp, scenes / 4);
  EXPECT_GT(clouded, scenes / 3);
  EXPECT_GT(overlapping, scenes / 20);
  for (const char* kind : {"aircraft", "drone", "tower", "pole", "building", "balloon"}) {
    EXPECT_TRUE(kinds.count(kind)) << kind;
  }
  const std::set<std::pair<int, int>> all_sizes = {{640, 480},   {752, 480},  {800, 600},
                                                   {1024, 768},  {1280, 720}, {1280, 1024},
                                                   {1920, 1080}, {1920, 1200}};
  EXPECT_EQ(sizes, all_sizes);
  for (size_t n = 1; n <= 5; ++n) EXPECT_GT(obstacle_counts[n], 0) << n << " obstacles";
  EXPECT_EQ(obstacle_counts[0], 0);
}

// Rendered, the obstacles are where the generator put them: visible, mostly in frame, their
// truth median disparity near f B / depth (the visible surface is a little nearer than the
// centre of the bounds), the truth maps agree with the per-obstacle truth, and they move.
TEST(RandomScenes, TruthIsConsistentWithThePlacement) {
  int obstacles = 0, visible = 0, moved = 0, moving = 0;
  for (const std::string& family : RandomSceneFamilies()) {
    for (uint64_t seed = 1; seed <= 6; ++seed) {
      const RandomScene r = GenerateRandomScene(family, seed);
      const SyntheticRenderer renderer(r.scenario.options);
      const FrameTruth first = renderer.Truth(0);
      const FrameTruth last = renderer.Truth(r.scenario.frames - 1);
      ASSERT_EQ(first.obstacles.size(), r.obstacles.size());
      for (size_t i = 0; i < r.obstacles.size(); ++i) {
        const ObstacleTruth& t = first.obstacles[i];
        const RandomObstacleInfo& info = r.obstacles[i];
        ++obstacles;
        EXPECT_EQ(t.kind, info.kind);
        if (t.visible_px == 0) continue;  // hidden behind a nearer one
        ++visible;
        EXPECT_DOUBLE_EQ(t.median_disparity_px,
                         testing::MedianOverId(first.object_id, first.disparity_px, t.id));
        EXPECT_GT(t.median_disparity_px, 0.8 * info.disparity_px) << r.scenario.name << " " << i;
        EXPECT_LT(t.median_disparity_px, 3.0 * info.disparity_px) << r.scenario.name << " " << i;
        if (info.speed_px_per_frame >= 0.5) {
          ++moving;
          const ObstacleTruth& e = last.obstacles[i];
          const double du = (e.bbox.x + e.bbox.width / 2.0) - (t.bbox.x + t.bbox.width / 2.0);
          const double dv = (e.bbox.y + e.bbox.height / 2.0) - (t.bbox.y + t.bbox.height / 2.0);
          if (std::hypot(du, dv) >= 1.0) ++moved;
        }
      }
    }
  }
  EXPECT_GT(visible, obstacles * 8 / 10);
  EXPECT_GT(moved, moving * 8 / 10);
}

}  // namespace
}  // namespace stevi::drivers
