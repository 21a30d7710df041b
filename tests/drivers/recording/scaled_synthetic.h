// The synthetic scene at a small size, for the recording driver's tests (recording_test,
// replay_source_test): small frames keep recordings quick to write and read.
#pragma once

#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers::fixtures {

// The default scene rendered at width x height with the default rig's field of view (the focal
// length scaled from 700 px at 640 wide).
inline SyntheticOptions ScaledSynthetic(int width, int height) {
  SyntheticOptions o;
  o.width = width;
  o.height = height;
  o.f_px = 700.0 * width / 640.0;
  return o;
}

}  // namespace stevi::drivers::fixtures
