// A randomised family of synthetic scenes for an evaluation that cannot be tuned to one scene:
// each scene is a pure function of (family, seed). The evaluation keeps two splits of seeds:
// tuning seeds (1..999) that anyone may look at and tune on, and test seeds (1001..) that nobody
// ever tunes on (see tests/bench/README.md).
//
// Families (every scene: 4..6 frames at 10 fps, 1..5 obstacles moving slowly, a few pixels a
// frame, some pairs partly overlapping in the image at different ranges; sensor noise 1..6 grey
// levels, blur 0..1.5 px half the time, a right gain of 0.85..1.15, vignetting 0..30 % at the
// corners, a vertical misalignment of the right image of -0.5..0.5 px):
//   - "sky": aircraft, drones and balloons against the sky (gradient, often clouds); the camera
//     high up (60..400 m, pitch 0..+12 deg) or low and pitched up (+10..+25 deg); any image size
//     and f 500..2500 px, B 0.2..1 m; ranges 10..800 m.
//   - "airfield": the camera 2..30 m over textured ground (sometimes a runway), pitch -10..+5 deg;
//     towers, poles and buildings standing on the ground, aircraft parked (30 %) or flying, drones;
//     f 400..1600 px, B 0.2..0.8 m; ranges 15..400 m.
//   - "long_range": a telephoto rig (f 2000..6000 px, B 0.3..1 m, 1280x720 to 1920x1200) near the
//     ground (2..20 m, pitch 0..+5 deg); aircraft 200..1500 m away on approach or crossing, and
//     far towers and buildings; hazy: a pale, flat sky and low contrast (0.1..0.5).
//   - "close": a wide-angle rig (f 300..600 px, B 0.1..0.3 m, 640x480 to 1280x720) 1.5..10 m up;
//     drones, poles and small balloons 5..40 m away.
// Every obstacle's disparity (f B / depth of its reference point, at full resolution) is between
// 3 px and width / 12 px, and at least 60 % of its projected bounding box is in frame.
//
// Contrast (0.1..1): the obstacle's albedo (the mean grey of its texture, on the full 0..1 scale)
// differs from the background's grey b (the sky gradient's grey at the obstacle's centre row, or
// the ground's albedo when that row is below the horizon) by c times the largest step possible
// in that direction: albedo = b (1 - c) for a darker obstacle, b + c (1 - b) for a brighter one
// (c = 1: black, or white). Its texture amplitude (Obstacle::contrast) is c times 0.2..0.4, so a
// faint obstacle is also faintly textured. Shading (darker sides and undersides, lit
// ellipsoids), clouds and vignetting come on top.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {

// What the generator chose for one obstacle, at t = 0.
struct RandomObstacleInfo {
  int id = 0;
  std::string kind;         // as Obstacle::kind
  double depth_m = 0;       // camera depth of its reference point (the centre of its bounds)
  double range_m = 0;       // distance of that point from the left camera centre
  double disparity_px = 0;  // f B / depth_m, at full resolution
  double extent_m = 0;      // its largest extent (span, length or height)
  double contrast = 0;      // c, 0.1..1 (see above)
  double grey_step = 0;     // albedo - background grey, full scale, signed
  double background_grey = 0;
  bool standing = false;          // stands on the ground (tower, pole, building, parked aircraft)
  bool overlapping = false;       // placed to overlap an earlier obstacle in the image
  double speed_px_per_frame = 0;  // its reference point's image motion at t = 0
};

struct RandomScene {
  std::string family;
  uint64_t seed = 0;
  Scenario scenario;                          // name "<family>-<seed>"
  std::vector<RandomObstacleInfo> obstacles;  // in the order of scenario.options.scene.obstacles
};

// "sky", "airfield", "long_range", "close".
const std::vector<std::string>& RandomSceneFamilies();

// The scene `seed` of `family` (one of RandomSceneFamilies(); throws std::invalid_argument
// otherwise). Deterministic: the same (family, seed) gives the same scene, frames and truth.
RandomScene GenerateRandomScene(const std::string& family, uint64_t seed);

// GenerateRandomScene(family, seed).scenario.
Scenario RandomScenario(const std::string& family, uint64_t seed);
// The scene of a family picked from the seed.
Scenario RandomScenario(uint64_t seed);

}  // namespace stevi::drivers
