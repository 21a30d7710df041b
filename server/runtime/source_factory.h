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
  std::string gst_device = "/dev/video0";  // uvc
  std::string gst_url;                     // rtsp
  std::string gst_file;                    // video
  int gst_latency_ms = 100;                // rtsp
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
