#include "drivers/gstreamer/pipelines.h"

#include <cstdint>

namespace stevi::drivers {
namespace {

// The length of the UTF-8 sequence that starts at text[i], or 0 when it is not a valid one
// (overlong forms, surrogates and code points above U+10FFFF are invalid too).
size_t Utf8SequenceLength(std::string_view text, size_t i) {
  const auto byte = [&](size_t k) { return static_cast<uint8_t>(text[k]); };
  const uint8_t b0 = byte(i);
  if (b0 < 0x80) return 1;
  size_t length = 0;
  uint32_t code = 0;
  if ((b0 & 0xE0) == 0xC0) {
    length = 2;
    code = b0 & 0x1Fu;
  } else if ((b0 & 0xF0) == 0xE0) {
    length = 3;
    code = b0 & 0x0Fu;
  } else if ((b0 & 0xF8) == 0xF0) {
    length = 4;
    code = b0 & 0x07u;
  } else {
    return 0;
  }
  if (i + length > text.size()) return 0;
  for (size_t k = 1; k < length; ++k) {
    if ((byte(i + k) & 0xC0) != 0x80) return 0;
    code = (code << 6) | (byte(i + k) & 0x3Fu);
  }
  static constexpr uint32_t kMinimum[] = {0, 0, 0x80, 0x800, 0x10000};
  if (code < kMinimum[length] || code > 0x10FFFF || (code >= 0xD800 && code <= 0xDFFF)) return 0;
  return length;
}

// A printable rendering of a rejected value for the error message (control bytes as \xNN).
std::string Printable(std::string_view value) {
  std::string out;
  for (const char c : value) {
    const auto b = static_cast<uint8_t>(c);
    if (b < 0x20 || b == 0x7F) {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[b >> 4];
      out += kHex[b & 0xF];
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

Result<std::string> QuoteGstValue(std::string_view value, std::string_view what) {
  const std::string name(what);
  if (value.empty()) return InvalidArgument(name + ": must not be empty");
  if (value == "NULL") {
    return InvalidArgument(name +
                           ": 'NULL' cannot be passed to GStreamer (it reads it as no string)");
  }
  for (size_t i = 0; i < value.size();) {
    const auto b = static_cast<uint8_t>(value[i]);
    if (b < 0x20 || b == 0x7F) {
      return InvalidArgument(name + ": contains a control character at byte " + std::to_string(i) +
                             " (got '" + Printable(value) + "')");
    }
    if (value[i] == '\\' || value[i] == '"') {
      return InvalidArgument(name + ": contains " +
                             (value[i] == '"' ? "a double quote" : "a backslash") +
                             ", which a GStreamer pipeline description cannot quote safely (got '" +
                             std::string(value) + "')");
    }
    const size_t length = Utf8SequenceLength(value, i);
    if (length == 0) {
      return InvalidArgument(name + ": is not valid UTF-8 at byte " + std::to_string(i));
    }
    i += length;
  }
  return "\"" + std::string(value) + "\"";
}

Result<std::string> UvcPipeline(std::string_view device, int width, int height, int fps) {
  Result<std::string> quoted = QuoteGstValue(device, "device");
  if (!quoted.ok()) return quoted.error();
  std::string problems;
  if (width < 16 || width > 16384) problems += "width: must be in [16, 16384] pixels" + Got(width);
  if (height < 16 || height > 16384) {
    problems += std::string(problems.empty() ? "" : "; ") +
                "height: must be in [16, 16384] pixels" + Got(height);
  }
  if (fps < 1 || fps > 1000) {
    problems += std::string(problems.empty() ? "" : "; ") + "fps: must be in [1, 1000]" + Got(fps);
  }
  if (!problems.empty()) return InvalidArgument(problems);
  return "v4l2src device=" + quoted.value() + " ! image/jpeg,width=" + std::to_string(width) +
         ",height=" + std::to_string(height) + ",framerate=" + std::to_string(fps) + "/1 ! jpegdec";
}

Result<std::string> RtspPipeline(std::string_view url, int latency_ms) {
  if (!url.starts_with("rtsp://") && !url.starts_with("rtsps://") && !url.starts_with("rtspt://")) {
    return InvalidArgument("url: must start with rtsp://, rtsps:// or rtspt:// (got '" +
                           Printable(url) + "')");
  }
  Result<std::string> quoted = QuoteGstValue(url, "url");
  if (!quoted.ok()) return quoted.error();
  if (latency_ms < 0 || latency_ms > 10000) {
    return InvalidArgument("latency_ms: must be in [0, 10000] ms" + Got(latency_ms));
  }
  return "rtspsrc location=" + quoted.value() +
         " protocols=tcp latency=" + std::to_string(latency_ms) +
         " ! application/x-rtp,media=video ! decodebin";
}

Result<std::string> VideoFilePipeline(std::string_view path) {
  Result<std::string> quoted = QuoteGstValue(path, "path");
  if (!quoted.ok()) return quoted.error();
  return "filesrc location=" + quoted.value() + " ! decodebin";
}

std::string GstSinkTail(bool live) {
  return " ! videoconvert ! video/x-raw,format=" + std::string(kGstLumaFormats) +
         " ! appsink name=" + std::string(kGstSinkName) + (live ? " drop=true" : " drop=false") +
         " max-buffers=2 sync=false emit-signals=false enable-last-sample=false";
}

bool MentionsGstSinkName(std::string_view pipeline) {
  return pipeline.find(kGstSinkName) != std::string_view::npos;
}

}  // namespace stevi::drivers
