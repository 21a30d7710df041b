// Internal to drivers/synthetic: the renderer's noise and procedural textures. Hashed lattice
// values, smooth value noise, the multi-octave surface texture (its octaves faded out below the
// pixel's footprint) and the triplanar blend of three such textures by a surface normal. Used per
// pixel by the shading in renderer.cc and by the clouds in textures.cc. Inline and in an unnamed
// namespace on purpose: every includer gets its own copy, which the compiler inlines into the
// per-pixel loop as readily as a file-local helper (with external linkage instead, some scenes
// render up to a quarter slower). Only renderer.cc and textures.cc include it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace stevi::drivers::internal {
namespace {  // internal linkage on purpose: see above

// Texture octaves: cell sizes 1, 3 and 9 times the finest cell, and their weights.
constexpr int kOctaves = 3;
constexpr double kOctaveScale[kOctaves] = {1.0, 3.0, 9.0};
constexpr float kOctaveWeight[kOctaves] = {0.5f, 0.3f, 0.2f};
// Triplanar texture blend: a plane counts where its squared normal component exceeds this
// fraction of the largest.
constexpr double kHillBlendFloor = 0.6;

inline uint32_t Fmix32(uint32_t h) {
  h ^= h >> 16;
  h *= 0x85EBCA6Bu;
  h ^= h >> 13;
  h *= 0xC2B2AE35u;
  h ^= h >> 16;
  return h;
}

// Hashed lattice value in [0, 1).
inline float Lattice(uint32_t seed, int64_t i, int64_t j) {
  const uint32_t h = Fmix32(seed + static_cast<uint32_t>(i) * 0x9E3779B1u +
                            static_cast<uint32_t>(j) * 0x85EBCA77u);
  return static_cast<float>(h >> 8) * (1.0f / 16777216.0f);
}

inline float SmoothStep(float x) { return x * x * (3.0f - 2.0f * x); }

// Smooth (C1) value noise in [0, 1) at lattice coordinates (s, t).
inline float ValueNoise(uint32_t seed, double s, double t) {
  const double fs = std::floor(s);
  const double ft = std::floor(t);
  const auto i = static_cast<int64_t>(fs);
  const auto j = static_cast<int64_t>(ft);
  const float ws = SmoothStep(static_cast<float>(s - fs));
  const float wt = SmoothStep(static_cast<float>(t - ft));
  const float v00 = Lattice(seed, i, j);
  const float v10 = Lattice(seed, i + 1, j);
  const float v01 = Lattice(seed, i, j + 1);
  const float v11 = Lattice(seed, i + 1, j + 1);
  const float a = v00 + (v10 - v00) * ws;
  const float b = v01 + (v11 - v01) * ws;
  return a + (b - a) * wt;
}

// Multi-octave texture at surface coordinates (s, t) metres, zero-mean, within +-0.5.
// Octaves finer than 2 px fade out (gone at 1 px): footprint_m is the size of one pixel on the
// surface. It depends on the depth only, so both views shade a world point alike.
inline float Texture(uint32_t seed, double s, double t, double cell_m, double footprint_m) {
  float sum = 0.0f;
  for (int k = 0; k < kOctaves; ++k) {
    const double cell = cell_m * kOctaveScale[k];
    const float fade = static_cast<float>(std::clamp(cell / footprint_m - 1.0, 0.0, 1.0));
    if (fade <= 0.0f) continue;
    const uint32_t octave_seed = seed + static_cast<uint32_t>(k) * 0x632BE5ABu;
    // Offsets keep the lattices of the octaves from lining up.
    const float n = ValueNoise(octave_seed, s / cell + 0.37 * k, t / cell + 0.61 * k);
    sum += kOctaveWeight[k] * fade * (n - 0.5f);
  }
  return sum;
}

// Triplanar texture at (x, y, z) for the unit normal n: the textures of the planes facing x, y
// and z (seeds seed[0..2], sampled on (z, y), (x, z) and (x, y)), weighted by n_i^2 above
// kHillBlendFloor times the largest n_j^2, normalised. Continuous in the normal, and only one or
// two planes are sampled per pixel (the texture is the cost).
inline float Triplanar(const double n[3], const uint32_t seed[3], double x, double y, double z,
                       double cell_m, double footprint_m) {
  const double n2[3] = {n[0] * n[0], n[1] * n[1], n[2] * n[2]};
  const double floor2 = kHillBlendFloor * std::max({n2[0], n2[1], n2[2]});
  const double wx = std::max(0.0, n2[0] - floor2);
  const double wy = std::max(0.0, n2[1] - floor2);
  const double wz = std::max(0.0, n2[2] - floor2);
  const double w_sum = wx + wy + wz;
  float tex = 0.0f;
  if (w_sum > 0.0) {
    if (wy > 0.0)
      tex += static_cast<float>(wy / w_sum) * Texture(seed[1], x, z, cell_m, footprint_m);
    if (wz > 0.0)
      tex += static_cast<float>(wz / w_sum) * Texture(seed[2], x, y, cell_m, footprint_m);
    if (wx > 0.0)
      tex += static_cast<float>(wx / w_sum) * Texture(seed[0], z, y, cell_m, footprint_m);
  }
  return tex;
}

}  // namespace
}  // namespace stevi::drivers::internal
