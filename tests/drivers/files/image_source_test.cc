#include "drivers/files/image_source.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iterator>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "core/geometry/calibration_io.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/data.h"
#include "tests/testing/status_matchers.h"

using stevi::testing::IsError;

namespace stevi::drivers {
namespace {

std::string FileName(const std::string& dir, const char* pattern, int index) {
  char name[256];
  std::snprintf(name, sizeof(name), pattern, index);
  return dir + "/" + name;
}

void WriteCalibration(const std::string& path, cv::Size size, double f = 500, double b = 0.5) {
  const Status saved = geometry::SaveCalibrationYaml(
      geometry::IdealCalibration(size, f, b, size.width / 2.0, size.height / 2.0), path);
  ASSERT_TRUE(saved.ok()) << saved.error().message;
}

cv::Mat1b Noise(cv::Size size, int seed) {
  cv::Mat1b image(size);
  cv::RNG rng(static_cast<uint64_t>(seed));
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  return image;
}

// A small sequence of random pairs left_%03d.png / right_%03d.png with indices
// first..first+count-1, and a matching ideal calibration.
struct SmallSequence {
  std::string dir;
  ImageSourceOptions options;
};

SmallSequence MakeSmallSequence(const std::string& name, int first, int count,
                                cv::Size size = cv::Size(160, 120)) {
  SmallSequence seq;
  seq.dir = testing::MakeTempDir(name);
  for (int i = first; i < first + count; ++i) {
    EXPECT_TRUE(cv::imwrite(FileName(seq.dir, "left_%03d.png", i), Noise(size, 2 * i)));
    EXPECT_TRUE(cv::imwrite(FileName(seq.dir, "right_%03d.png", i), Noise(size, 2 * i + 1)));
  }
  WriteCalibration(seq.dir + "/calib.yaml", size);
  seq.options.left = seq.dir + "/left_%03d.png";
  seq.options.right = seq.dir + "/right_%03d.png";
  seq.options.calibration = seq.dir + "/calib.yaml";
  seq.options.first_index = first;
  seq.options.fps = 4.0;
  return seq;
}

bool Contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// ---- The acceptance criterion: depth of fronto-parallel textured targets, 10..40 m ----------

// Round depths (whole or half-pixel disparities with f B = 420 px m) and awkward ones in between,
// where block matching's sub-pixel interpolation has no integer to lock onto.
constexpr double kRoundDepths[] = {10, 15, 20, 30, 40};
constexpr double kAwkwardDepths[] = {12.3, 17.7, 26.1, 34.4, 38.2};

// A thin textured box whose camera-facing face is at depth z and appears w x h px centred at
// pixel (u, v).
Obstacle Target(int id, double z, double u, double v, double w, double h,
                const SyntheticOptions& o) {
  const double cx = o.width / 2.0, cy = o.height / 2.0;
  Obstacle t;
  t.id = id;
  char name[32];
  std::snprintf(name, sizeof(name), "target-%.1fm", z);
  t.name = name;
  const double thickness = 0.2;
  t.size_m = cv::Vec3d(w * z / o.f_px, h * z / o.f_px, thickness);
  t.path.kind = Path::Kind::kStatic;
  t.path.start = cv::Vec3d((u - cx) * z / o.f_px, (v - cy) * z / o.f_px, z + thickness / 2);
  t.albedo = 0.35;
  return t;
}

TEST(ImageSequence, DepthOfFrontoParallelTargetsFrom10To40MetresWithin2Percent) {
  const std::string dir = testing::MakeTempDir("stevi_targets");
  SyntheticOptions base;  // 640x480, f 700 px, B 0.6 m, noise 2 grey levels
  base.scene.obstacles.clear();

  // Frames 0..9: one 90 x 70 px target each, above the horizon. Frames 10 and 11: five targets
  // side by side, 70 x 55 px, nearest on the right so that its match stays inside the right
  // image. The gaps (58 px) are wider than what block matching smears across the sky next to a
  // target (about 30 px with the default 15 px block): canonical blobs that touch would merge.
  std::vector<SyntheticOptions> frames;
  std::vector<double> all_depths(std::begin(kRoundDepths), std::end(kRoundDepths));
  all_depths.insert(all_depths.end(), std::begin(kAwkwardDepths), std::end(kAwkwardDepths));
  for (size_t i = 0; i < all_depths.size(); ++i) {
    SyntheticOptions o = base;
    o.scene.obstacles.push_back(Target(1, all_depths[i], 300 + 5.0 * i, 150, 90, 70, o));
    frames.push_back(o);
  }
  for (const auto* depths : {&kRoundDepths, &kAwkwardDepths}) {
    SyntheticOptions o = base;
    const double u[] = {576, 448, 320, 192, 64};  // nearest at the right ... farthest at the left
    for (int i = 0; i < 5; ++i) {
      o.scene.obstacles.push_back(Target(i + 1, (*depths)[i], u[i], 110 + 25 * (i % 2), 70, 55, o));
    }
    frames.push_back(o);
  }
  const size_t total_targets = all_depths.size() * 2;

  std::vector<FrameTruth> truths;
  for (size_t k = 0; k < frames.size(); ++k) {
    ASSERT_TRUE(frames[k].Validate().empty());
    const SyntheticRenderer renderer(frames[k]);
    FrameTruth truth;
    StereoFrame frame = renderer.Render(static_cast<int64_t>(k), &truth);
    if (k == 4) {  // a colour pair with alpha and a plain colour pair: both accepted
      cv::cvtColor(frame.left, frame.left, cv::COLOR_GRAY2BGRA);
      cv::cvtColor(frame.right, frame.right, cv::COLOR_GRAY2BGRA);
    } else if (k == 10) {
      cv::cvtColor(frame.left, frame.left, cv::COLOR_GRAY2BGR);
      cv::cvtColor(frame.right, frame.right, cv::COLOR_GRAY2BGR);
    }
    ASSERT_TRUE(cv::imwrite(FileName(dir, "left_%03d.png", static_cast<int>(k)), frame.left));
    ASSERT_TRUE(cv::imwrite(FileName(dir, "right_%03d.png", static_cast<int>(k)), frame.right));
    truths.push_back(truth);
  }
  const geometry::StereoRig truth_rig = SyntheticRenderer(base).Rig();
  const Status saved = geometry::SaveCalibrationYaml(
      geometry::IdealCalibration(cv::Size(base.width, base.height), truth_rig.f_px(),
                                 truth_rig.baseline_m(), truth_rig.cx(), truth_rig.cy()),
      dir + "/calibration.yaml");
  ASSERT_TRUE(saved.ok()) << saved.error().message;

  ImageSourceOptions options;
  options.left = dir + "/left_%03d.png";
  options.right = dir + "/right_%03d.png";
  options.calibration = dir + "/calibration.yaml";
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  std::printf("%s\n", (*source)->Describe().c_str());

  pipeline::PipelineConfig config;
  config.canonical.threshold_range_m = 60.0;
  pipeline::ConfigStore store;
  ASSERT_TRUE(store.Set(config).ok());
  pipeline::Pipeline pipeline;

  std::printf("frame  target       truth depth  measured depth  error %%  IoU\n");
  int measured = 0;
  double worst = 0;
  for (;;) {
    Result<StereoFrame> frame = (*source)->Next();
    if (!frame.ok()) {
      EXPECT_THAT(frame, IsError(ErrorCode::kOutOfRange)) << frame.error().message;
      break;
    }
    ASSERT_LT(frame->index, static_cast<int64_t>(truths.size()));
    const FrameTruth& truth = truths[static_cast<size_t>(frame->index)];
    Result<pipeline::FrameResult> result =
        pipeline.Process(*frame, pipeline::Snapshot{store.Get(), (*source)->Rig()});
    ASSERT_TRUE(result.ok()) << result.error().message;
    for (const ObstacleTruth& o : truth.obstacles) {
      ASSERT_FALSE(o.bbox.empty()) << o.name;
      const detection::Detection* best = nullptr;
      double best_iou = 0;
      for (const detection::Detection& d : result->detections) {
        const double inter = (d.bbox & o.bbox).area();
        const double iou = inter / (d.bbox.area() + o.bbox.area() - inter);
        if (iou > best_iou) {
          best_iou = iou;
          best = &d;
        }
      }
      if (best == nullptr || best_iou < 0.3) {
        ADD_FAILURE() << "frame " << frame->index << ": " << o.name << " at " << o.depth_m
                      << " m not detected (best IoU " << best_iou << ")";
        std::printf("%5lld  %-11s  %9.2f m  %14s\n", static_cast<long long>(frame->index),
                    o.name.c_str(), o.depth_m, "missed");
        continue;
      }
      const double error = (best->depth_m - o.depth_m) / o.depth_m;
      worst = std::max(worst, std::abs(error));
      ++measured;
      std::printf("%5lld  %-11s  %9.2f m  %12.2f m  %+6.2f  %.2f\n",
                  static_cast<long long>(frame->index), o.name.c_str(), o.depth_m, best->depth_m,
                  100 * error, best_iou);
      EXPECT_LE(std::abs(error), 0.02) << "frame " << frame->index << " " << o.name;
    }
  }
  std::printf("%d targets measured, worst depth error %.2f %%\n", measured, 100 * worst);
  EXPECT_EQ(measured, static_cast<int>(total_targets));
}

// ---- Opening, errors, end of sequence, loop, video ------------------------------------------

TEST(OpenImageSource, MissingFilesAreNamed) {
  SmallSequence seq = MakeSmallSequence("stevi_missing", 0, 2);
  ImageSourceOptions options = seq.options;
  options.calibration = seq.dir + "/no_such_calibration.yaml";
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(options);
  ASSERT_FALSE(source.ok());
  EXPECT_TRUE(Contains(source.error().message, "no_such_calibration.yaml"))
      << source.error().message;

  options = seq.options;
  options.first_index = 7;
  source = OpenImageSource(options);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kNotFound));
  EXPECT_TRUE(Contains(source.error().message, "left_007.png")) << source.error().message;

