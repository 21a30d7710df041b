// Two GenICam cameras (through Aravis) as one stereo source.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/common/fields.h"
#include "drivers/aravis/aravis_camera.h"
#include "drivers/aravis/stereo_pairer.h"
#include "drivers/stereo_source.h"

namespace stevi::drivers {

struct AravisTrigger {
  TriggerMode mode = TriggerMode::kFreeRun;
  // kHardware: the trigger source of both cameras, e.g. "Line0".
  std::string line;
};

// The region of interest's sides, pixels: the one place these bounds live (the server's config
// checks use them too). Below 16 px no block matcher has a window to work with.
inline constexpr int kMinRoiPx = 16;
inline constexpr int kMaxRoiPx = 16384;

struct AravisOptions {
  // The cameras: a device id ("Aravis-Fake-GV01"), a serial number ("GV01") or an IP address.
  std::string left_id;
  std::string right_id;
  // Region of interest, pixels, centred on each sensor; the same on both cameras.
  int roi_width = 640;  // kMinRoiPx..kMaxRoiPx
  int roi_height = 480;
  // "" picks Mono8 where offered, else a Bayer*8 format (converted to grey).
  std::string pixel_format;
  // Frames per second: the cameras' rate in free run, the host's trigger rate in software mode,
  // and the expected rate (for the default pair tolerance and loss detection) in hardware mode.
  double frame_rate_hz = 30;
  // Exposure, microseconds; 0 = automatic where the camera has it.
  double exposure_us = 0;
  // Gain, dB; negative = automatic where the camera has it.
  double gain_db = -1;
  AravisTrigger trigger;
  // Largest |right - left| capture-time difference of a pair, ms; 0 = half the frame period.
  double pair_tolerance_ms = 0;
  // Stream buffers per camera (2..64).
  int buffers = 8;
  // How long Next() waits for a pair before kUnavailable. A camera that delivers nothing for
  // max(timeout, 5 frame periods + exposure) is declared lost and reopened.
  std::chrono::milliseconds timeout{1000};
  // See TimestampSource: kCamera pairs by the cameras' clocks, which must share a time base.
  TimestampSource timestamps = TimestampSource::kCamera;

  // Frame period, ns.
  int64_t FramePeriodNs() const;
  // pair_tolerance_ms in ns, or half the frame period when it is 0.
  int64_t PairToleranceNs() const;
  // Every problem, as "field: problem (got X)".
  std::vector<std::string> Validate() const;

  // The fields of stevi.v1.AravisConfig (the cameras' ids and the timeout are not among them).
  static constexpr fields::ChoiceName<TriggerMode> kTriggerNames[] = {
      {TriggerMode::kFreeRun, "free_run"},
      {TriggerMode::kSoftware, "software"},
      {TriggerMode::kHardware, "hardware"}};
  static constexpr fields::ChoiceName<TimestampSource> kTimestampNames[] = {
      {TimestampSource::kCamera, "camera"}, {TimestampSource::kHost, "host"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.roi_width, Field("width", "pixels", "region of interest, centred")
                              .In(kMinRoiPx, kMaxRoiPx)
                              .Flag("roi", "WxH"));
    v.Number(s.roi_height, Field("height", "pixels", "region of interest, centred")
                               .In(kMinRoiPx, kMaxRoiPx)
                               .Flag("roi", "WxH"));
    v.Number(s.frame_rate_hz, Field("frame_rate_hz", "Hz", "both cameras").Above(0).AtMost(1000));
    v.Number(s.exposure_us, Field("exposure_us", "us", "fixed exposure; 0 = automatic")
                                .AtLeast(0)
                                .Below(1e8)
                                .Flag("exposure-us", "US"));
    v.Number(s.gain_db,
             Field("gain_db", "dB", "fixed gain; negative = automatic").Flag("gain-db", "DB"));
    v.Choice(s.trigger.mode,
             Field("trigger", "", "what starts an exposure").Flag("trigger", "MODE"),
             kTriggerNames);
    v.Text(s.trigger.line,
           Field("trigger_line", "", "the hardware trigger's line, e.g. Line0").Flag("trigger"));
    v.Number(s.pair_tolerance_ms, Field("pair_tolerance_ms", "ms",
                                        "largest capture-time difference of a pair; 0 = "
                                        "half the frame period")
                                      .AtLeast(0)
                                      .AtMost(1000));
    v.Number(s.buffers, Field("buffers", "", "stream buffers per camera").In(2, 64));
    v.Text(s.pixel_format, Field("pixel_format", "", "Mono8 or Bayer*8; empty = automatic"));
    v.Choice(s.timestamps, Field("timestamps", "", "which clock pairs the frames").Flag(),
             kTimestampNames);
  }
};

// Thread-compatible like every StereoSource: one thread calls Next(). Counters(), Describe(),
// Rig(), NominalFps() and the per-camera accessors are safe from any thread.
//
// Each camera has its own acquisition thread: it pops frames, feeds the pairer, notices the
// loss of its camera (AravisCamera::control_lost(), or no frame for the loss time) and reopens it
// with a backoff of 250 ms doubling to 1 s, independently of how often Next() is called. Next()
// hands out the newest completed pair; when the caller falls behind, older pairs are skipped (they
// still count in Counters().pairs).
class AravisStereoSource : public StereoSource {
 public:
  // Validates the options, opens and configures both cameras (errors name the camera and the
  // problem; an unknown id lists the devices present) and starts acquisition. `rig` may be
  // null (no calibration yet); otherwise its image size must be the ROI.
  static Result<std::unique_ptr<AravisStereoSource>> Open(
      AravisOptions options, std::shared_ptr<const geometry::StereoRig> rig);

  // Stops both threads and releases the cameras. Blocks for a few seconds when a GigE camera is
  // lost or being reopened: Aravis waits for its control requests to time out (~2.5 s each).
  ~AravisStereoSource() override;

  // "aravis Aravis-Fake-GV01 + Aravis-Fake-GV02 640x480 30 fps" (plus the trigger when not
  // free-running).
  std::string Describe() const override;
  std::shared_ptr<const geometry::StereoRig> Rig() const override;
  // Blocks until a pair (CV_8UC1, rectified = false, t_ns = left capture time) or the timeout.
  // kUnavailable names the camera: at once when one was just lost, then (while it is being
  // reopened) after the timeout; "no pair from L/R for 1 s" with what each side delivered when
  // frames do not pair.
  Result<StereoFrame> Next() override;
  // 0: the cameras pace themselves.
  double NominalFps() const override { return 0; }
  // The pairer's counters, plus incomplete_dropped (both cameras, all reopenings) and
  // reconnects.
  SourceCounters Counters() const override;
  void Interrupt() override;

  // The last opened camera's settings as read back, and its stream statistics (frames and
  // incomplete buffers are totals over reopenings).
  CameraInfo camera_info(Side side) const;
  CameraStats camera_stats(Side side) const;

 private:
  struct Impl;
  explicit AravisStereoSource(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace stevi::drivers
