// A scene description for the synthetic rig. World frame = the left camera's frame at rest:
// x right, y down, z forward, metres. The camera looks along +z; the ground is the plane
// y = camera_height_m.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::drivers {

// How an obstacle moves. Positions are of the box centre, in metres, at scene time t (seconds).
struct Path {
  enum class Kind {
    kStatic,   // stays at `start`
    kLinear,   // start + velocity * t, wrapping back to start every period_s (0 = never)
    kCircle,   // circle in the x-z plane around `start` of radius_m, angular_rate_rad_s, phase_rad
  };
  Kind kind = Kind::kStatic;
  cv::Vec3d start;
  cv::Vec3d velocity_mps;
  double period_s = 0;
  double radius_m = 0;
  double angular_rate_rad_s = 0;
  double phase_rad = 0;

  cv::Vec3d PositionAt(double t_s) const;
};

// An axis-aligned textured box.
struct Obstacle {
  int id = 0;                // > 0, unique in the scene
  std::string name;
  cv::Vec3d size_m;          // x (width), y (height), z (depth)
  Path path;
  double albedo = 0.5;       // mean grey level 0..1 of its texture
  double contrast = 0.35;    // texture contrast 0..1
  double texture_cell_m = 0.15;  // finest texture detail, metres
};

struct Scene {
  double camera_height_m = 40.0;  // the ground plane is y = camera_height_m
  double ground_albedo = 0.45;
  double ground_contrast = 0.3;
  double ground_texture_cell_m = 0.4;
  double sky_top = 0.55;          // grey of the sky at the top row, 0..1
  double sky_horizon = 0.9;       // grey at the horizon
  std::vector<Obstacle> obstacles;

  std::vector<std::string> Validate() const;
};

// The demo scene: a tower and a hangar standing on the ground, and moving aircraft and drones
// (straight and curved paths, two crossing, one passing behind another), all within the range
// where the default rig sees at least 8 px of disparity.
Scene DefaultScene();

}  // namespace stevi::drivers