  std::filesystem::remove(FileName(seq.dir, "right_%03d.png", 0));
  source = OpenImageSource(seq.options);
  ASSERT_FALSE(source.ok());
  EXPECT_TRUE(Contains(source.error().message, "right_000.png")) << source.error().message;
}

TEST(ImageSourceOptionsValidate, RefusesBadPatternsAndListsEveryProblem) {
  SmallSequence seq = MakeSmallSequence("stevi_patterns", 0, 1);
  for (const char* bad : {"left_%s.png", "left_%d%d.png", "left.png%", "left_%n.png",
                          "left_%ld.png", "left_%999999d.png", "left_%.3d.png", "left_%*d.png"}) {
    ImageSourceOptions options = seq.options;
    options.left = seq.dir + "/" + bad;
    const std::vector<std::string> problems = options.Validate();
    ASSERT_EQ(problems.size(), 1u) << bad;
    EXPECT_EQ(problems[0].rfind("left: ", 0), 0u) << problems[0];
    Result<std::unique_ptr<StereoSource>> source = OpenImageSource(options);
    ASSERT_FALSE(source.ok()) << bad;
    EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  }
  // A literal '%' next to the one conversion is fine.
  ImageSourceOptions ok = seq.options;
  ok.left = seq.dir + "/100%%_left_%03d.png";
  EXPECT_TRUE(ok.Validate().empty());

  ImageSourceOptions bad;
  bad.left = "left_%d.png";
  bad.right = "right.avi";  // a pattern and a video
  bad.fps = 0;
  bad.first_index = -1;
  const std::vector<std::string> problems = bad.Validate();
  ASSERT_EQ(problems.size(), 4u);
  for (const char* field : {"calibration: ", "fps: ", "first_index: ", "right: "}) {
    bool found = false;
    for (const std::string& p : problems) found = found || p.rfind(field, 0) == 0;
    EXPECT_TRUE(found) << field;
  }
}

