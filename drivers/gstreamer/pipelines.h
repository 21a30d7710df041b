// gst-launch descriptions for the usual stereo sources, and the quoting of the user's strings
// (paths, devices, URLs) inside them. Pure functions of their arguments: no GStreamer needed.
#pragma once

#include <string>
#include <string_view>

#include "core/common/error.h"

namespace stevi::drivers {

// The name of the appsink the driver appends to every pipeline. A user pipeline must not use it.
inline constexpr std::string_view kGstSinkName = "stevi_sink";

// `value` as one double-quoted property value of a gst-launch description, e.g. "/v/a b.avi"
// becomes "\"/v/a b.avi\"": inside the quotes '!', spaces, '=' and the like are plain characters.
// kInvalidArgument, naming `what` ("path"), for what gst_parse_launch cannot take back unchanged:
// an empty string, a control character, a backslash or a double quote (its lexer has no
// unambiguous escape for them), invalid UTF-8, and the word NULL (read as no string at all).
Result<std::string> QuoteGstValue(std::string_view value, std::string_view what);

// A UVC camera delivering Motion-JPEG: "v4l2src device=\"DEVICE\" !
// image/jpeg,width=W,height=H,framerate=FPS/1 ! jpegdec". `width` and `height` are of the whole
// frame (both views side by side), pixels, 16..16384; `fps` frames per second, 1..1000.
Result<std::string> UvcPipeline(std::string_view device, int width, int height, int fps);

// An RTSP stream over TCP (interleaved: no UDP ports to open), its first video stream decoded by
// decodebin: "rtspsrc location=\"URL\" protocols=tcp latency=L ! application/x-rtp,media=video !
// decodebin". Motion-JPEG needs only Debian's plugins-base and -good (rtpjpegdepay, jpegdec);
// H.264 also needs h264parse (gstreamer1.0-plugins-bad) and avdec_h264 (gstreamer1.0-libav).
// `url` must start with rtsp://, rtsps:// or rtspt://; `latency_ms` is the jitter buffer's,
// 0..10000 ms (0 for the newest frame soonest).
Result<std::string> RtspPipeline(std::string_view url, int latency_ms);

// A video file decoded by decodebin: "filesrc location=\"PATH\" ! decodebin". An MJPEG AVI or
// MKV needs only plugins-base and -good.
Result<std::string> VideoFilePipeline(std::string_view path);

// The formats the appsink takes: each holds the luma the pipeline reads as it is, as a plane of
// its own (GRAY8 and the planar and semi-planar YUV formats) or every other byte (the packed 4:2:2
// ones). videoconvert passes any of them through untouched, so a decoder's I420 (jpegdec) or a
// UVC camera's YUY2 costs one copy of the luma; anything else (RGB, say) is converted.
inline constexpr std::string_view kGstLumaFormats =
    "{GRAY8,I420,YV12,NV12,NV21,Y42B,Y444,YUY2,YVYU,UYVY}";

// What the driver appends to a user pipeline: " ! videoconvert ! video/x-raw,format={luma
// formats} ! appsink name=stevi_sink ..." with, for a live source, drop=true max-buffers=2 (the
// newest frame wins), and for a file drop=false max-buffers=2 (every frame, the decoder waits for
// the reader).
std::string GstSinkTail(bool live);

// Whether `pipeline` mentions the driver's sink name (it would clash with the appended appsink).
bool MentionsGstSinkName(std::string_view pipeline);

}  // namespace stevi::drivers
