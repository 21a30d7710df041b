#include "server/runtime/source_factory.h"

#include <utility>

#include "core/common/fields.h"
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

std::vector<std::string> CheckAravis(const SourceSpec& spec) {
  std::vector<std::string> problems;
  const std::string ids = " required for the aravis source (device id, serial or address)";
  if (spec.left.empty()) problems.push_back("source.left:" + ids);
  if (spec.right.empty()) problems.push_back("source.right:" + ids);
  if (!spec.left.empty() && spec.left == spec.right) {
    problems.push_back("source.right: must be another camera than source.left (both '" + spec.left +
                       "')");
  }
  // The driver's own checks of each field (their ranges live in drivers/aravis), and the trigger
  // line a hardware trigger needs; the rest (exposure against the frame period, the pixel format)
  // is checked when the cameras open.
  AppendPrefixed(problems, "source.aravis.", fields::Check(spec.aravis));
  if (spec.aravis.trigger.mode == drivers::TriggerMode::kHardware &&
      spec.aravis.trigger.line.empty()) {
    problems.push_back("source.aravis.trigger_line: required with a hardware trigger (e.g. Line0)");
  }
  return problems;
}

Result<std::unique_ptr<drivers::StereoSource>> OpenAravis(const SourceSpec& spec) {
  std::shared_ptr<const geometry::StereoRig> rig;
  if (!spec.calibration.empty()) {
    Result<geometry::StereoRig> loaded = geometry::StereoRig::FromFile(spec.calibration);
    if (!loaded.ok()) return loaded.error().Prefixed("source.calibration: ");
    rig = std::make_shared<const geometry::StereoRig>(std::move(loaded).value());
  }
  return Opened(drivers::AravisStereoSource::Open(spec.aravis, std::move(rig)), "source.aravis: ");
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
    return Error::Invalid(problems);
  }
  return FindSourceKind(spec.kind)->open(spec);
}

}  // namespace stevi::server
