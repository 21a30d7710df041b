// Where frames come from: every kind of source the server opens, in one table. A new kind of source
// is one entry in source_factory.cc (its checks and how it opens) plus its driver; the server's
// configuration names it by the SourceConfig.kind value of the same name (SOURCE_KIND_<NAME>).
#pragma once

#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/error.h"
#include "core/common/fields.h"
#include "drivers/aravis/aravis_source.h"
#include "drivers/files/image_source.h"
#include "drivers/gstreamer/gst_source.h"
#include "drivers/recording/replay_source.h"
#include "drivers/stereo_source.h"
#include "drivers/synthetic/chessboard_source.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::server {

// What the configuration says about the source, as the drivers take it. The options of every
// kind are filled (the server maps them from a stevi.v1.SourceConfig by name); the kind's entry
// uses its own. Problems are named by the configuration's paths ("source.left").
// What the GStreamer kinds' pipelines are built from (stevi.v1.GstConfig's fields besides the
// driver's own, drivers::GstOptions).
struct GstInputs {
  std::string device = "/dev/video0";
  std::string url;
  std::string file;
  int latency_ms = 100;

  std::vector<std::string> Validate() const { return fields::Check(*this); }

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Text(s.device, Field("device", "", "uvc: the V4L2 device").Flag("device", "DEV"));
    v.Text(s.url, Field("url", "", "rtsp: rtsp://host[:port]/path").Flag("url", "URL"));
    v.Text(s.file, Field("file", "",
                         "video: a video file GStreamer decodes (MJPEG AVI or MKV with Debian's "
                         "base and good plugins)")
                       .Flag("file", "FILE"));
    v.Number(s.latency_ms,
             Field("latency_ms", "ms", "rtsp: the jitter buffer").In(0, 5000).Flag("latency-ms"));
  }
};

struct SourceSpec {
  std::string kind = "synthetic";  // a SourceKinds() name
  // images: the two files or patterns and the calibration; aravis: the cameras' ids and an
  // optional calibration. Empty: not given.
  std::string left, right, calibration;
  std::string scene;                            // synthetic: a drivers::SceneNames() name
  drivers::SyntheticOptions synthetic;          // the scene's options, its scenario applied
  drivers::ChessboardSourceOptions chessboard;  // the chessboard scene's
  drivers::ImageSourceOptions images;
  drivers::AravisOptions aravis;
  std::string replay_dir;
  drivers::ReplayOptions replay;
  // gst, uvc, rtsp, video: the source's options (their pipelines are built from the shorthand's
  // fields below, or given whole for gst); left and right above name the two devices, URLs or
  // files of the layout "two".
  drivers::GstOptions gst;
  GstInputs gst_inputs;  // uvc's device, rtsp's URL and latency, video's file
};

struct SourceKind {
  std::string_view name;         // "synthetic", "images", "aravis", "replay", "gst", ...
  std::string_view description;  // for --help and errors
  // Problems of the spec for this kind, before anything is opened.
  std::vector<std::string> (*check)(const SourceSpec& spec);
  Result<std::unique_ptr<drivers::StereoSource>> (*open)(const SourceSpec& spec);
};

// Every kind, the default (synthetic) first.
std::span<const SourceKind> SourceKinds();
// The kind of that name, or null.
const SourceKind* FindSourceKind(std::string_view name);
// "synthetic, images, aravis, replay".
std::string SourceKindNames();

// The spec's problems: an unknown kind, or its kind's checks.
std::vector<std::string> CheckSource(const SourceSpec& spec);
// Opens the spec's kind. Errors name the configuration's part ("source.aravis: ...").
Result<std::unique_ptr<drivers::StereoSource>> OpenSource(const SourceSpec& spec);

}  // namespace stevi::server
