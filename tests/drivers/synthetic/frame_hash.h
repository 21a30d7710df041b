// Hashes of rendered frames, for the synthetic driver's tests that pin a scene's pixels and truth
// (random_scenes_test, scenarios_test).
#pragma once

#include <cstddef>
#include <cstdint>

#include <opencv2/core.hpp>

#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers::fixtures {

// FNV-1a's offset basis: the hash of nothing.
inline constexpr uint64_t kFnvOffset = 0xCBF29CE484222325ull;

// FNV-1a over the bytes of a matrix, continuing from `h`.
inline uint64_t Fnv1a(uint64_t h, const cv::Mat& m) {
  const cv::Mat c = m.isContinuous() ? m : m.clone();
  const auto* p = c.ptr<uint8_t>();
  const size_t n = c.total() * c.elemSize();
  for (size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 0x100000001B3ull;
  }
  return h;
}

// `h` continued over a frame: both images, then the truth's disparity and object maps.
inline uint64_t HashFrame(uint64_t h, const StereoFrame& frame, const FrameTruth& truth) {
  h = Fnv1a(h, frame.left);
  h = Fnv1a(h, frame.right);
  h = Fnv1a(h, truth.disparity_px);
  return Fnv1a(h, truth.object_id);
}

}  // namespace stevi::drivers::fixtures
