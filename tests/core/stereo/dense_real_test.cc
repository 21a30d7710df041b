// The dense matcher on the real pairs (Middlebury, KITTI 2015) from $STEVI_DATA_DIR, against the
// plain OpenCV reference cv::StereoSGBM in the same run, and the calibration of its confidence on
// the held-out split. Skips when the data is absent. Figures: core/stereo/README.md.
#include "core/stereo/dense_matcher.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/stereo/disparity.h"
#include "drivers/synthetic/random_scenes.h"
#include "drivers/synthetic/synthetic_source.h"
#include "tests/testing/data.h"
#include "tests/testing/real_pairs.h"
#include "tests/testing/sanitized.h"

namespace stevi::stereo {
namespace {

using testing::RealPair;

// The confidence is P(inlier): the disparity within this of the truth (pixels). The stixel world
// reads it as the probability that a value lies within its noise model; a value off by 2 px at a
// disparity of 3 px is no inlier to it.
constexpr double kInlierPx = 1.0;

// The tuning split (the confidence model and the penalties were chosen on it) and the held-out
// split (reported, never tuned on).
const std::vector<std::string> kTuning = {"tsukuba",         "venus",           "sawtooth",
                                          "kitti-000000_10", "kitti-000001_10", "kitti-000002_10"};
const std::vector<std::string> kHeldOut = {"teddy", "cones", "motorcycle", "kitti-000005_10",
                                           "kitti-000046_10"};

// Sawtooth (Middlebury 2001) is not among the shared loader's pairs: no masks, truth / 8.
std::optional<RealPair> LoadSawtooth(const std::string& data_dir, std::string& problem) {
  RealPair pair;
  pair.name = "sawtooth";
  pair.folder = data_dir + "/middlebury2001/sawtooth";
  pair.left = cv::imread(pair.folder + "/im2.ppm", cv::IMREAD_GRAYSCALE);
  pair.right = cv::imread(pair.folder + "/im6.ppm", cv::IMREAD_GRAYSCALE);
  const cv::Mat truth = cv::imread(pair.folder + "/disp2.pgm", cv::IMREAD_GRAYSCALE);
  if (pair.left.empty() || pair.right.empty() || truth.empty()) {
    problem = pair.folder + ": missing or unreadable images";
    return std::nullopt;
  }
  truth.convertTo(pair.truth_px, CV_32F, 1.0 / 8.0);
  pair.evaluated = pair.truth_px > 0;
  // The 2001 pairs' truth leaves a border unknown; sawtooth's is 0 there already.
  return pair;
}

const std::map<std::string, RealPair>* LoadAll(std::string& problem) {
  static std::map<std::string, RealPair> pairs;
  static std::string why;
  static bool loaded = false;
  if (!loaded) {
    loaded = true;
    const std::optional<std::string> data = testing::DataDir();
    if (!data) {
      why = "reference data folder not found: " + testing::DataDirWanted();
    } else {
      std::vector<std::string> names = kTuning;
      names.insert(names.end(), kHeldOut.begin(), kHeldOut.end());
      for (const std::string& name : names) {
        std::optional<RealPair> pair =
            name == "sawtooth" ? LoadSawtooth(*data, why) : testing::LoadRealPair(*data, name, why);
        if (!pair) {
          pairs.clear();
          break;
        }
        pairs[name] = std::move(*pair);
      }
    }
  }
  problem = why;
  return pairs.empty() ? nullptr : &pairs;
}

// The search range for a pair: 128 on KITTI; on Middlebury the multiple of 16 above the truth.
int RangeFor(const RealPair& pair) {
  if (pair.kitti) return 128;
  double max_truth = 0;
  cv::minMaxLoc(pair.truth_px, nullptr, &max_truth, nullptr, nullptr, pair.evaluated);
  return (static_cast<int>(max_truth) + 2 + 15) / 16 * 16;
}

// The plain OpenCV reference: as a user would run it (no padding, grey input).
DisparityMap Reference(const RealPair& pair, int num) {
  cv::Ptr<cv::StereoSGBM> sgbm = cv::StereoSGBM::create(0, num, 5, 8 * 25, 32 * 25, 1, 63, 10, 100,
                                                        32, cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat raw;
  sgbm->compute(pair.left, pair.right, raw);
  DisparityMap map;
  map.fixed = raw;
  map.fixed.setTo(DisparityMap::kInvalid, map.fixed < 0);
  map.num_disparities = num;
  return map;
}

DisparityMap Dense(const RealPair& pair, int num, DenseCues* cues = nullptr) {
  DenseMatcherOptions options;
  options.num_disparities = num;
  DenseMatcher matcher(options);
  DisparityMap map = matcher.Compute(pair.left, pair.right);
  if (cues != nullptr) *cues = matcher.last_cues();
  return map;
}

// Frame 0 of the random scene `family` / `seed` through the default dense matcher: the map, with
// the scene's exact truth in `truth` and the matcher's cues in `cues`.
DisparityMap DenseOnRandomScene(const std::string& family, uint64_t seed,
                                drivers::FrameTruth& truth, DenseCues* cues = nullptr) {
  const drivers::Scenario scenario = drivers::RandomScenario(family, seed);
  drivers::SyntheticRenderer renderer(scenario.options);
  const StereoFrame frame = renderer.Render(0, &truth);
  DenseMatcher matcher({});
  DisparityMap map = matcher.Compute(frame.left, frame.right);
  if (cues != nullptr) *cues = matcher.last_cues();
  return map;
}

// Pixels evaluated, and bad at > threshold px counting an unmatched pixel as bad.
struct BadCount {
  long evaluated = 0, bad = 0, matched = 0;
};
BadCount CountBad(const DisparityMap& map, const RealPair& pair, double threshold) {
  BadCount c;
  for (int y = 0; y < map.fixed.rows; ++y) {
    for (int x = 0; x < map.fixed.cols; ++x) {
      if (!pair.evaluated(y, x)) continue;
      ++c.evaluated;
      const std::optional<float> d = map.At(x, y);
      c.matched += d.has_value();
      c.bad += !d || std::abs(*d - pair.truth_px(y, x)) > threshold;
    }
  }
  return c;
}

class DenseReal : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string problem;
    pairs_ = LoadAll(problem);
    if (pairs_ == nullptr) GTEST_SKIP() << "real stereo pairs not available: " << problem;
  }
  const RealPair& Pair(const std::string& name) const { return pairs_->at(name); }
  const std::map<std::string, RealPair>* pairs_ = nullptr;
};

// KITTI: D1 outliers (> 3 px and > 5 %, unmatched counted as bad) and matched pixels over the known
// truth of the 5 frames, dense (128 disparities) against the plain cv::StereoSGBM.
TEST_F(DenseReal, KittiBeatsOpenCvSgbm) {
  long evaluated = 0, dense_bad = 0, dense_matched = 0, ref_bad = 0, ref_matched = 0;
  std::printf(
      "| KITTI pair | SGBM D1 bad %% | SGBM matched %% | dense D1 bad %% | dense matched %% "
      "| dense bad3 (matched only) %% |\n|---|---|---|---|---|---|\n");
  for (const std::string& name : testing::KittiPairNames()) {
    const RealPair& pair = Pair(name);
    const testing::DisparityScore ref = testing::ScoreDisparity(Reference(pair, 128), 1, pair);
    const testing::DisparityScore dense = testing::ScoreDisparity(Dense(pair, 128), 1, pair);
    std::printf("| %s | %.2f | %.2f | %.2f | %.2f | %.2f |\n", name.c_str(), ref.D1RawPct(),
                ref.MatchedPct(), dense.D1RawPct(), dense.MatchedPct(), dense.Bad3MatchedPct());
    evaluated += dense.evaluated;
    dense_bad += dense.d1_raw;
    dense_matched += dense.matched;
    ref_bad += ref.d1_raw;
    ref_matched += ref.matched;
  }
  std::printf("| all 5 | %.2f | %.2f | %.2f | %.2f | |\n", 100.0 * ref_bad / evaluated,
              100.0 * ref_matched / evaluated, 100.0 * dense_bad / evaluated,
              100.0 * dense_matched / evaluated);
  EXPECT_LE(dense_bad, ref_bad);
  EXPECT_GE(dense_matched, ref_matched);
}

// Middlebury: bad at > 2 px over the non-occluded mask (unmatched counted as bad), each pair with a
// range covering its truth, the same for both matchers.
TEST_F(DenseReal, MiddleburyBeatsOpenCvSgbm) {
  long evaluated = 0, dense_bad = 0, ref_bad = 0;
  std::printf(
      "| Middlebury pair | range | SGBM bad2 %% | SGBM matched %% | dense bad2 %% | dense "
      "matched %% |\n|---|---|---|---|---|---|\n");
  for (const char* name : {"tsukuba", "venus", "sawtooth", "teddy", "cones", "motorcycle"}) {
    const RealPair& pair = Pair(name);
    const int num = RangeFor(pair);
    const BadCount ref = CountBad(Reference(pair, num), pair, 2.0);
    const BadCount dense = CountBad(Dense(pair, num), pair, 2.0);
    std::printf("| %s | %d | %.2f | %.2f | %.2f | %.2f |\n", name, num,
                100.0 * ref.bad / ref.evaluated, 100.0 * ref.matched / ref.evaluated,
                100.0 * dense.bad / dense.evaluated, 100.0 * dense.matched / dense.evaluated);
    evaluated += dense.evaluated;
    dense_bad += dense.bad;
    ref_bad += ref.bad;
  }
  std::printf("| all | | %.2f | | %.2f | |\n", 100.0 * ref_bad / evaluated,
              100.0 * dense_bad / evaluated);
  EXPECT_LE(dense_bad, ref_bad);
}

// Pixels by confidence bin: the mean predicted P(inlier) against the observed inlier rate (and the
// rate within 3 px), printed as a Markdown table and checked for calibration.
struct CalibrationBins {
  static constexpr int kBins = 8;
  std::array<double, kBins> predicted{}, inlier{}, within3{}, count{};

