// Any GStreamer pipeline (a UVC stereo camera, two webcams, an RTSP camera, a video file, CSI
// camera pairs) as a stereo source.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/fields.h"
#include "drivers/stereo_source.h"

namespace stevi::drivers {

// How the two views come out of the pipelines.
enum class GstLayout {
  kSideBySide,  // one pipeline, left view | right view in each frame
  kTopBottom,   // one pipeline, left view above the right view
  kTwo,         // two pipelines, one per view, paired by capture time
};

// "side-by-side", "top-bottom", "two" (the flag spellings).
const char* GstLayoutName(GstLayout layout);
// Both spellings: the config names ("side_by_side", "top_bottom", "two") and the flag names
// ("side-by-side", "top-bottom"); nullopt for anything else.
std::optional<GstLayout> ParseGstLayout(std::string_view text);

struct GstOptions {
  GstLayout layout = GstLayout::kSideBySide;
  // side-by-side, top-bottom: the one pipeline; two: left_pipeline and right_pipeline. Each is a
  // gst-launch description whose last element gives the frames ("v4l2src ! jpegdec"); the driver
  // appends " ! videoconvert ! video/x-raw,format={luma formats} ! appsink name=stevi_sink ...",
  // so none may name an element stevi_sink. pipelines.h builds the usual ones.
  std::string pipeline;
  std::string left_pipeline;
  std::string right_pipeline;
  // The size of ONE view, pixels; 0 = as the stream comes (then the first frame fixes it). A
  // frame of another size is an error naming both sizes, at the start and later.
  int width = 0;
  int height = 0;
  // The expected frame rate, Hz: for loss detection and the default pair tolerance; a file's
  // playback rate when its caps give none.
  double fps = 30;
  // two: the largest |right - left| capture-time difference of a pair, ms; 0 = half a frame
  // period (and at most that).
  double pair_tolerance_ms = 0;
  // Whether the pipelines are live (cameras, RTSP): the newest pair wins, and a pipeline that
  // fails, ends or delivers nothing for max(timeout, 5 frame periods) is torn down and rebuilt.
  // Not live (files): every frame in order, the decoders waiting for the reader; the end of the
  // file is the end of the source (kOutOfRange) unless `loop`.
  bool live = true;
  // Files: play again from the start at the end (times keep increasing over laps).
  bool loop = false;
  // How long Next() waits for a pair before kUnavailable (> 0).
  std::chrono::milliseconds timeout{1000};
  // How long Open() waits for the first frame of each pipeline (> 0): a camera or a stream can
  // take seconds to start.
  std::chrono::milliseconds start_timeout{10000};

  // Frame period at `fps`, ns.
  int64_t FramePeriodNs() const;
  // pair_tolerance_ms in ns, or half the frame period when it is 0.
  int64_t PairToleranceNs() const;
  // No frame for this long and a live pipeline is lost: max(timeout, 5 frame periods).
  std::chrono::nanoseconds LostAfter() const;
  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;

  static constexpr fields::ChoiceName<GstLayout> kLayoutNames[] = {
      {GstLayout::kSideBySide, "side_by_side"},
      {GstLayout::kTopBottom, "top_bottom"},
      {GstLayout::kTwo, "two"}};
  // The timeouts are not among the fields (like the Aravis source's).
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.layout,
             Field("layout", "", "how the views come out of the pipelines").Flag("layout", "L"),
             kLayoutNames);
    v.Text(s.pipeline, Field("pipeline", "", "side_by_side, top_bottom: the gst-launch pipeline")
                           .Flag("pipeline", "P"));
    v.Text(s.left_pipeline,
           Field("left_pipeline", "", "two: the left view's pipeline").Flag("left-pipeline", "P"));
    v.Text(
        s.right_pipeline,
        Field("right_pipeline", "", "two: the right view's pipeline").Flag("right-pipeline", "P"));
    v.Number(s.width, Field("width", "pixels", "one view; 0 = as the stream comes")
                          .In(16, 16384)
                          .Or(0, "as the stream comes")
                          .Flag("size", "WxH"));
    v.Number(s.height, Field("height", "pixels", "one view; 0 = as the stream comes")
                           .In(16, 16384)
                           .Or(0, "as the stream comes")
                           .Flag("size", "WxH"));
    v.Number(s.fps, Field("fps", "Hz", "expected frame rate").Above(0).AtMost(1000));
    v.Number(s.pair_tolerance_ms, Field("pair_tolerance_ms", "ms",
                                        "two: largest capture-time difference of a pair; 0 = "
                                        "half the frame period")
                                      .AtLeast(0)
                                      .AtMost(1000));
    v.Flag(s.live, Field("live", "", "cameras and streams (true) or files (false)"));
    v.Flag(s.loop, Field("loop", "", "files: start again at the end"));
  }
};

// Thread-compatible like every StereoSource: one thread calls Next(). Counters(), Describe(),
// Rig(), ImageSize(), NominalFps(), Notes() and Interrupt() are safe from any thread.
//
// Each pipeline runs in a GstCapture with its own thread, which pulls frames independently of how
// often Next() is called. Live: Next() hands out the newest pair (older ones are skipped, still
// counted in Counters().pairs). Files: every pair in order; the pipelines wait for Next().
class GstStereoSource : public StereoSource {
 public:
  // Validates the options, starts the pipelines and waits for the first frame of each (up to
  // start_timeout), so that a bad pipeline, a missing element or device, a wrong size or an odd
  // width (side-by-side) fails here, naming it. `rig` may be null (no calibration yet); otherwise
  // its image size must be one view's.
  static Result<std::unique_ptr<GstStereoSource>> Open(
      GstOptions options, std::shared_ptr<const geometry::StereoRig> rig);

  // Stops the pipelines and joins their threads.
  ~GstStereoSource() override;

  // "gst side-by-side 640x480 (v4l2src device=/dev/video0 ...)".
  std::string Describe() const override;
  std::shared_ptr<const geometry::StereoRig> Rig() const override;
  // The rig's size, else one view's (from the options or the first frame).
  cv::Size ImageSize() const override;
  // Blocks until a pair (CV_8UC1; t_ns = the left capture time; unix_time_ns for live sources, 0
  // for files; rectified only when the rig needs no remap) or the timeout. kUnavailable says what
  // happened ("rtsp: lost 0.3 s ago (Could not read from resource); reconnecting, attempt 3"): at
  // once after a loss, then after each timeout while it lasts. kOutOfRange at the end of a file
  // (not looping); kInvalidArgument for a frame of the wrong size.
  Result<StereoFrame> Next() override;
  // Files: the caps' frame rate, else fps. Live: 0 (the pipelines pace themselves).
  double NominalFps() const override;
  // pairs (delivered or skipped); two: unpaired_dropped and the skew statistics; reconnects.
  SourceCounters Counters() const override;
  void Interrupt() override;
  // The pipelines as they run, warnings they posted, frame-rate mismatches.
  std::vector<std::string> Notes() const override;

 private:
  struct Impl;
  explicit GstStereoSource(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::drivers
