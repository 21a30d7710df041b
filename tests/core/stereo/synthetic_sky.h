// The synthetic rig's default scene as the matchers' sky tests see it (dense_matcher_test,
// matcher_test): a flat sky gradient with pixel noise of sigma 2 around textured obstacles.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/stereo_frame.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::stereo::fixtures {

// Frame 0 of the default scene, its truth, and masks of its open sky and of its obstacles.
struct SkyScene {
  StereoFrame frame;
  drivers::FrameTruth truth;
  cv::Mat1b open_sky;   // sky pixels more than 8 px from anything else
  cv::Mat1b obstacles;  // the obstacles' pixels (object id > 0)
};

// The open sky leaves out the sky within 8 px of anything else: next to an obstacle's silhouette,
// SGBM and any window-based gate give the sky the obstacle's disparity.
inline SkyScene DefaultSkyScene() {
  const drivers::SyntheticRenderer renderer{drivers::SyntheticOptions{}};
  SkyScene scene;
  scene.frame = renderer.Render(0, &scene.truth);
  cv::Mat1b near_scene;
  cv::dilate(scene.truth.object_id != -1, near_scene,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(17, 17)));
  scene.open_sky = (scene.truth.object_id == -1) & ~near_scene;
  scene.obstacles = scene.truth.object_id > 0;
  return scene;
}

}  // namespace stevi::stereo::fixtures
