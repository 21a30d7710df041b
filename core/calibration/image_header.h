// Untrusted encoded images: read the size from the header before decoding, then decode.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"

namespace stevi::calibration {

// Width and height (pixels) from a PNG (the IHDR chunk) or baseline/progressive JPEG (the first
// SOFn frame header) without decoding the image. Any other format, a truncated or malformed
// header, or a zero size gives kInvalidArgument naming the problem. Reads only the header bytes;
// never throws.
Result<cv::Size> ImageHeaderSize(std::span<const std::uint8_t> bytes);
Result<cv::Size> ImageHeaderSize(const std::string& bytes);

// Decodes PNG or JPEG bytes into an 8-bit grey image. The header size is checked first: an image
// wider or taller than `max_size` is refused with kResourceExhausted without being decoded (a
// decompression bomb costs nothing). Other formats, and bytes that do not decode to the size the
// header announced, give kInvalidArgument. Never throws.
Result<cv::Mat> DecodeGreyImage(std::span<const std::uint8_t> bytes, cv::Size max_size);

}  // namespace stevi::calibration
