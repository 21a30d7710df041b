#include "drivers/gstreamer/gst_errors.h"

#include <array>
#include <utility>

#include "drivers/gstreamer/gst_ptr.h"

namespace stevi::drivers::gst {
namespace {

struct ElementPackage {
  std::string_view element;
  std::string_view package;
};

constexpr std::string_view kBase = "gstreamer1.0-plugins-base";
constexpr std::string_view kGood = "gstreamer1.0-plugins-good";
constexpr std::string_view kBad = "gstreamer1.0-plugins-bad";
constexpr std::string_view kUgly = "gstreamer1.0-plugins-ugly";
constexpr std::string_view kLibav = "gstreamer1.0-libav";
constexpr std::string_view kNvidia = "NVIDIA's JetPack (nvidia-l4t-gstreamer), not Debian";

// Where the elements of stereo pipelines come from on Debian 12 (apt-cache show's
// Gstreamer-Elements field).
constexpr std::array kPackages = {
    ElementPackage{"filesrc", "libgstreamer1.0-0"},
    ElementPackage{"queue", "libgstreamer1.0-0"},
    ElementPackage{"tee", "libgstreamer1.0-0"},
    ElementPackage{"appsink", kBase},
    ElementPackage{"appsrc", kBase},
    ElementPackage{"videoconvert", kBase},
    ElementPackage{"videoscale", kBase},
    ElementPackage{"videorate", kBase},
    ElementPackage{"videotestsrc", kBase},
    ElementPackage{"decodebin", kBase},
    ElementPackage{"decodebin3", kBase},
    ElementPackage{"uridecodebin", kBase},
    ElementPackage{"compositor", kBase},
    ElementPackage{"rawvideoparse", kBase},
    ElementPackage{"v4l2src", kGood},
    ElementPackage{"jpegdec", kGood},
    ElementPackage{"jpegenc", kGood},
    ElementPackage{"pngdec", kGood},
    ElementPackage{"rtspsrc", kGood},
    ElementPackage{"rtpjpegdepay", kGood},
    ElementPackage{"rtph264depay", kGood},
    ElementPackage{"rtph265depay", kGood},
    ElementPackage{"rtpjitterbuffer", kGood},
    ElementPackage{"udpsrc", kGood},
    ElementPackage{"souphttpsrc", kGood},
    ElementPackage{"multipartdemux", kGood},
    ElementPackage{"multifilesrc", kGood},
    ElementPackage{"avidemux", kGood},
    ElementPackage{"avimux", kGood},
    ElementPackage{"matroskademux", kGood},
    ElementPackage{"matroskamux", kGood},
    ElementPackage{"qtdemux", kGood},
    ElementPackage{"v4l2h264dec", kGood},
    ElementPackage{"h264parse", kBad},
    ElementPackage{"h265parse", kBad},
    ElementPackage{"jpegparse", kBad},
    ElementPackage{"tsdemux", kBad},
    ElementPackage{"vah264dec", kBad},
    ElementPackage{"avdec_h264", kLibav},
    ElementPackage{"avdec_h265", kLibav},
    ElementPackage{"avdec_mjpeg", kLibav},
    ElementPackage{"x264enc", kUgly},
    ElementPackage{"vaapih264dec", "gstreamer1.0-vaapi"},
    ElementPackage{"libcamerasrc",
                   "gstreamer1.0-libcamera (on a Raspberry Pi, Raspberry Pi OS's own build)"},
    ElementPackage{"nvarguscamerasrc", kNvidia},
    ElementPackage{"nvvidconv", kNvidia},
    ElementPackage{"nvv4l2decoder", kNvidia},
};

// Longest debug detail kept in a message, characters.
constexpr size_t kMaxDetail = 160;

std::string WithoutFinalPeriod(std::string text) {
  while (!text.empty() && (text.back() == '.' || text.back() == ' ')) text.pop_back();
  return text;
}

// The last non-empty line of a debug string: its most specific part ("system error: No such file
// or directory", "Missing decoder: H.264 (...)"); "" when it has a single line (a source location
// and an object path, which say nothing to an operator).
std::string DebugDetail(const char* debug) {
  if (debug == nullptr) return "";
  std::string text(debug);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  const size_t newline = text.rfind('\n');
  if (newline == std::string::npos) return "";
  text = text.substr(newline + 1);
  // Caps with codec data run to hundreds of characters.
  if (text.size() > kMaxDetail) text = text.substr(0, kMaxDetail) + " [...]";
  return text;
}

std::string_view SourceName(GstMessage* message) {
  const char* name = GST_MESSAGE_SRC_NAME(message);
  return name != nullptr ? name : "pipeline";
}

ErrorCode CodeOf(const GError& error, const std::string& detail) {
  if (error.domain == GST_RESOURCE_ERROR) {
    return error.code == GST_RESOURCE_ERROR_NOT_FOUND ? ErrorCode::kNotFound
                                                      : ErrorCode::kUnavailable;
  }
  if (error.domain == GST_CORE_ERROR) {
    return error.code == GST_CORE_ERROR_MISSING_PLUGIN || error.code == GST_CORE_ERROR_NEGOTIATION
               ? ErrorCode::kInvalidArgument
               : ErrorCode::kUnavailable;
  }
  if (error.domain == GST_STREAM_ERROR) {
    switch (error.code) {
      case GST_STREAM_ERROR_CODEC_NOT_FOUND:
      case GST_STREAM_ERROR_TYPE_NOT_FOUND:
      case GST_STREAM_ERROR_WRONG_TYPE:
      case GST_STREAM_ERROR_DECODE:
      case GST_STREAM_ERROR_DEMUX:
      case GST_STREAM_ERROR_FORMAT:
      case GST_STREAM_ERROR_NOT_IMPLEMENTED: return ErrorCode::kInvalidArgument;
      default: break;
    }
    if (detail.find("not-negotiated") != std::string::npos) return ErrorCode::kInvalidArgument;
  }
  return ErrorCode::kUnavailable;
}

// What to install when the error is a missing decoder of a usual codec.
std::string DecoderHint(const std::string& text) {
  if (text.find("video/x-h264") != std::string::npos) {
    return " (H.264 needs h264parse from gstreamer1.0-plugins-bad and avdec_h264 from "
           "gstreamer1.0-libav)";
  }
  if (text.find("video/x-h265") != std::string::npos) {
    return " (H.265 needs h265parse from gstreamer1.0-plugins-bad and avdec_h265 from "
           "gstreamer1.0-libav)";
  }
  if (text.find("not-negotiated") != std::string::npos) {
    return " (the elements agreed on no format: check the caps, e.g. the width, height and "
           "framerate the device offers: gst-inspect-1.0, v4l2-ctl --list-formats-ext)";
  }
  return "";
}

}  // namespace

std::string_view PackageOfElement(std::string_view element) {
  for (const ElementPackage& e : kPackages) {
    if (e.element == element) return e.package;
  }
  return {};
}

Error ParseFailure(const GError& error, GstParseContext* context) {
  std::string message;
  if (error.domain == GST_PARSE_ERROR && error.code == GST_PARSE_ERROR_NO_SUCH_ELEMENT) {
    StrvPtr missing(context != nullptr ? gst_parse_context_get_missing_elements(context) : nullptr);
    std::string list;
    std::string packages;
    for (gchar** e = missing.get(); e != nullptr && *e != nullptr; ++e) {
      list += (list.empty() ? "'" : ", '") + std::string(*e) + "'";
      const std::string_view package = PackageOfElement(*e);
      if (!package.empty() && packages.find(package) == std::string::npos) {
        packages += (packages.empty() ? "" : ", ") + std::string(package);
      }
    }
    if (list.empty()) return InvalidArgument(message + error.message);
    message += "no GStreamer element " + list;
    message += packages.empty() ? " (misspelt, or its plugin is not installed: gst-inspect-1.0 "
                                  "NAME tells)"
                                : " (install " + packages + ")";
    return InvalidArgument(message);
  }
  return InvalidArgument(message + "bad pipeline: " + error.message);
}

Error BusFailure(GstMessage* message) {
  GError* raw_error = nullptr;
  gchar* raw_debug = nullptr;
  gst_message_parse_error(message, &raw_error, &raw_debug);
  const ErrorPtr error(raw_error);
  const CharPtr debug(raw_debug);
  const std::string detail = DebugDetail(debug.get());
  const std::string all = detail + (debug ? std::string(" ") + debug.get() : "");
  std::string text = std::string(SourceName(message)) + ": " +
                     WithoutFinalPeriod(error ? error->message : "unknown error");
  if (!detail.empty()) text += " (" + WithoutFinalPeriod(detail) + ")";
  text += DecoderHint(all);
  const ErrorCode code = error ? CodeOf(*error, all) : ErrorCode::kUnavailable;
  return Error{code, std::move(text)};
}

std::string ShortReason(GstMessage* message) {
  GError* raw_error = nullptr;
  gst_message_parse_error(message, &raw_error, nullptr);
  const ErrorPtr error(raw_error);
  return WithoutFinalPeriod(error ? error->message : "unknown error");
}

std::string WarningText(GstMessage* message) {
  GError* raw_error = nullptr;
  gchar* raw_debug = nullptr;
  gst_message_parse_warning(message, &raw_error, &raw_debug);
  const ErrorPtr error(raw_error);
  const CharPtr debug(raw_debug);
  std::string text = std::string(SourceName(message)) + ": " +
                     WithoutFinalPeriod(error ? error->message : "unknown warning");
  if (const std::string detail = DebugDetail(debug.get()); !detail.empty()) {
    text += " (" + WithoutFinalPeriod(detail) + ")";
  }
  return text;
}

}  // namespace stevi::drivers::gst
