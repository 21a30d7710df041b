// The configure steps of AravisCamera::Open (aravis_internal.h, ConfigureCamera): pixel format,
// centred region of interest, exposure and gain, frame rate, trigger.
#include <algorithm>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "core/common/format.h"
#include "drivers/aravis/aravis_internal.h"

namespace stevi::drivers::aravis_internal {
namespace {

bool IsBayer(PixelFormat format) { return format != PixelFormat::kMono8; }

// Pixel format first: on some cameras it changes the ROI steps.
Status ConfigurePixelFormat(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info,
                            guint32& arv_format) {
  std::vector<std::string> offered;
  {
    guint n = 0;
    const char** strings =
        arv_camera_dup_available_pixel_formats_as_strings(step.camera, &n, step.error.out());
    offered = TakeStrings(strings, n);  // after the call: it sets n
    if (step.error) return step.Failed("listing the pixel formats");
  }
  const auto offers = [&](const std::string& format) {
    return std::find(offered.begin(), offered.end(), format) != offered.end();
  };
  std::optional<PixelFormat> format;
  if (!settings.pixel_format.empty()) {
    format = ParsePixelFormat(settings.pixel_format);
    if (!format) {
      return InvalidArgument(step.name + ": pixel format " + settings.pixel_format +
                             " is not supported (supported: " + SupportedPixelFormats() + ")");
    }
    if (!offers(settings.pixel_format)) {
      return InvalidArgument(step.name + " does not offer pixel format " + settings.pixel_format +
                             " (it offers " + Join(offered) + ")");
    }
  } else if (offers("Mono8")) {
    format = PixelFormat::kMono8;
  } else {
    for (const std::string& f : offered) {
      if (std::optional<PixelFormat> p = ParsePixelFormat(f)) {
        format = p;
        break;
      }
    }
    if (!format) {
      return InvalidArgument(step.name + " offers none of the supported pixel formats (" +
                             SupportedPixelFormats() + "); it offers " + Join(offered));
    }
  }
  info.pixel_format = *format;
  arv_camera_set_pixel_format_from_string(step.camera, PixelFormatName(*format), step.error.out());
  if (step.error)
    return step.Failed(std::string("setting pixel format ") + PixelFormatName(*format));
  arv_format = arv_camera_get_pixel_format(step.camera, step.error.out());
  if (step.error) return step.Failed("reading the pixel format back");

  return Status::Ok();
}

// What the camera allows for the region of interest: ConfigureRoi's steps share it.
struct RoiLimits {
  bool has_offsets = false;
  gint sensor_w = 0, sensor_h = 0;
  gint w_min = 0, w_max = 0, h_min = 0, h_max = 0;
};

// The offsets reset to 0 (so that the full width is allowed), the sensor size (the largest ROI
// when the camera has no SensorWidth) and the size bounds.
Status ReadRoiLimits(ConfigureStep& step, RoiLimits& limits, CameraInfo& info) {
  limits.has_offsets = step.Available("OffsetX") && step.Available("OffsetY");
  if (limits.has_offsets) {
    arv_camera_set_region(step.camera, 0, 0, -1, -1, step.error.out());
    if (step.error) return step.Failed("resetting the ROI offsets");
  }
  if (step.Available("SensorWidth") && step.Available("SensorHeight")) {
    arv_camera_get_sensor_size(step.camera, &limits.sensor_w, &limits.sensor_h, step.error.out());
    if (step.error) return step.Failed("reading the sensor size");
  }
  arv_camera_get_width_bounds(step.camera, &limits.w_min, &limits.w_max, step.error.out());
  if (step.error) return step.Failed("reading the width bounds");
  arv_camera_get_height_bounds(step.camera, &limits.h_min, &limits.h_max, step.error.out());
  if (step.error) return step.Failed("reading the height bounds");
  // No SensorWidth: the largest ROI is the sensor.
  if (limits.sensor_w <= 0 || limits.sensor_h <= 0) {
    limits.sensor_w = limits.w_max;
    limits.sensor_h = limits.h_max;
  }
  info.sensor = cv::Size(limits.sensor_w, limits.sensor_h);
  return Status::Ok();
}

// The requested size against the sensor, the size bounds and the camera's size steps.
Status CheckRoiSize(ConfigureStep& step, const CameraSettings& settings, const RoiLimits& limits) {
  const int roi_w = settings.roi_width, roi_h = settings.roi_height;
  const gint sensor_w = limits.sensor_w, sensor_h = limits.sensor_h;
  const gint w_min = limits.w_min, w_max = limits.w_max, h_min = limits.h_min, h_max = limits.h_max;
  if (roi_w > std::min(sensor_w, w_max) || roi_h > std::min(sensor_h, h_max)) {
    return InvalidArgument(
        step.name + ": the region of interest " + SizeText(roi_w, roi_h) +
        " is larger than its sensor (" + SizeText(sensor_w, sensor_h) +
        (w_max < sensor_w || h_max < sensor_h
             ? ", largest ROI " + SizeText(w_max, h_max) + " at the current binning"
             : std::string()) +
        ")");
  }
  if (roi_w < w_min || roi_h < h_min) {
    return InvalidArgument(step.name + ": the region of interest " + SizeText(roi_w, roi_h) +
                           " is smaller than its minimum " + SizeText(w_min, h_min));
  }
  const gint w_step = std::max(1, arv_camera_get_width_increment(step.camera, step.error.out()));
  if (step.error) return step.Failed("reading the width step");
  const gint h_step = std::max(1, arv_camera_get_height_increment(step.camera, step.error.out()));
  if (step.error) return step.Failed("reading the height step");
  if ((roi_w - w_min) % w_step != 0 || (roi_h - h_min) % h_step != 0) {
    return InvalidArgument(step.name + ": the region of interest " + SizeText(roi_w, roi_h) +
                           " does not fit its size steps (width " + std::to_string(w_min) +
                           " + k*" + std::to_string(w_step) + ", height " + std::to_string(h_min) +
                           " + k*" + std::to_string(h_step) + ")");
  }
  return Status::Ok();
}

// The offsets that centre the region on the sensor, aligned to the camera's offset steps (and to
// even pixels for a Bayer mosaic); (0, 0) with a note when the camera has no offsets.
Status CentredOffsets(ConfigureStep& step, const CameraSettings& settings, const RoiLimits& limits,
                      CameraInfo& info, cv::Point& offset) {
  const PixelFormat format = info.pixel_format;
  int x = (limits.sensor_w - settings.roi_width) / 2,
      y = (limits.sensor_h - settings.roi_height) / 2;
  if (limits.has_offsets) {
    const gint x_step =
        std::max(1, arv_camera_get_x_offset_increment(step.camera, step.error.out()));
    if (step.error) return step.Failed("reading the x offset step");
    const gint y_step =
        std::max(1, arv_camera_get_y_offset_increment(step.camera, step.error.out()));
    if (step.error) return step.Failed("reading the y offset step");
    // A Bayer mosaic keeps its phase only with even offsets.
    const int x_align = IsBayer(format) ? std::lcm(x_step, 2) : x_step;
    const int y_align = IsBayer(format) ? std::lcm(y_step, 2) : y_step;
    x -= x % x_align;
    y -= y % y_align;
  } else {
    x = y = 0;
    info.notes.push_back("roi: the camera has no offsets, the region is at the sensor's corner");
  }
  offset = cv::Point(x, y);
  return Status::Ok();
}

// The region set (width and height before the offsets: the offsets' bounds depend on them) and
// read back: the camera must have taken it as asked.
Status ApplyRoi(ConfigureStep& step, const CameraSettings& settings, bool has_offsets,
                cv::Point offset, CameraInfo& info) {
  const int roi_w = settings.roi_width, roi_h = settings.roi_height;
  const int x = offset.x, y = offset.y;
  arv_camera_set_region(step.camera, -1, -1, roi_w, roi_h, step.error.out());
  if (step.error) return step.Failed("setting the ROI size " + SizeText(roi_w, roi_h));
  if (has_offsets) {
    arv_camera_set_region(step.camera, x, y, -1, -1, step.error.out());
    if (step.error) return step.Failed("setting the ROI offsets");
  }
  gint rx = 0, ry = 0, rw = 0, rh = 0;
  arv_camera_get_region(step.camera, &rx, &ry, &rw, &rh, step.error.out());
  if (step.error) return step.Failed("reading the ROI back");
  info.roi = cv::Rect(rx, ry, rw, rh);
  if (rw != roi_w || rh != roi_h || (has_offsets && (rx != x || ry != y))) {
    return InvalidArgument(step.name + ": asked for the region " + SizeText(roi_w, roi_h) +
                           " at (" + std::to_string(x) + ", " + std::to_string(y) +
                           "), the camera set " + SizeText(rw, rh) + " at (" + std::to_string(rx) +
                           ", " + std::to_string(ry) + ")");
  }
  return Status::Ok();
}

// The region of interest, centred on the sensor.
Status ConfigureRoi(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info) {
  RoiLimits limits;
  cv::Point offset;
  Status done = ReadRoiLimits(step, limits, info);
  if (done.ok()) done = CheckRoiSize(step, settings, limits);
  if (done.ok()) done = CentredOffsets(step, settings, limits, info, offset);
  if (done.ok()) done = ApplyRoi(step, settings, limits.has_offsets, offset, info);
  return done;
}

// Exposure and gain: a value, or automatic; the same steps over two SFNC features.
struct AnalogControl {
  const char* noun;     // "exposure"
  const char* setting;  // "exposure_us"
  const char* control;  // "exposure time control"
  const char* unit;     // "us"
  gboolean (*available)(ArvCamera*, GError**);
  gboolean (*auto_available)(ArvCamera*, GError**);
  void (*set_auto)(ArvCamera*, ArvAuto, GError**);
  void (*get_bounds)(ArvCamera*, double*, double*, GError**);
  void (*set)(ArvCamera*, double, GError**);
  double (*get)(ArvCamera*, GError**);
};

const AnalogControl kExposure = {"exposure",
                                 "exposure_us",
                                 "exposure time control",
                                 "us",
                                 arv_camera_is_exposure_time_available,
                                 arv_camera_is_exposure_auto_available,
                                 arv_camera_set_exposure_time_auto,
                                 arv_camera_get_exposure_time_bounds,
                                 arv_camera_set_exposure_time,
                                 arv_camera_get_exposure_time};
// SFNC "Gain" is in dB; a few cameras expose only a raw gain in their own units.
const AnalogControl kGain = {"gain",
                             "gain_db",
                             "gain control",
                             "dB",
                             arv_camera_is_gain_available,
                             arv_camera_is_gain_auto_available,
                             arv_camera_set_gain_auto,
                             arv_camera_get_gain_bounds,
                             arv_camera_set_gain,
                             arv_camera_get_gain};

// Sets `c` to `value`, or to automatic when `automatic` (kept as it is, with a note, on a camera
// without the automatic mode); reads the value back into `actual` when the camera has the control.
Status ConfigureAnalog(ConfigureStep& step, const AnalogControl& c, bool automatic, double value,
                       double& actual, bool& is_auto, std::vector<std::string>& notes) {
  const std::string noun = c.noun;
  const bool has = c.available(step.camera, nullptr) != 0;
  const bool has_auto = c.auto_available(step.camera, nullptr) != 0;
  if (automatic) {
    if (has_auto) {
      c.set_auto(step.camera, ARV_AUTO_CONTINUOUS, step.error.out());
      if (step.error) return step.Failed("enabling automatic " + noun);
      is_auto = true;
    } else {
      notes.push_back(noun + ": the camera has no automatic " + noun + ", kept its setting");
    }
  } else {
    if (!has) {
      return InvalidArgument(step.name + ": " + c.setting + " " + FormatNumber(value) +
                             " was asked but the camera has no " + c.control);
    }
    if (has_auto) {
      c.set_auto(step.camera, ARV_AUTO_OFF, step.error.out());
      if (step.error) return step.Failed("disabling automatic " + noun);
    }
    double lo = 0, hi = 0;
    c.get_bounds(step.camera, &lo, &hi, step.error.out());
    if (step.error) return step.Failed("reading the " + noun + " bounds");
    if (value < lo || value > hi) {
      return InvalidArgument(step.name + ": " + c.setting + " " + FormatNumber(value) +
                             " is outside its range " + FormatNumber(lo) + ".." + FormatNumber(hi) +
                             " " + c.unit);
    }
    c.set(step.camera, value, step.error.out());
    if (step.error)
      return step.Failed("setting the " + noun + " to " + FormatNumber(value) + " " + c.unit);
  }
  if (has) {
    actual = c.get(step.camera, step.error.out());
    if (step.error) return step.Failed("reading the " + noun + " back");
  }
  return Status::Ok();
}

Status ConfigureFrameRate(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info) {
  // Frame rate, before the trigger: on several vendors arv_camera_set_frame_rate() also
  // switches the FrameStart trigger off. Triggered cameras are paced by their trigger.
  if (arv_camera_is_frame_rate_available(step.camera, nullptr) != 0) {
    if (settings.trigger == TriggerMode::kFreeRun) {
      double lo = 0, hi = 0;
      arv_camera_get_frame_rate_bounds(step.camera, &lo, &hi, step.error.out());
      if (step.error) return step.Failed("reading the frame rate bounds");
      if (settings.frame_rate_hz < lo || settings.frame_rate_hz > hi) {
        return InvalidArgument(step.name + ": frame_rate_hz " +
                               FormatNumber(settings.frame_rate_hz) + " is outside its range " +
                               FormatNumber(lo) + ".." + FormatNumber(hi) + " Hz");
      }
      arv_camera_set_frame_rate(step.camera, settings.frame_rate_hz, step.error.out());
      if (step.error)
        return step.Failed("setting the frame rate to " + FormatNumber(settings.frame_rate_hz));
    }
    info.frame_rate_hz = arv_camera_get_frame_rate(step.camera, step.error.out());
    if (step.error) return step.Failed("reading the frame rate back");
  } else if (settings.trigger == TriggerMode::kFreeRun) {
    info.notes.push_back("frame rate: the camera has no frame-rate control, it runs at its own");
  }

  return Status::Ok();
}

Status ConfigureTrigger(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info) {
  switch (settings.trigger) {
    case TriggerMode::kFreeRun:
      if (step.Available("TriggerMode")) {
        arv_camera_clear_triggers(step.camera, step.error.out());
        if (step.error) return step.Failed("switching the triggers off");
      }
      break;
    case TriggerMode::kSoftware:
      if (arv_camera_is_software_trigger_supported(step.camera, nullptr) == 0) {
        return InvalidArgument(step.name + " has no software trigger");
      }
      arv_camera_set_trigger(step.camera, "Software", step.error.out());
      if (step.error) return step.Failed("setting the software trigger");
      break;
    case TriggerMode::kHardware: {
      guint n = 0;
      const char** strings =
          arv_camera_dup_available_trigger_sources(step.camera, &n, step.error.out());
      const std::vector<std::string> sources = TakeStrings(strings, n);
      if (step.error) return step.Failed("listing the trigger sources");
      if (std::find(sources.begin(), sources.end(), settings.trigger_line) == sources.end()) {
        return InvalidArgument(step.name + " has no trigger source '" + settings.trigger_line +
                               "' (it has " +
                               (sources.empty() ? std::string("none") : Join(sources)) + ")");
      }
      arv_camera_set_trigger(step.camera, settings.trigger_line.c_str(), step.error.out());
      if (step.error) return step.Failed("setting the trigger source " + settings.trigger_line);
      break;
    }
  }
  info.trigger = settings.trigger;
  arv_camera_set_acquisition_mode(step.camera, ARV_ACQUISITION_MODE_CONTINUOUS, step.error.out());
  if (step.error) return step.Failed("setting continuous acquisition");

  return Status::Ok();
}

}  // namespace

Status ConfigureCamera(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info,
                       guint32& arv_format) {
  Status done = ConfigurePixelFormat(step, settings, info, arv_format);
  if (done.ok()) done = ConfigureRoi(step, settings, info);
  if (done.ok()) {
    done = ConfigureAnalog(step, kExposure, settings.exposure_us <= 0, settings.exposure_us,
                           info.exposure_us, info.exposure_auto, info.notes);
  }
  if (done.ok()) {
    done = ConfigureAnalog(step, kGain, settings.gain_db < 0, settings.gain_db, info.gain_db,
                           info.gain_auto, info.notes);
  }
  // Frame rate before the trigger: on several vendors arv_camera_set_frame_rate() also switches
  // the FrameStart trigger off.
  if (done.ok()) done = ConfigureFrameRate(step, settings, info);
  if (done.ok()) done = ConfigureTrigger(step, settings, info);
  return done;
}

}  // namespace stevi::drivers::aravis_internal
