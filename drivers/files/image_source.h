// Image sequences (printf-style patterns) and video files as a stereo source.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "drivers/stereo_source.h"

namespace stevi::drivers {

struct ImageSourceOptions {
  // Either printf-style patterns with one integer conversion ("left_%04d.png") or video files
  // (any file OpenCV's VideoCapture opens; chosen when the path has no '%').
  std::string left;
  std::string right;
  // Calibration YAML of the rig (required).
  std::string calibration;
  // Frames per second to pace live playback at (> 0).
  double fps = 10.0;
  // First index tried for patterns; the sequence ends at the first missing index.
  int first_index = 0;
  // Start again at the beginning at the end of the sequence (the server's demo loops).
  bool loop = false;

  std::vector<std::string> Validate() const;
};

// Opens the sequence, checks that the first pair exists, is readable and matches the calibration's
// image size. Errors name the file.
Result<std::unique_ptr<StereoSource>> OpenImageSource(const ImageSourceOptions& options);

}  // namespace stevi::drivers
