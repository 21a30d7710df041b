#include "server/runtime/source_factory.h"

#include <cmath>
#include <functional>
#include <utility>

#include "core/common/fields.h"
#include "drivers/gstreamer/pipelines.h"
#include "drivers/synthetic/scenarios.h"

namespace stevi::server {
namespace {

template <class Source>
Result<std::unique_ptr<drivers::StereoSource>> Opened(Result<std::unique_ptr<Source>> source,
                                                      std::string_view prefix) {
  if (!source.ok()) return source.error().Prefixed(prefix);
  return std::unique_ptr<drivers::StereoSource>(std::move(source).value());
}

bool GivesFiles(const SourceSpec& spec) {
  return !spec.left.empty() || !spec.right.empty() || !spec.calibration.empty();
}

std::vector<std::string> CheckSynthetic(const SourceSpec& spec) {
  std::vector<std::string> problems;
  if (GivesFiles(spec)) {
    problems.push_back(
        "source: left, right and calibration are for the images source (--source images)");
  }
  if (spec.scene == drivers::kChessboardScene && spec.synthetic.loop_frames != 0) {
    problems.push_back("source.synthetic.loop_frames: not for the chessboard scene");
  }
  if (!drivers::IsKnownScene(spec.scene)) {
    std::string names;
    for (const std::string& name : drivers::SceneNames()) {
      names += (names.empty() ? "" : ", ") + name;
    }
    problems.push_back("source.synthetic.scene: unknown scene '" + spec.scene +
                       "' (one of: " + names + ")");
  }
  return problems;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenSynthetic(const SourceSpec& spec) {
  if (spec.scene == drivers::kChessboardScene) {
    return Opened(drivers::ChessboardSource::Open(spec.chessboard), "source.synthetic: ");
  }
  return Opened(drivers::OpenSyntheticSource(spec.synthetic), "source.synthetic: ");
}

std::vector<std::string> CheckImages(const SourceSpec& spec) {
  std::vector<std::string> problems;
  if (spec.left.empty()) problems.push_back("source.left: required for the images source");
  if (spec.right.empty()) problems.push_back("source.right: required for the images source");
  if (spec.calibration.empty()) {
    problems.push_back("source.calibration: required for the images source");
  }
  return problems;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenImages(const SourceSpec& spec) {
  return drivers::OpenImageSource(spec.images);
}

// The cameras' options: the spec's aravis options with its left and right ids.
drivers::AravisOptions AravisOf(const SourceSpec& spec) {
  drivers::AravisOptions options = spec.aravis;
  options.left_id = spec.left;
  options.right_id = spec.right;
  return options;
}

// The driver's own checks (drivers/aravis), each named by its config path: the cameras' ids are
// source.left and source.right, the rest source.aravis.FIELD.
std::vector<std::string> CheckAravis(const SourceSpec& spec) {
  std::vector<std::string> problems;
  for (const std::string& problem : AravisOf(spec).Validate()) {
    if (problem.rfind("left_id:", 0) == 0) {
      problems.push_back("source.left:" + problem.substr(8));
    } else if (problem.rfind("right_id:", 0) == 0) {
      problems.push_back("source.right:" + problem.substr(9));
    } else {
      problems.push_back("source.aravis." + problem);
    }
  }
  return problems;
}

// The calibration of a camera source: null when none is given (the data directory's active one
// applies later, if it fits).
Result<std::shared_ptr<const geometry::StereoRig>> OptionalRig(const SourceSpec& spec) {
  if (spec.calibration.empty()) return std::shared_ptr<const geometry::StereoRig>();
  Result<geometry::StereoRig> loaded = geometry::StereoRig::FromFile(spec.calibration);
  if (!loaded.ok()) return loaded.error().Prefixed("source.calibration: ");
  return std::make_shared<const geometry::StereoRig>(std::move(loaded).value());
}

Result<std::unique_ptr<drivers::StereoSource>> OpenAravis(const SourceSpec& spec) {
  Result<std::shared_ptr<const geometry::StereoRig>> rig = OptionalRig(spec);
  if (!rig.ok()) return rig.error();
  return Opened(drivers::AravisStereoSource::Open(AravisOf(spec), std::move(rig).value()),
                "source.aravis: ");
}

// ---- GStreamer: gst takes the pipelines whole; uvc, rtsp and video build them -------------------

bool TwoViews(const SourceSpec& spec) { return spec.gst.layout == drivers::GstLayout::kTwo; }

// The noun and field of each shorthand kind: what names one view's input.
struct Shorthand {
  std::string_view noun;   // "device"
  std::string_view field;  // "source.gst.device"
};
Shorthand ShorthandOf(const std::string& kind) {
  if (kind == "uvc") return {"device", "source.gst.device"};
  if (kind == "rtsp") return {"URL", "source.gst.url"};
  return {"file", "source.gst.file"};
}

// One pipeline per view of the layout, from the kind's shorthand (`one` builds a pipeline from a
// device, URL or file), or the problems.
Result<drivers::GstOptions> WithPipelines(
    const SourceSpec& spec, const std::string& single,
    const std::function<Result<std::string>(const std::string&)>& one) {
  const Shorthand what = ShorthandOf(spec.kind);
  drivers::GstOptions options = spec.gst;
  std::vector<std::string> problems;
  const auto build = [&](const std::string& from, const std::string& field, std::string& out) {
    if (from.empty()) {
      problems.push_back(field + ": required (the " + std::string(what.noun) + ")");
      return;
    }
    Result<std::string> pipeline = one(from);
    if (pipeline.ok()) {
      out = std::move(pipeline).value();
    } else {
      problems.push_back(field + ": " + pipeline.error().message);
    }
  };
  if (TwoViews(spec)) {
    build(spec.left, "source.left", options.left_pipeline);
    build(spec.right, "source.right", options.right_pipeline);
  } else {
    build(single, std::string(what.field), options.pipeline);
  }
  if (!problems.empty()) return InvalidArgument(problems);
  return options;
}

// The options the kind opens with: gst's as given, the others' with their pipelines built.
Result<drivers::GstOptions> GstOptionsOf(const SourceSpec& spec) {
  if (spec.kind == "gst") return spec.gst;
  if (spec.kind == "uvc") {
    if (spec.gst.width == 0 || spec.gst.height == 0) {
      return InvalidArgument(
          "source.gst.width, height: required for uvc (the size of one view, "
          "--size WxH; the camera is asked for the frame that holds both)");
    }
    // The camera's frame: both views side by side, one above the other, or one (two cameras).
    const int w =
        spec.gst.layout == drivers::GstLayout::kSideBySide ? 2 * spec.gst.width : spec.gst.width;
    const int h =
        spec.gst.layout == drivers::GstLayout::kTopBottom ? 2 * spec.gst.height : spec.gst.height;
    const int fps = static_cast<int>(std::lround(spec.gst.fps));
    return WithPipelines(spec, spec.gst_inputs.device, [&](const std::string& device) {
      return drivers::UvcPipeline(device, w, h, fps);
    });
  }
  if (spec.kind == "rtsp") {
    return WithPipelines(spec, spec.gst_inputs.url, [&](const std::string& url) {
      return drivers::RtspPipeline(url, spec.gst_inputs.latency_ms);
    });
  }
  return WithPipelines(spec, spec.gst_inputs.file,
                       [](const std::string& file) { return drivers::VideoFilePipeline(file); });
}

std::vector<std::string> CheckGst(const SourceSpec& spec) {
  std::vector<std::string> problems;
  const bool two = TwoViews(spec);
  if (spec.kind == "gst" && (!spec.left.empty() || !spec.right.empty())) {
    problems.push_back(
        "source.left, source.right: not for gst (its pipelines are "
        "source.gst.pipeline, or left_pipeline and right_pipeline with the layout "
        "two)");
  } else if (spec.kind != "gst" && !two && (!spec.left.empty() || !spec.right.empty())) {
    problems.push_back("source.left, source.right: only with the layout two (one " +
                       std::string(ShorthandOf(spec.kind).noun) + " per view)");
  }
  AppendPrefixed(problems, "source.gst.", spec.gst_inputs.Validate());
  Result<drivers::GstOptions> options = GstOptionsOf(spec);
  if (!options.ok()) {
    problems.push_back(options.error().message);
    return problems;
  }
  AppendPrefixed(problems, "source.gst.", options->Validate());
  return problems;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenGst(const SourceSpec& spec) {
  Result<drivers::GstOptions> options = GstOptionsOf(spec);
  if (!options.ok()) return options.error();
  Result<std::shared_ptr<const geometry::StereoRig>> rig = OptionalRig(spec);
  if (!rig.ok()) return rig.error();
  return Opened(drivers::GstStereoSource::Open(std::move(options).value(), std::move(rig).value()),
                "source." + spec.kind + ": ");
}

std::vector<std::string> CheckReplay(const SourceSpec& spec) {
  std::vector<std::string> problems;
  if (spec.replay_dir.empty()) {
    problems.push_back("source.replay.dir: required for the replay source (--replay DIR)");
  }
  if (GivesFiles(spec)) {
    problems.push_back(
        "source: left, right and calibration do not apply to a replay (the "
        "recording holds its frames and calibration)");
  }
  AppendPrefixed(problems, "source.replay.", spec.replay.Validate());
  return problems;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenReplay(const SourceSpec& spec) {
  return Opened(drivers::ReplaySource::Open(spec.replay_dir, spec.replay), "source.replay: ");
}

constexpr SourceKind kKinds[] = {
    {"synthetic", "the built-in synthetic rig (the default)", &CheckSynthetic, &OpenSynthetic},
    {"images", "image sequences or video files", &CheckImages, &OpenImages},
    {"aravis", "two GenICam cameras (GigE Vision or USB3 Vision) through Aravis", &CheckAravis,
     &OpenAravis},
    {"replay", "a recording", &CheckReplay, &OpenReplay},
    {"gst", "any GStreamer pipeline (--pipeline)", &CheckGst, &OpenGst},
    {"uvc", "a UVC stereo camera, or two webcams (--device, --layout)", &CheckGst, &OpenGst},
    {"rtsp", "an RTSP camera (--url)", &CheckGst, &OpenGst},
    {"video", "a video file, e.g. side by side (--file, --layout)", &CheckGst, &OpenGst},
};

}  // namespace

std::span<const SourceKind> SourceKinds() { return kKinds; }

const SourceKind* FindSourceKind(std::string_view name) {
  for (const SourceKind& kind : kKinds) {
    if (kind.name == name) return &kind;
  }
  return nullptr;
}

std::string SourceKindNames() {
  std::string names;
  for (const SourceKind& kind : kKinds)
    names += (names.empty() ? "" : ", ") + std::string(kind.name);
  return names;
}

std::vector<std::string> CheckSource(const SourceSpec& spec) {
  const SourceKind* kind = FindSourceKind(spec.kind);
  if (kind == nullptr) {
    return {"source.kind: unknown kind '" + spec.kind + "' (one of: " + SourceKindNames() + ")"};
  }
  return kind->check(spec);
}

Result<std::unique_ptr<drivers::StereoSource>> OpenSource(const SourceSpec& spec) {
  if (std::vector<std::string> problems = CheckSource(spec); !problems.empty()) {
    return InvalidArgument(problems);
  }
  return FindSourceKind(spec.kind)->open(spec);
}

}  // namespace stevi::server
