// Unaligned loads and stores of GCC vector types, shared by the SIMD matchers
// (block_matcher_kernels.cc, dense_matcher.cc, dense_confidence.cc). Vector arguments by
// reference: no ABI questions without AVX.
#pragma once

#include <cstring>

namespace stevi::stereo::simd {

template <typename V>
[[gnu::always_inline]] inline void Load(V& v, const void* p) {
  std::memcpy(&v, p, sizeof v);
}
template <typename V>
[[gnu::always_inline]] inline void Store(void* p, const V& v) {
  std::memcpy(p, &v, sizeof v);
}

}  // namespace stevi::stereo::simd
