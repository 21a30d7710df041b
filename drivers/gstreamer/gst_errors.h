// GStreamer's errors (parse errors, ERROR messages of the bus) as stevi errors that say what to do.
// Internal to stevi_gstreamer and its tests: this header pulls in GStreamer.
#pragma once

#include <string>
#include <string_view>

#include <gst/gst.h>

#include "core/common/error.h"

namespace stevi::drivers::gst {

// The Debian 12 package that holds one of the usual elements ("gstreamer1.0-plugins-good" for
// v4l2src), or where it comes from when Debian has none (nvarguscamerasrc); "" when unknown.
std::string_view PackageOfElement(std::string_view element);

// A failed gst_parse_launch_full (`error` set) as kInvalidArgument: "no GStreamer element
// 'x264enc' (install gstreamer1.0-plugins-ugly)", or the parser's message for a syntax, link or
// property error.
Error ParseFailure(const GError& error, GstParseContext* context);

// An ERROR message as an error naming the element ("v4l2src0: Cannot identify device ..."):
// kNotFound for a missing device or file, kInvalidArgument for streams that do not decode or
// negotiate (with the packages a missing H.264/H.265 decoder needs), kUnavailable for the rest (a
// device that cannot be opened, a server that does not answer).
Error BusFailure(GstMessage* message);

// The ERROR's own text without its final period ("Could not read from resource").
std::string ShortReason(GstMessage* message);

// A WARNING's text with its element ("rtpjitterbuffer0: ...").
std::string WarningText(GstMessage* message);

}  // namespace stevi::drivers::gst
