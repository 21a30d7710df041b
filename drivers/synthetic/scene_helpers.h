// Building blocks of the synthetic scenarios, shared by scene.cc (the detection scenarios) and
// tracking_scenarios.cc. Internal to drivers/synthetic: not part of the drivers' interface.
#pragma once

#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "drivers/synthetic/scene.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {

// An obstacle: id (> 0), name, size (x width, y height, z depth; metres), path, and texture
// (mean grey 0..1, contrast 0..1, finest detail in metres).
// SplitMix64's output function: a well-mixed 64-bit hash of x (seeds, textures, noise).
inline uint64_t SplitMix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

Obstacle MakeObstacle(int id, std::string name, cv::Vec3d size_m, Path path, double albedo,
                      double contrast, double cell_m);

// A path that stays at `centre` (metres).
Path Fixed(cv::Vec3d centre);

// Straight flight of the box centre from `start` to `end` (metres) over period_s seconds, then
// back to `start` and again.
Path Leg(cv::Vec3d start, cv::Vec3d end, double period_s);

// A circle in the x-z plane around `centre` (metres), once every period_s seconds, starting at
// phase_rad (0 = +x of the centre).
Path Circle(cv::Vec3d centre, double radius_m, double period_s, double phase_rad);

// The options of an evaluation scenario: the default rig (640x480, f = 700 px, B = 0.6 m,
// 10 fps), pixel noise of 2 grey levels, `seed` and `scene`.
SyntheticOptions ScenarioOptions(uint64_t seed, Scene scene);

// An evaluation scenario: `name`, `frames` long, with ScenarioOptions(seed, scene) and the
// `description` of what is in it and what makes it hard.
Scenario MakeScenario(std::string name, uint64_t seed, Scene scene, int frames,
                      std::string description);

}  // namespace stevi::drivers