TEST(OpenImageSource, RefusesMismatchedSizesAndSixteenBitImages) {
  SmallSequence seq = MakeSmallSequence("stevi_sizes", 0, 2);
  ASSERT_TRUE(cv::imwrite(FileName(seq.dir, "right_%03d.png", 0), Noise(cv::Size(150, 120), 9)));
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(seq.options);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(source.error().message, "left_000.png")) << source.error().message;
  EXPECT_TRUE(Contains(source.error().message, "right_000.png")) << source.error().message;
  EXPECT_TRUE(Contains(source.error().message, "150x120")) << source.error().message;

  // Both images agree but the calibration says otherwise.
  ASSERT_TRUE(cv::imwrite(FileName(seq.dir, "left_%03d.png", 0), Noise(cv::Size(150, 120), 8)));
  source = OpenImageSource(seq.options);
  ASSERT_FALSE(source.ok());
  EXPECT_TRUE(Contains(source.error().message, "160x120")) << source.error().message;

  cv::Mat1w sixteen(120, 160, uint16_t{1000});
  ASSERT_TRUE(cv::imwrite(FileName(seq.dir, "left_%03d.png", 0), sixteen));
  ASSERT_TRUE(cv::imwrite(FileName(seq.dir, "right_%03d.png", 0), sixteen));
  source = OpenImageSource(seq.options);
  ASSERT_FALSE(source.ok());
  EXPECT_THAT(source, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(source.error().message, "16-bit")) << source.error().message;
  EXPECT_TRUE(Contains(source.error().message, "left_000.png")) << source.error().message;
}

