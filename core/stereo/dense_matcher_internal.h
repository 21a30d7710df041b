// Internal to core/stereo: the sizes of DenseMatcher's confidence tables, shared by
// dense_matcher.cc (the constructor fills the frame-independent tables) and dense_confidence.cc
// (Confidence reads them). Not part of the library's interface.
#pragma once

namespace stevi::stereo::internal {

inline constexpr int kMarginBins = 256;  // margin (summed over paths), capped
// The logistic's table: z in [-kZRange, kZRange] in steps of 1 / kZSteps.
inline constexpr int kZRange = 12, kZSteps = 32;

}  // namespace stevi::stereo::internal