  void Add(int confidence, double error_px) {
    const int bin = std::min(kBins - 1, confidence * kBins / 256);
    predicted[bin] += confidence / 255.0;
    inlier[bin] += error_px <= kInlierPx;
    within3[bin] += error_px <= 3.0;
    count[bin] += 1;
  }
  double Observed(int b) const { return inlier[b] / count[b]; }
  void Print(const char* title) const {
    std::printf(
        "| confidence (%s) | pixels | predicted | inlier (within 1 px) | within 3 px |\n"
        "|---|---|---|---|---|\n",
        title);
    for (int b = 0; b < kBins; ++b) {
      if (count[b] == 0) continue;
      std::printf("| %d..%d | %.0f | %.3f | %.3f | %.3f |\n", b * 256 / kBins,
                  (b + 1) * 256 / kBins - 1, count[b], predicted[b] / count[b], Observed(b),
                  within3[b] / count[b]);
    }
  }
  // Each bin of at least 2000 pixels within 0.15 of its prediction.
  void ExpectCalibrated() const {
    for (int b = 0; b < kBins; ++b) {
      if (count[b] < 2000) continue;
      EXPECT_NEAR(Observed(b), predicted[b] / count[b], 0.15) << "bin " << b;
    }
  }
};

// Calibration of the confidence on the held-out pairs: per bin of confidence, the predicted mean
// against the observed fraction within 3 px (and 1 px) of the truth, for the measured pixels where
// the fitted model speaks alone; the filled pixels (capped) and those the structure prior lowered
// are printed apart.
TEST_F(DenseReal, ConfidenceIsCalibratedOnHeldOutPairs) {
  CalibrationBins bins;
  long high = 0, high_inlier = 0;
  double filled = 0, filled_inlier = 0, filled_predicted = 0;
  double lowered = 0, lowered_inlier = 0, lowered_predicted = 0;
  for (const std::string& name : kHeldOut) {
    const RealPair& pair = Pair(name);
    DenseCues cues;
    const DisparityMap map = Dense(pair, RangeFor(pair), &cues);
    for (int y = 0; y < map.fixed.rows; ++y) {
      for (int x = 0; x < map.fixed.cols; ++x) {
        const std::optional<float> d = map.At(x, y);
        if (!pair.evaluated(y, x) || !d) continue;
        const int c = map.confidence(y, x);
        const double err = std::abs(*d - pair.truth_px(y, x));
        if (c >= 200) {
          ++high;
          high_inlier += err <= kInlierPx;
        }
        if (cues.filled(y, x)) {
          filled += 1;
          filled_inlier += err <= kInlierPx;
          filled_predicted += c / 255.0;
          continue;
        }
        if (cues.structure(y, x) < kDenseStructureFull) {
          lowered += 1;
          lowered_inlier += err <= kInlierPx;
          lowered_predicted += c / 255.0;
          continue;
        }
        bins.Add(c, err);
      }
    }
  }
  bins.Print("measured");
  std::printf("| filled (capped at 100) | %.0f | %.3f | %.3f | |\n", filled,
              filled_predicted / std::max(1.0, filled), filled_inlier / std::max(1.0, filled));
  std::printf("| lowered by the structure prior | %.0f | %.3f | %.3f | |\n", lowered,
              lowered_predicted / std::max(1.0, lowered), lowered_inlier / std::max(1.0, lowered));
  ASSERT_GT(high, 1000);
  const double high_rate = static_cast<double>(high_inlier) / high;
  std::printf("confidence >= 200: %ld pixels, %.3f inliers\n", high, high_rate);
  EXPECT_GE(high_rate, 0.90);
  // The lowest populated bin is clearly worse.
  int lowest = 0;
  while (lowest < CalibrationBins::kBins && bins.count[lowest] < 1000) ++lowest;
  ASSERT_LT(lowest, CalibrationBins::kBins);
  EXPECT_LT(bins.Observed(lowest), high_rate - 0.2) << "bin " << lowest;
  bins.ExpectCalibrated();
}

// The same calibration on the synthetic test split (seeds 1001.., never tuned on): flat noisy
// skies, clouds at infinity and low-texture ground, with exact truth everywhere (the sky's is 0).
// Every matched pixel counts, with the confidence a consumer sees (filled and lowered ones
// included).
TEST(DenseSynthetic, ConfidenceIsCalibratedOnTheSyntheticTestSplit) {
  CalibrationBins bins;
  double sky = 0, sky_trusted = 0;
  for (const std::string& family : drivers::RandomSceneFamilies()) {
    for (uint64_t seed = 1001; seed <= 1006; ++seed) {
      drivers::FrameTruth truth;
      const DisparityMap map = DenseOnRandomScene(family, seed, truth);
      for (int y = 0; y < map.fixed.rows; y += 2) {
        for (int x = 0; x < map.fixed.cols; x += 2) {
          const std::optional<float> d = map.At(x, y);
          if (truth.object_id(y, x) == -1) {
            sky += 1;
            sky_trusted += d && map.confidence(y, x) >= 128;
          }
          if (!d) continue;
          bins.Add(map.confidence(y, x), std::abs(*d - truth.disparity_px(y, x)));
        }
      }
    }
  }
  bins.Print("synthetic test split");
  std::printf("sky pixels trusted (confidence >= 128): %.2f %% of %.0f\n",
              100.0 * sky_trusted / std::max(1.0, sky), sky);
  bins.ExpectCalibrated();
  // The open sky (truth 0, flat or clouds) is almost never trusted: 0.40 % measured.
  ASSERT_GT(sky, 100000);
  EXPECT_LT(sky_trusted / sky, 0.02);
}

// Fits the confidence model on the tuning split (logistic regression by Newton's method) and
// prints the weights for kDenseConfidenceWeights. Run with --gtest_also_run_disabled_tests.
TEST_F(DenseReal, DISABLED_FitConfidence) {
  std::vector<DenseConfidenceVector> features;
  std::vector<double> labels;
  const auto add = [&](const DisparityMap& map, const DenseCues& cues, const cv::Mat1f& truth,
                       const cv::Mat1b& evaluated, int step) {
    for (int y = 0; y < map.fixed.rows; y += step) {
      for (int x = 0; x < map.fixed.cols; x += step) {
        const std::optional<float> d = map.At(x, y);
        // Where the structure prior lowers the confidence the model does not speak alone.
        if (!evaluated(y, x) || !d || cues.structure(y, x) < kDenseStructureFull) continue;
        features.push_back(DenseConfidenceFeatures({.margin = std::min<int>(255, cues.margin(y, x)),
                                                    .texture_ratio = cues.texture_ratio(y, x),
                                                    .filled = cues.filled(y, x) != 0,
                                                    .agreement = cues.agreement(y, x),
                                                    .structure_ratio = cues.structure(y, x)},
                                                   DenseMatcherOptions{}.num_paths));
        labels.push_back(std::abs(*d - truth(y, x)) <= kInlierPx ? 1.0 : 0.0);
      }
    }
  };
  for (const std::string& name : kTuning) {
    const RealPair& pair = Pair(name);
    DenseCues cues;
    const DisparityMap map = Dense(pair, RangeFor(pair), &cues);
    add(map, cues, pair.truth_px, pair.evaluated, 1);
  }
  const size_t real = labels.size();
  // The synthetic tuning seeds (1..999; the test split starts at 1001), every pixel with its exact
  // truth, the sky's (0) included: flat noisy skies and clouds, which the real pairs lack.
  for (const std::string& family : drivers::RandomSceneFamilies()) {
    for (uint64_t seed = 1; seed <= 12; ++seed) {
      drivers::FrameTruth truth;
      DenseCues cues;
      const DisparityMap map = DenseOnRandomScene(family, seed, truth, &cues);
      add(map, cues, truth.disparity_px, cv::Mat1b(map.fixed.size(), uint8_t{1}), 4);
    }
  }
  std::printf("samples: %zu real, %zu synthetic\n", real, labels.size() - real);
  // The synthetic pixels weigh kSyntheticShare of the real ones in all, however many they are.
  const double kSyntheticShare = std::getenv("SHARE") ? std::atof(std::getenv("SHARE")) : 1.0;
  const double synthetic_weight =
      kSyntheticShare * static_cast<double>(real) / std::max<size_t>(1, labels.size() - real);
  constexpr int kF = kDenseConfidenceFeatures;
  cv::Mat1d w(kF, 1, 0.0);
  for (int iteration = 0; iteration < 25; ++iteration) {
    cv::Mat1d hessian(kF, kF, 0.0), gradient(kF, 1, 0.0);
    for (size_t i = 0; i < features.size(); ++i) {
      double z = 0;
      for (int j = 0; j < kF; ++j) z += w(j) * features[i][j];
      const double p = 1.0 / (1.0 + std::exp(-z));
      const double weight = i < real ? 1.0 : synthetic_weight;
      for (int j = 0; j < kF; ++j) {
        gradient(j) += weight * (labels[i] - p) * features[i][j];
        for (int k = 0; k < kF; ++k) {
          hessian(j, k) += weight * p * (1 - p) * features[i][j] * features[i][k];
        }
      }
    }
    for (int j = 0; j < kF; ++j) hessian(j, j) += 1e-6 * features.size();
    cv::Mat1d step;
    cv::solve(hessian, gradient, step, cv::DECOMP_CHOLESKY);
    w += step;
  }
  std::printf("kDenseConfidenceWeights = {");
  for (int j = 0; j < kF; ++j) std::printf("%s%.4f", j ? ", " : "", w(j));
  std::printf("};  // %zu samples\n", features.size());
}

// Time at 640x480 with 64 disparities on one thread (New Tsukuba frame 1), against
// cv::StereoSGBM 3-way (block 5, same range) in the same run. Printed only: no timing assertion.
TEST_F(DenseReal, TimeAt640x480AgainstOpenCvSgbm) {
  const std::optional<std::string> data = testing::DataDir();
  const cv::Mat left = cv::imread(*data + "/new_tsukuba/frames/l.png", cv::IMREAD_GRAYSCALE);
  const cv::Mat right = cv::imread(*data + "/new_tsukuba/frames/r.png", cv::IMREAD_GRAYSCALE);
  if (left.empty() || right.empty()) GTEST_SKIP() << "New Tsukuba frame 1 not found";
  ASSERT_EQ(left.size(), cv::Size(640, 480));
  const int threads = cv::getNumThreads();
  cv::setNumThreads(1);
  // Median of 15 runs; of 3 under a sanitizer, whose times say nothing of the matcher's.
  constexpr int kRuns = testing::kSanitized ? 3 : 15;
  auto median_ms = [](auto&& run) {
    std::vector<double> ms;
    for (int i = 0; i < kRuns; ++i) {
      const auto t0 = std::chrono::steady_clock::now();
      run();
      ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(ms.begin(), ms.end());
    return ms[ms.size() / 2];
  };
  DenseMatcher dense4({.num_paths = 4}), dense5({});
  cv::Ptr<cv::StereoSGBM> sgbm = cv::StereoSGBM::create(0, 64, 5, 8 * 25, 32 * 25, 1, 63, 10, 100,
                                                        32, cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat raw;
  const double t_sgbm = median_ms([&] { sgbm->compute(left, right, raw); });
  const double t5 = median_ms([&] { dense5.Compute(left, right); });
  const double t4 = median_ms([&] { dense4.Compute(left, right); });
  DenseMatcher portable({});
  portable.set_simd_path(DenseMatcher::SimdPath::kPortable);
  const double t_portable = median_ms([&] { portable.Compute(left, right); });
  DenseMatcher avx2({});
  avx2.set_simd_path(DenseMatcher::SimdPath::kAvx2);
  const double t_avx2 = median_ms([&] { avx2.Compute(left, right); });
  cv::setNumThreads(threads);
  std::printf(
      "640x480, 64 disparities, one thread (median of %d): dense 5 paths %.2f ms, dense 4 "
      "paths %.2f ms, dense 5 paths AVX2 only %.2f ms, dense portable %.2f ms, "
      "cv::StereoSGBM 3-way %.2f ms\n",
      kRuns, t5, t4, t_avx2, t_portable, t_sgbm);
}

}  // namespace
}  // namespace stevi::stereo