TEST(ImageSourceNext, PlaysTheSequenceThenReportsItsEnd) {
  SmallSequence seq = MakeSmallSequence("stevi_end", 5, 3);
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(seq.options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  StereoSource& s = **source;
  EXPECT_EQ(s.NominalFps(), 4.0);
  EXPECT_EQ(s.Describe(), "images " + seq.options.left + " " + seq.options.right + " (160x120)");
  for (int i = 5; i < 8; ++i) {
    Result<StereoFrame> frame = s.Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->index, i);
    EXPECT_EQ(frame->t_ns, static_cast<int64_t>(i) * 250'000'000);
    EXPECT_EQ(frame->left.size(), cv::Size(160, 120));
    EXPECT_EQ(cv::norm(frame->left, Noise(cv::Size(160, 120), 2 * i), cv::NORM_INF), 0.0);
    EXPECT_EQ(cv::norm(frame->right, Noise(cv::Size(160, 120), 2 * i + 1), cv::NORM_INF), 0.0);
    EXPECT_TRUE(frame->rectified);  // an ideal calibration needs no remap
  }
  Result<StereoFrame> end = s.Next();
  ASSERT_FALSE(end.ok());
  EXPECT_THAT(end, IsError(ErrorCode::kOutOfRange));
}

TEST(ImageSourceNext, BrokenPairInTheMiddleNamesTheFile) {
  SmallSequence seq = MakeSmallSequence("stevi_broken", 0, 3);
  std::filesystem::remove(FileName(seq.dir, "right_%03d.png", 1));
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(seq.options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  ASSERT_TRUE((*source)->Next().ok());
  Result<StereoFrame> broken = (*source)->Next();
  ASSERT_FALSE(broken.ok());
  EXPECT_THAT(broken, IsError(ErrorCode::kInvalidArgument));
  EXPECT_TRUE(Contains(broken.error().message, "right_001.png")) << broken.error().message;
}

TEST(ImageSourceNext, LoopStartsAgainWithIncreasingTime) {
  SmallSequence seq = MakeSmallSequence("stevi_loop", 2, 3);
  seq.options.loop = true;
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(seq.options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  int64_t last_t_ns = -1;
  std::vector<int64_t> indices;
  for (int i = 0; i < 8; ++i) {
    Result<StereoFrame> frame = (*source)->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    indices.push_back(frame->index);
    EXPECT_GT(frame->t_ns, last_t_ns);
    last_t_ns = frame->t_ns;
    EXPECT_EQ(cv::norm(frame->left, Noise(cv::Size(160, 120), 2 * static_cast<int>(frame->index)),
                       cv::NORM_INF),
              0.0);
  }
  EXPECT_EQ(indices, (std::vector<int64_t>{2, 3, 4, 2, 3, 4, 2, 3}));
}

TEST(ImageSourceNext, VideoPairPlaysInLockStep) {
  const std::string dir = testing::MakeTempDir("stevi_video");
  const cv::Size size(160, 120);
  const int frames = 6;
  for (const char* name : {"left.avi", "right.avi"}) {
    cv::VideoWriter writer(dir + "/" + name, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           size, /*isColor=*/true);
    ASSERT_TRUE(writer.isOpened()) << "cannot write MJPG video " << name;
    for (int i = 0; i < frames; ++i) {
      cv::Mat3b image;
      cv::cvtColor(Noise(size, i), image, cv::COLOR_GRAY2BGR);
      writer.write(image);
    }
  }
  WriteCalibration(dir + "/calib.yaml", size);
  ImageSourceOptions options;
  options.left = dir + "/left.avi";
  options.right = dir + "/right.avi";
  options.calibration = dir + "/calib.yaml";
  options.fps = 10.0;
  Result<std::unique_ptr<StereoSource>> source = OpenImageSource(options);
  ASSERT_TRUE(source.ok()) << source.error().message;
  EXPECT_TRUE(Contains((*source)->Describe(), "left.avi")) << (*source)->Describe();
  for (int i = 0; i < frames; ++i) {
    Result<StereoFrame> frame = (*source)->Next();
    ASSERT_TRUE(frame.ok()) << frame.error().message;
    EXPECT_EQ(frame->index, i);
    EXPECT_EQ(frame->t_ns, static_cast<int64_t>(i) * 100'000'000);
    EXPECT_EQ(frame->left.size(), size);
    EXPECT_EQ(frame->right.size(), size);
  }
  Result<StereoFrame> end = (*source)->Next();
  ASSERT_FALSE(end.ok());
  EXPECT_THAT(end, IsError(ErrorCode::kOutOfRange));

  options.left = dir + "/missing.avi";
  source = OpenImageSource(options);
  ASSERT_FALSE(source.ok());
  EXPECT_TRUE(Contains(source.error().message, "missing.avi")) << source.error().message;
}

}  // namespace
}  // namespace stevi::drivers
