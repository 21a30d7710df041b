// Fuzz target: the images a client uploads for a calibration (CalibrationService.Calibrate's
// ImagePair bytes), through the path core/calibration/calibrate.cc takes them: the header check
// (ImageHeaderSize: the PNG IHDR or the JPEG SOFn size, before anything is decoded) and
// DecodeGreyImage (the size limit, then cv::imdecode).
//
// Input: byte 0 picks the size limit (CalibrationOptions::max_image_size: a square of 16, 64, 256,
// 1024 or 4096 pixels a side, the default); the rest is the uploaded file.
// Checked besides the sanitizers:
//   - both ImageHeaderSize overloads agree;
//   - an image whose header is refused, or announces more than the limit, is not decoded
//     (DecodeGreyImage fails, kResourceExhausted for an oversized one);
//   - a decoded image is 8-bit grey, exactly the header's size, so at most the limit's pixels.
// Run it with -malloc_limit_mb=256 so that a decoder allocating for more
// pixels than the header announced is reported, not just a decoded size that differs.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/calibration/image_header.h"
#include "tests/fuzz/require.h"

namespace calibration = stevi::calibration;

using stevi::fuzz::Require;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  static constexpr int kSides[] = {16, 64, 256, 1024, 4096};
  const int side = kSides[data[0] % 5];
  const cv::Size limit(side, side);
  const std::span<const uint8_t> bytes(data + 1, size - 1);

  const stevi::Result<cv::Size> header = calibration::ImageHeaderSize(bytes);
  const stevi::Result<cv::Size> header_of_string = calibration::ImageHeaderSize(
      std::string(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  Require(header.ok() == header_of_string.ok());
  if (header.ok()) {
    Require(*header == *header_of_string);
    Require(header->width > 0 && header->height > 0);
  } else {
    Require(header.error().message == header_of_string.error().message);
  }

  const stevi::Result<cv::Mat> grey = calibration::DecodeGreyImage(bytes, limit);
  if (!header.ok()) {
    Require(!grey.ok());
    return 0;
  }
  const bool too_large = header->width > limit.width || header->height > limit.height;
  if (too_large) {
    Require(!grey.ok() && grey.error().code == stevi::ErrorCode::kResourceExhausted);
    return 0;
  }
  if (!grey.ok()) return 0;
  Require(grey->type() == CV_8UC1 && grey->size() == *header);
  Require(grey->cols <= limit.width && grey->rows <= limit.height);
  return 0;
}
