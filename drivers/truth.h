// What was really in a frame, for the sources that know it (the synthetic rig): the evaluation's
// and the truth stream's reference.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::drivers {

// What was really there in one frame.
struct ObstacleTruth {
  int id = 0;          // stable over the sequence
  std::string name;    // "tower", "hangar", "drone-1", ...
  std::string kind;    // Obstacle::kind: "box", "aircraft", "drone", "balloon", ...
  cv::Rect bbox;       // visible pixels in the left image (empty when not visible)
  int visible_px = 0;  // visible pixel count in the left image
  // The centre of the face towards the camera (the box's, or the bounding box of a composite's
  // parts), in the cam frame (pitched with the camera).
  cv::Vec3d position_cam_m;
  double depth_m = 0;  // z of that point (level camera: of every pixel of a box's front)
  double range_m = 0;  // |position_cam_m|
  // The median of the exact disparity over the obstacle's visible left pixels (0 when none): a
  // truth depth f B / median_disparity_px for any shape, where depth_m is the box's front face.
  double median_disparity_px = 0;
};

struct FrameTruth {
  int64_t index = 0;
  double t_s = 0;
  std::vector<ObstacleTruth> obstacles;  // every obstacle of the scene, visible or not
  cv::Mat1f disparity_px;                // exact disparity of the left image; 0 for the sky
  cv::Mat1i object_id;                   // per left pixel: obstacle id, 0 = ground, -1 = sky
};

}  // namespace stevi::drivers
