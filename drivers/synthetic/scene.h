// A scene description for the synthetic rig. World frame = the left camera's centre at rest,
// level: x right, y down, z forward, metres. The camera looks along +z pitched up by
// Scene::camera_pitch_deg (0 = level; roll is always 0, and both views are pitched alike, so
// the rig stays rectified); the ground is the world plane y = camera_height_m. Besides the
// obstacles (boxes, or composites of boxes and ellipsoids: the only things with an obstacle id),
// the ground may carry hills (half-buried ellipsoids) and flat painted marks: they are terrain,
// object_id 0 in the truth, like the ground. The sky (object_id -1, disparity 0) is a vertical
// gradient with optional clouds at infinity.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::drivers {

// How an obstacle moves. Positions are of the box centre, in metres, at scene time t (seconds).
struct Path {
  enum class Kind {
    kStatic,  // stays at `start`
    kLinear,  // start + velocity * t, wrapping back to start every period_s (0 = never)
    kCircle,  // circle in the x-z plane around `start` of radius_m, angular_rate_rad_s, phase_rad
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

// One solid of a composite obstacle: an axis-aligned box or an axis-aligned ellipsoid, centred
// at offset_m from the obstacle's position (its path), with full extents size_m (an ellipsoid's
// diameters). Parts share the obstacle's id, albedo and texture.
struct ObstaclePart {
  enum class Shape { kBox, kEllipsoid };
  Shape shape = Shape::kBox;
  cv::Vec3d offset_m{0.0, 0.0, 0.0};
  cv::Vec3d size_m{1.0, 1.0, 1.0};  // every side > 0
};

// An obstacle: an axis-aligned textured box of size_m centred on its path (parts empty, the
// classic), or a composite of parts (size_m is then unused): an aircraft, a drone, a tower...
// Boxes are shaded by face orientation (edges show); ellipsoids are lit from above like hills.
struct Obstacle {
  int id = 0;  // > 0, unique in the scene
  std::string name;
  cv::Vec3d size_m;  // x (width), y (height), z (depth); parts empty only
  Path path;
  double albedo = 0.5;           // mean grey level 0..1 of its texture
  double contrast = 0.35;        // texture contrast 0..1
  double texture_cell_m = 0.15;  // finest texture detail, metres
  // What it is, copied to the truth: "box", "aircraft", "drone", "tower", "pole", "building",
  // "balloon".
  std::string kind = "box";
  std::vector<ObstaclePart> parts;  // empty: one box of size_m
};

// A smooth bump of the terrain: the part of the ellipsoid
// ((x - cx) / rx)^2 + ((y - cy) / ry)^2 + ((z - cz) / rz)^2 <= 1 above the ground. The centre is
// on or below the ground (centre_m[1] >= camera_height_m), so the hill rises
// radii_m[1] - (centre_m[1] - camera_height_m) metres above the ground and its foot is the
// ellipse where it meets the ground plane. Not an obstacle: object_id 0 in the truth.
// Textured in world (x, z) like the ground and lit from above, so that its slopes show.
struct Hill {
  cv::Vec3d centre_m;                // world frame (y down): centre_m[1] >= camera_height_m
  cv::Vec3d radii_m{1.0, 1.0, 1.0};  // semi-axes along x, y (vertical) and z, all > 0
  double albedo = 0.45;              // mean grey level 0..1 of its texture
  double contrast = 0.3;             // texture contrast 0..1
  double texture_cell_m = 1.0;       // finest texture detail, metres
};

// A flat mark painted on the ground (a runway edge line, a threshold bar, a field of another
// crop): the axis-aligned rectangle x in [x, x + width), z in [y, y + height) of the ground
// plane (cv::Rect2d's y is the world z). Its grey is albedo + its own contrast times the ground's
// texture; edges are anti-aliased (the pixel's footprint on the ground is box-filtered), so both
// views see it alike at sub-pixel disparities. Marks listed later paint over earlier ones and over
// the ground; hills and obstacles hide them. Not an obstacle: object_id 0.
struct GroundMark {
  cv::Rect2d area_xz_m;    // x = x0, y = z0, width = x extent, height = z extent; both > 0
  double albedo = 0.9;     // mean grey 0..1 of the paint
  double contrast = 0.05;  // contrast 0..1 of the paint's texture (the ground's noise pattern)
};

// A dashed line along z on the ground (a runway centreline): dashes of length dash_m separated
// by gaps of gap_m, the first dash starting at z_start_m, none beyond z_end_m (which may be
// infinite); width_m wide, centred on x = x_m. One periodic pattern instead of many marks:
// cheap for hundreds of dashes. Painted after the GroundMarks, same shading as a mark.
struct DashedLine {
  double x_m = 0.0;
  double width_m = 0.9;
  double z_start_m = 0.0;
  double z_end_m = 2000.0;  // > z_start_m; may be +infinity
  double dash_m = 30.0;     // > 0
  double gap_m = 20.0;      // >= 0 (0 = a continuous line)
  double albedo = 0.9;
  double contrast = 0.05;
};

struct Scene {
  double camera_height_m = 40.0;  // the ground plane is y = camera_height_m
  double ground_albedo = 0.45;
  double ground_contrast = 0.3;
  double ground_texture_cell_m = 0.4;
  double sky_top = 0.55;     // grey of the sky at the top row, 0..1
  double sky_horizon = 0.9;  // grey at the horizon
  // The camera's pitch, degrees, positive up (|pitch| <= 45). The horizon is then the row
  // cy + f tan(pitch); the sky gradient runs from sky_horizon there to sky_top cy rows above.
  double camera_pitch_deg = 0.0;
  // Clouds: low-frequency noise in the sky's grey, at infinity (disparity 0, object_id -1).
  // cloud_cover 0..1 (0 = none), cloud_grey the grey the densest cloud adds to the sky (-1..1:
  // negative for dark clouds), cloud_scale the size of the largest cloud features as a fraction
  // of the image width (> 0). Clouds fade out towards the horizon.
  double cloud_cover = 0.0;
  double cloud_grey = 0.2;
  double cloud_scale = 0.3;
  std::vector<Obstacle> obstacles;
  // Terrain (object_id 0, never in the truth's obstacle list).
  std::vector<Hill> hills;
  std::vector<GroundMark> marks;         // painted in order, later over earlier
  std::vector<DashedLine> dashed_lines;  // painted after the marks
  // The rig's own motion through the scene (world frame, m/s; level: y = 0): at time t the
  // camera is at rig_velocity_mps * (t mod rig_period_s), so the ground and the obstacles move
  // past it (the flight repeats every rig_period_s; 0 = never). Hills and marks are not supported
  // with a moving rig. Zero (the default): the camera is at rest.
  cv::Vec3d rig_velocity_mps{0.0, 0.0, 0.0};
  double rig_period_s = 0.0;

  // The camera's offset from its rest position at time t (world frame, metres).
  cv::Vec3d RigOffsetAt(double t_s) const;

  std::vector<std::string> Validate() const;
};

// The demo scene: a tower and a hangar standing on the ground, and moving aircraft and drones
// (straight and curved paths, two crossing, one passing behind another), all within the range
// where the default rig sees at least 8 px of disparity.
Scene DefaultScene();

}  // namespace stevi::drivers
