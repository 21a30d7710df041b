#include "core/calibration/image_header.h"

#include <algorithm>
#include <climits>
#include <cstdio>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

namespace stevi::calibration {
namespace {

constexpr std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};

std::uint32_t BigEndian32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

int BigEndian16(const std::uint8_t* p) { return (int{p[0]} << 8) | int{p[1]}; }

// The first bytes in hex, for "not a PNG or JPEG image (starts with 47 49 46 38)".
std::string FirstBytes(std::span<const std::uint8_t> bytes) {
  std::string out;
  char buf[4];
  for (std::size_t i = 0; i < bytes.size() && i < 4; ++i) {
    std::snprintf(buf, sizeof buf, "%02x", static_cast<unsigned>(bytes[i]));
    if (!out.empty()) out += ' ';
    out += buf;
  }
  return out.empty() ? std::string("nothing") : out;
}

Result<cv::Size> PngSize(std::span<const std::uint8_t> bytes) {
  // Signature (8), then the first chunk: length (4) = 13, type "IHDR", width (4), height (4).
  if (bytes.size() < 24) {
    return InvalidArgument("truncated PNG header (" + std::to_string(bytes.size()) +
                           " bytes, the IHDR chunk needs 24)");
  }
  const std::uint8_t* p = bytes.data() + 8;
  if (BigEndian32(p) != 13 || p[4] != 'I' || p[5] != 'H' || p[6] != 'D' || p[7] != 'R') {
    return InvalidArgument("malformed PNG: the first chunk is not a 13-byte IHDR");
  }
  const std::uint32_t width = BigEndian32(p + 8);
  const std::uint32_t height = BigEndian32(p + 12);
  if (width == 0 || height == 0 || width > INT_MAX || height > INT_MAX) {
    return InvalidArgument("malformed PNG: IHDR size " + std::to_string(width) + "x" +
                           std::to_string(height) + " is out of range");
  }
  return cv::Size(static_cast<int>(width), static_cast<int>(height));
}

bool IsStartOfFrame(int marker) {
  // SOF0..SOF15 are C0..CF, except C4 (DHT), C8 (JPG extension) and CC (DAC).
  return marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
}

Result<cv::Size> JpegSize(std::span<const std::uint8_t> bytes) {
  const std::size_t n = bytes.size();
  const std::uint8_t* b = bytes.data();
  std::size_t pos = 2;  // after SOI
  while (true) {
    if (pos >= n)
      return InvalidArgument("truncated JPEG: no frame header (SOFn) before the data ends");
    if (b[pos] != 0xFF) {
      return InvalidArgument("malformed JPEG: expected a marker at byte " + std::to_string(pos));
    }
    while (pos < n && b[pos] == 0xFF) ++pos;  // fill bytes
    if (pos >= n)
      return InvalidArgument("truncated JPEG: no frame header (SOFn) before the data ends");
    const int marker = b[pos++];
    if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) continue;
    if (marker == 0xD9)
      return InvalidArgument("malformed JPEG: the image ends (EOI) before a frame header");
    if (marker == 0x00)
      return InvalidArgument("malformed JPEG: a stuffed 0xFF00 outside the image data");
    if (pos + 2 > n) return InvalidArgument("truncated JPEG: a segment length is cut off");
    const int length = BigEndian16(b + pos);  // includes the two length bytes
    if (length < 2) return InvalidArgument("malformed JPEG: a segment length below 2");
    if (IsStartOfFrame(marker)) {
      // precision (1), height (2), width (2), components (1).
      if (length < 8 || pos + 7 > n) return InvalidArgument("truncated JPEG frame header (SOFn)");
      const int height = BigEndian16(b + pos + 3);
      const int width = BigEndian16(b + pos + 5);
      if (height == 0) {
        return InvalidArgument("unsupported JPEG: the height is given later (DNL marker)");
      }
      if (width == 0) return InvalidArgument("malformed JPEG: zero width in the frame header");
      return cv::Size(width, height);
    }
    if (marker == 0xDA)
      return InvalidArgument("malformed JPEG: image data (SOS) before a frame header");
    pos += static_cast<std::size_t>(length);
  }
}

}  // namespace

Result<cv::Size> ImageHeaderSize(std::span<const std::uint8_t> bytes) {
  const std::size_t png_prefix = std::min<std::size_t>(bytes.size(), 8);
  if (bytes.size() >= 4 && std::equal(kPngSignature, kPngSignature + png_prefix, bytes.begin())) {
    return PngSize(bytes);
  }
  if (bytes.size() >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8) return JpegSize(bytes);
  if (bytes.empty()) return InvalidArgument("empty image data (expected PNG or JPEG bytes)");
  return InvalidArgument("not a PNG or JPEG image (starts with " + FirstBytes(bytes) + ")");
}

Result<cv::Size> ImageHeaderSize(const std::string& bytes) {
  return ImageHeaderSize(std::span<const std::uint8_t>(
      reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()));
}

Result<cv::Mat> DecodeGreyImage(std::span<const std::uint8_t> bytes, cv::Size max_size) {
  Result<cv::Size> header = ImageHeaderSize(bytes);
  if (!header.ok()) return header.error();
  const cv::Size size = *header;
  if (size.width > max_size.width || size.height > max_size.height) {
    std::ostringstream s;
    s << "image of " << size.width << "x" << size.height << " pixels exceeds the maximum of "
      << max_size.width << "x" << max_size.height << "; not decoded";
    return ResourceExhausted(s.str());
  }
  if (bytes.size() > static_cast<std::size_t>(INT_MAX)) {
    return ResourceExhausted("image data larger than 2 GiB; not decoded");
  }
  cv::Mat grey;
  try {
    const cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1,
                         const_cast<std::uint8_t*>(bytes.data()));
    grey = cv::imdecode(buffer, cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& e) {
    return InvalidArgument("cannot decode the image (" + e.err + ")");
  }
  if (grey.empty()) return InvalidArgument("cannot decode the image (corrupt or truncated data)");
  if (grey.size() != size) {
    std::ostringstream s;
    s << "the image decoded to " << grey.cols << "x" << grey.rows << " but its header says "
      << size.width << "x" << size.height;
    return InvalidArgument(s.str());
  }
  if (grey.type() != CV_8UC1) {
    cv::Mat converted;
    grey.convertTo(converted, CV_8U);
    grey = converted;
  }
  return grey;
}

}  // namespace stevi::calibration
