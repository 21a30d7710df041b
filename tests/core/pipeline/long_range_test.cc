// The thesis's long-range case with the default configuration: a 1280x1024 telephoto rig (f 6000
// px, B 0.7 m) on the ground, an airliner on a 3-degree approach from 1200 m to 300 m and a light
// aircraft crossing at 420 m. The thesis measured more than 20 m of error at 300 m on a 0.7 m
// baseline; the range must be five times better, and its reported uncertainty honest.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <memory>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/truth_match.h"

namespace stevi::pipeline {
namespace {

constexpr double kF = 6000.0;
constexpr double kB = 0.7;

drivers::Obstacle Aircraft(int id, const char* name, cv::Vec3d size_m, cv::Vec3d centre_m) {
  drivers::Obstacle o;
  o.id = id;
  o.name = name;
  o.size_m = size_m;
  o.path.start = centre_m;
  o.albedo = 0.3;
  o.contrast = 0.35;
  o.texture_cell_m = 0.6;
  return o;
}

drivers::SyntheticOptions Telephoto(double approach_range_m) {
  drivers::SyntheticOptions options;
  options.width = 1280;
  options.height = 1024;
  options.f_px = kF;
  options.baseline_m = kB;
  options.noise_sigma = 2.0;
  options.seed = static_cast<uint64_t>(approach_range_m);
  drivers::Scene scene;
  scene.camera_height_m = 2.0;
  // The airliner's nose on the 3-degree glide path (y down: above the camera is negative y).
  const double glide = std::tan(3.0 * M_PI / 180.0);
  scene.obstacles.push_back(Aircraft(
      1, "airliner", {36.0, 6.0, 40.0},
      {-0.2 * approach_range_m * 0.01, -approach_range_m * glide, approach_range_m + 20.0}));
  // The light aircraft crosses to the right of the approach, a little higher.
  scene.obstacles.push_back(Aircraft(2, "light-aircraft", {11.0, 2.5, 8.0},
                                     {40.0 - 0.05 * approach_range_m, -34.0, 424.0}));
  options.scene = scene;
  return options;
}

struct Measured {
  double truth_range_m = 0, range_m = 0, sigma_m = 0, disparity_px = 0;
};

TEST(LongRange, DefaultsRangeAnApproachingAirlinerAndACrossingAircraftHonestly) {
  for (const Algorithm algorithm : {Algorithm::kSteViE, Algorithm::kSteViS}) {
    std::vector<Measured> measured;
    int expected = 0, found = 0, boxes = 0;
    for (double range : {1200.0, 1000.0, 800.0, 650.0, 500.0, 400.0, 300.0}) {
      const drivers::SyntheticRenderer renderer(Telephoto(range));
      drivers::FrameTruth truth;
      const StereoFrame frame = renderer.Render(0, &truth);
      PipelineConfig config;  // the defaults
      config.algorithm = algorithm;
      Pipeline pipeline;
      const Result<FrameResult> result =
          pipeline.Process(frame, {std::make_shared<const PipelineConfig>(config),
                                   std::make_shared<const geometry::StereoRig>(renderer.Rig())});
      ASSERT_TRUE(result.ok()) << result.error().message;
      std::vector<cv::Rect> detected, truth_boxes;
      const int bin = result->binning;
      for (const detection::Detection& d : result->detections) {
        detected.emplace_back(d.bbox.x * bin, d.bbox.y * bin, d.bbox.width * bin,
                              d.bbox.height * bin);
      }
      std::vector<const drivers::ObstacleTruth*> objects;
      for (const drivers::ObstacleTruth& o : truth.obstacles) {
        if (o.visible_px < 100) continue;
        objects.push_back(&o);
        truth_boxes.push_back(o.bbox);
      }
      if (const char* dump = std::getenv("STEVI_DUMP")) {
        cv::Mat3b out;
        cv::cvtColor(frame.left, out, cv::COLOR_GRAY2BGR);
        for (const cv::Rect& r : truth_boxes) cv::rectangle(out, r, {0, 255, 0}, 2);
        for (const cv::Rect& r : detected) cv::rectangle(out, r, {0, 0, 255}, 2);
        cv::imwrite(
            std::string(dump) + "/long_range_" + std::to_string(static_cast<int>(range)) + ".png",
            out);
      }
      expected += static_cast<int>(objects.size());
      boxes += static_cast<int>(detected.size());
      for (const auto& [d, t] : testing::MatchByIoU(detected, truth_boxes, 0.3)) {
        ++found;
        const detection::Detection& det = result->detections[d];
        // The truth: the depth of the nearest face, along the ray through the detection's
        // centroid.
        const double depth = objects[t]->depth_m;
        Measured m;
        m.truth_range_m = depth * det.range_m / det.depth_m;
        m.range_m = det.range_m;
        m.sigma_m = det.range_sigma_m;
        m.disparity_px = det.disparity_px * bin;
        measured.push_back(m);
        std::printf("%s %-15s truth %7.1f m (d %5.2f px) measured %7.1f m +- %5.2f m (%+.2f %%)\n",
                    algorithm == Algorithm::kSteViE ? "stevie" : "stevis", objects[t]->name.c_str(),
                    m.truth_range_m, kF * kB / depth, m.range_m, m.sigma_m,
                    100 * (m.range_m - m.truth_range_m) / m.truth_range_m);
      }
    }
    ASSERT_FALSE(measured.empty());
    double ratio2 = 0;
    std::vector<double> relative;
    for (const Measured& m : measured) {
      ratio2 += std::pow((m.range_m - m.truth_range_m) / m.sigma_m, 2);
      relative.push_back(std::abs(m.range_m - m.truth_range_m) / m.truth_range_m);
      // Five times better than the thesis's 20 m at 300 m: 4 m there, the same relative error
      // (1.3 %) anywhere.
      EXPECT_LT(std::abs(m.range_m - m.truth_range_m), 4.0 * std::pow(m.truth_range_m / 300.0, 2))
          << m.truth_range_m;
    }
    std::nth_element(relative.begin(), relative.begin() + relative.size() / 2, relative.end());
    const double ratio_rms = std::sqrt(ratio2 / measured.size());
    std::printf("found %d of %d, %d boxes; median range error %.2f %%; error / sigma rms %.2f\n",
                found, expected, boxes, 100 * relative[relative.size() / 2], ratio_rms);
    EXPECT_EQ(found, expected);
    // One box per aircraft; the near ground (50-100 m below the horizon of a camera 2 m up)
    // leaves at most one false box in two frames.
    EXPECT_LE(boxes - found, 3);
    EXPECT_GT(ratio_rms, 0.5);
    EXPECT_LT(ratio_rms, 1.6);
  }
}

}  // namespace
}  // namespace stevi::pipeline
