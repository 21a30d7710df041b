#include "drivers/aravis/aravis_camera.h"

#include "core/common/format.h"

#include <arv.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <numeric>
#include <utility>

#include <opencv2/imgproc.hpp>

namespace stevi::drivers {
namespace {

// Aravis's device list is global: arv_update_device_list() frees the strings that
// arv_get_device_id() & co. returned, and arv_open_device() may refresh the list itself. This
// lock serialises every listing and opening in the process.
std::mutex& DeviceListMutex() {
  static std::mutex mutex;
  return mutex;
}

// Owns a GError out-parameter and frees it: every Aravis call that can fail gets a fresh one.
class GErrorSlot {
 public:
  GErrorSlot() = default;
  ~GErrorSlot() { Clear(); }
  GErrorSlot(const GErrorSlot&) = delete;
  GErrorSlot& operator=(const GErrorSlot&) = delete;

  // The out-parameter; clears an earlier error first.
  GError** out() {
    Clear();
    return &error_;
  }
  explicit operator bool() const { return error_ != nullptr; }
  // Our code for the error: a camera that does not answer (or that another host controls) is
  // unavailable; a value the camera refuses is an invalid argument; the rest is unexpected.
  ErrorCode code() const {
    if (error_ == nullptr) return ErrorCode::kInternal;
    if (error_->domain == ARV_DEVICE_ERROR) {
      switch (error_->code) {
        case ARV_DEVICE_ERROR_NOT_CONNECTED:
        case ARV_DEVICE_ERROR_PROTOCOL_ERROR:
        case ARV_DEVICE_ERROR_TRANSFER_ERROR:
        case ARV_DEVICE_ERROR_TIMEOUT:
        case ARV_DEVICE_ERROR_NOT_CONTROLLER:
        case ARV_DEVICE_ERROR_PROTOCOL_ERROR_ACCESS_DENIED:
        case ARV_DEVICE_ERROR_PROTOCOL_ERROR_BUSY: return ErrorCode::kUnavailable;
        default: return ErrorCode::kInternal;
      }
    }
    if (error_->domain == ARV_GC_ERROR) {
      switch (error_->code) {
        case ARV_GC_ERROR_OUT_OF_RANGE:
        case ARV_GC_ERROR_ENUM_ENTRY_NOT_FOUND:
        case ARV_GC_ERROR_READ_ONLY: return ErrorCode::kInvalidArgument;
        default: return ErrorCode::kInternal;
      }
    }
    return ErrorCode::kInternal;
  }
  std::string message() const {
    return error_ != nullptr && error_->message != nullptr ? error_->message : "unknown error";
  }
  void Clear() {
    if (error_ != nullptr) g_error_free(error_);
    error_ = nullptr;
  }

 private:
  GError* error_ = nullptr;
};

std::string Str(const char* s) { return s != nullptr ? s : ""; }

std::string Join(const std::vector<std::string>& items) {
  std::string out;
  for (const std::string& item : items) {
    if (!out.empty()) out += ", ";
    out += item;
  }
  return out;
}

// Strings of an Aravis "dup" array (the array is freed, the strings belong to Aravis).
std::vector<std::string> TakeStrings(const char** strings, guint n) {
  std::vector<std::string> out;
  if (strings == nullptr) return out;
  for (guint i = 0; i < n; ++i) out.push_back(Str(strings[i]));
  g_free(static_cast<gpointer>(strings));
  return out;
}

std::vector<DeviceEntry> ReadDeviceListLocked() {
  std::vector<DeviceEntry> devices;
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    DeviceEntry d;
    d.id = Str(arv_get_device_id(i));
    d.serial = Str(arv_get_device_serial_nbr(i));
    d.address = Str(arv_get_device_address(i));
    d.vendor = Str(arv_get_device_vendor(i));
    d.model = Str(arv_get_device_model(i));
    d.protocol = Str(arv_get_device_protocol(i));
    devices.push_back(std::move(d));
  }
  return devices;
}

// The device `key` names: a device id first, then a serial number, then an address.
// kInvalidArgument when a serial number is shared by several devices.
Result<std::optional<DeviceEntry>> Match(const std::vector<DeviceEntry>& devices,
                                         const std::string& key) {
  for (const DeviceEntry& d : devices) {
    if (d.id == key) return std::optional<DeviceEntry>(d);
  }
  std::vector<const DeviceEntry*> by_serial;
  for (const DeviceEntry& d : devices) {
    if (!d.serial.empty() && d.serial == key) by_serial.push_back(&d);
  }
  if (by_serial.size() > 1) {
    std::vector<std::string> names;
    for (const DeviceEntry* d : by_serial) names.push_back(DescribeDevice(*d));
    return InvalidArgument("camera '" + key +
                           "' is ambiguous: several devices have this "
                           "serial number (" +
                           Join(names) + "); use a device id");
  }
  if (by_serial.size() == 1) return std::optional<DeviceEntry>(*by_serial.front());
  for (const DeviceEntry& d : devices) {
    if (!d.address.empty() && d.address == key) return std::optional<DeviceEntry>(d);
  }
  return std::optional<DeviceEntry>();
}

Error DeviceNotFound(const std::string& key, const std::vector<DeviceEntry>& devices) {
  std::string message = "camera '" + key +
                        "' not found (matched against device ids, serial numbers and IP "
                        "addresses); ";
  if (devices.empty()) {
    message +=
        "no camera is present: check power and cabling, and for GigE Vision that the camera is "
        "on a subnet of this host and that discovery (UDP port 3956) is not blocked";
  } else {
    std::vector<std::string> names;
    for (const DeviceEntry& d : devices) names.push_back(DescribeDevice(d));
    message += "present: " + Join(names);
  }
  return NotFound(message);
}

int OpenCvBayerToGrey(PixelFormat format) {
  // GenICam names the colours of the mosaic's first row (BayerRG8: R G / G B); OpenCV names the
  // second row's second and third pixels, so GenICam RG is OpenCV BG, and so on.
  switch (format) {
    case PixelFormat::kBayerRG8: return cv::COLOR_BayerBG2GRAY;
    case PixelFormat::kBayerBG8: return cv::COLOR_BayerRG2GRAY;
    case PixelFormat::kBayerGR8: return cv::COLOR_BayerGB2GRAY;
    case PixelFormat::kBayerGB8: return cv::COLOR_BayerGR2GRAY;
    case PixelFormat::kMono8: break;
  }
  return -1;
}

bool IsBayer(PixelFormat format) { return format != PixelFormat::kMono8; }

void OnControlLost(ArvDevice* /*device*/, gpointer data) {
  // Runs on the thread of the failing USB3 Vision transfer: ours, or the stream's (which the
  // destructor joins by releasing the stream before the device).
  static_cast<std::shared_ptr<std::atomic<bool>>*>(data)->get()->store(true);
}

void DeleteLostFlag(gpointer data, GClosure* /*closure*/) {
  delete static_cast<std::shared_ptr<std::atomic<bool>>*>(data);
}

}  // namespace

const char* TriggerModeName(TriggerMode mode) {
  switch (mode) {
    case TriggerMode::kFreeRun: return "free-run";
    case TriggerMode::kSoftware: return "software";
    case TriggerMode::kHardware: return "hardware";
  }
  return "unknown";
}

const char* PixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kMono8: return "Mono8";
    case PixelFormat::kBayerRG8: return "BayerRG8";
    case PixelFormat::kBayerGR8: return "BayerGR8";
    case PixelFormat::kBayerGB8: return "BayerGB8";
    case PixelFormat::kBayerBG8: return "BayerBG8";
  }
  return "unknown";
}

std::optional<PixelFormat> ParsePixelFormat(std::string_view name) {
  for (PixelFormat f : {PixelFormat::kMono8, PixelFormat::kBayerRG8, PixelFormat::kBayerGR8,
                        PixelFormat::kBayerGB8, PixelFormat::kBayerBG8}) {
    if (name == PixelFormatName(f)) return f;
  }
  return std::nullopt;
}

std::string SupportedPixelFormats() { return "Mono8, BayerRG8, BayerGR8, BayerGB8, BayerBG8"; }

Result<cv::Mat> ToGrey(const void* data, size_t size, int width, int height, PixelFormat format) {
  if (data == nullptr || width <= 0 || height <= 0 ||
      size != static_cast<size_t>(width) * static_cast<size_t>(height)) {
    return InvalidArgument("a " + std::string(PixelFormatName(format)) + " image of " +
                           SizeText(width, height) + " needs " +
                           std::to_string(static_cast<long long>(width) * height) + " bytes (got " +
                           std::to_string(size) + ")");
  }
  // Aravis owns `data` (a stream buffer that goes back to the pool): always copy.
  const cv::Mat view(height, width, CV_8UC1, const_cast<void*>(data));
  cv::Mat grey;
  if (format == PixelFormat::kMono8) {
    view.copyTo(grey);
  } else {
    cv::cvtColor(view, grey, OpenCvBayerToGrey(format));
  }
  return grey;
}

std::string DescribeDevice(const DeviceEntry& device) {
  std::string text = device.id + " (serial " + (device.serial.empty() ? "?" : device.serial);
  if (!device.address.empty() && device.address != "0.0.0.0") text += ", " + device.address;
  return text + ")";
}

std::vector<DeviceEntry> ListDevices() {
  std::lock_guard lock(DeviceListMutex());
  arv_update_device_list();
  return ReadDeviceListLocked();
}

void SetAravisInterfaceEnabled(const std::string& interface_id, bool enabled) {
  std::lock_guard lock(DeviceListMutex());
  if (enabled) {
    arv_enable_interface(interface_id.c_str());
  } else {
    arv_disable_interface(interface_id.c_str());
  }
}

struct AravisCamera::Handles {
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  // GigE Vision: the camera's device (not owned), whose heartbeat thread clears its controller
  // flag when the control channel is lost. No "control-lost" handler is connected to it: Aravis's
  // heartbeat emits that signal without holding a reference to the device, and GLib references
  // the device for an emission that finds a handler, after dropping its signal lock. When that
  // emission races the release of the device's last reference (a lost camera released while its
  // heartbeat gives up), GLib revives the finalizing device (GLib-GObject-CRITICAL
  // "g_object_ref: assertion '!object_already_finalized' failed") and finalizes it a second time
  // on the heartbeat thread (a segfault). With no handler, the emission returns under GLib's lock
  // without touching the device's reference count, and the device's finalize joins the heartbeat
  // thread before freeing anything.
  ArvGvDevice* gv_device = nullptr;
  // Other devices: the flag of a "control-lost" handler (see OnControlLost; the fake device never
  // emits it).
  gulong lost_handler = 0;
  // Shared with the signal closure, which may outlive this object by an in-flight emission.
  std::shared_ptr<std::atomic<bool>> lost = std::make_shared<std::atomic<bool>>(false);
  guint32 pixel_format = 0;  // ArvPixelFormat the stream should carry
};

AravisCamera::AravisCamera() : handles_(std::make_unique<Handles>()) {}

AravisCamera::~AravisCamera() {
  Handles& h = *handles_;
  if (h.camera != nullptr && acquiring_ && !lost_ && !control_lost()) {
    GErrorSlot error;
    arv_camera_stop_acquisition(h.camera, error.out());  // best effort: nothing to report to
  }
  if (h.stream != nullptr) g_object_unref(h.stream);
  if (h.camera != nullptr) {
    if (h.lost_handler != 0) {
      g_signal_handler_disconnect(arv_camera_get_device(h.camera), h.lost_handler);
    }
    g_object_unref(h.camera);
  }
}

bool AravisCamera::control_lost() const {
  const Handles& h = *handles_;
  // The heartbeat thread writes this flag (a plain gboolean) once, after it gave up.
  if (h.gv_device != nullptr) return arv_gv_device_is_controller(h.gv_device) == FALSE;
  return h.lost->load();
}

namespace {

// What AravisCamera::Open's configure steps share: the camera, its name for messages, the error
// slot of the last call, and whether the camera's control was lost (then every failure is
// kUnavailable).
struct ConfigureStep {
  ArvCamera* camera;
  const std::string& name;
  GErrorSlot& error;
  const AravisCamera& owner;

  // Any failing call names the camera and the step.
  Error Failed(const std::string& what) const {
    return Error{owner.control_lost() ? ErrorCode::kUnavailable : error.code(),
                 name + ": " + what + " failed: " + error.message()};
  }
  bool Available(const char* feature) const {
    GErrorSlot e;
    const bool yes = arv_camera_is_feature_available(camera, feature, e.out()) != 0;
    return yes && !e;
  }
};

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

// The region of interest, centred on the sensor.
Status ConfigureRoi(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info) {
  const PixelFormat format = info.pixel_format;
  // Centred region of interest. Offsets go to 0 first, so that the full width is allowed.
  const bool has_offsets = step.Available("OffsetX") && step.Available("OffsetY");
  if (has_offsets) {
    arv_camera_set_region(step.camera, 0, 0, -1, -1, step.error.out());
    if (step.error) return step.Failed("resetting the ROI offsets");
  }
  gint sensor_w = 0, sensor_h = 0;
  if (step.Available("SensorWidth") && step.Available("SensorHeight")) {
    arv_camera_get_sensor_size(step.camera, &sensor_w, &sensor_h, step.error.out());
    if (step.error) return step.Failed("reading the sensor size");
  }
  gint w_min = 0, w_max = 0, h_min = 0, h_max = 0;
  arv_camera_get_width_bounds(step.camera, &w_min, &w_max, step.error.out());
  if (step.error) return step.Failed("reading the width bounds");
  arv_camera_get_height_bounds(step.camera, &h_min, &h_max, step.error.out());
  if (step.error) return step.Failed("reading the height bounds");
  if (sensor_w <= 0 || sensor_h <= 0) {  // no SensorWidth: the largest ROI is the sensor
    sensor_w = w_max;
    sensor_h = h_max;
  }
  info.sensor = cv::Size(sensor_w, sensor_h);
  const int roi_w = settings.roi_width, roi_h = settings.roi_height;
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
  int x = (sensor_w - roi_w) / 2, y = (sensor_h - roi_h) / 2;
  if (has_offsets) {
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
  // Width and height before the offsets: the offsets' bounds depend on them.
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

Result<std::unique_ptr<AravisCamera>> AravisCamera::Open(const CameraSettings& settings,
                                                         bool refresh_device_list) {
  std::unique_ptr<AravisCamera> cam(new AravisCamera());
  cam->settings_ = settings;
  Handles& h = *cam->handles_;
  CameraInfo& info = cam->info_;
  GErrorSlot error;

  {
    std::lock_guard lock(DeviceListMutex());
    // The current list first: discovery costs about a second.
    std::vector<DeviceEntry> devices;
    std::optional<DeviceEntry> found;
    if (!refresh_device_list) {
      devices = ReadDeviceListLocked();
      Result<std::optional<DeviceEntry>> match = Match(devices, settings.id);
      if (!match.ok()) return match.error();
      found = *match;
    }
    if (!found) {
      arv_update_device_list();
      devices = ReadDeviceListLocked();
      Result<std::optional<DeviceEntry>> match = Match(devices, settings.id);
      if (!match.ok()) return match.error();
      found = *match;
    }
    if (!found) return DeviceNotFound(settings.id, devices);
    info.device = *found;
    h.camera = arv_camera_new(info.device.id.c_str(), error.out());
    if (h.camera == nullptr || error) {
      // Whatever the cause (no answer, another host in control), the camera is not usable now.
      return Unavailable("cannot open camera " + DescribeDevice(info.device) + ": " +
                         error.message());
    }
  }
  const std::string name = "camera " + info.device.id;

  // From here on the destructor releases what was acquired.
  ArvDevice* device = arv_camera_get_device(h.camera);
  if (ARV_IS_GV_DEVICE(device)) {
    h.gv_device = ARV_GV_DEVICE(device);  // see Handles::gv_device: no handler on it
  } else {
    auto* flag = new std::shared_ptr<std::atomic<bool>>(h.lost);
    h.lost_handler = g_signal_connect_data(device, "control-lost", G_CALLBACK(OnControlLost), flag,
                                           DeleteLostFlag, static_cast<GConnectFlags>(0));
  }

  ConfigureStep step{h.camera, name, error, *cam};
  Status done = ConfigurePixelFormat(step, settings, info, h.pixel_format);
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
  if (!done.ok()) return done.error();

  // Stream and its buffer pool.
  const guint payload = arv_camera_get_payload(h.camera, error.out());
  if (error) return step.Failed("reading the payload size");
  if (arv_camera_is_gv_device(h.camera)) {
    // A plain UDP socket rather than Aravis's packet socket (used when the process has
    // CAP_NET_RAW): a packet socket catches every GVSP packet on the interface until its filter
    // is attached, so a stream reopened while the other camera streams to the same interface
    // takes that camera's frame ids as its own, then drops its real frames as "late" for
    // seconds. The plain socket receives only its own port's packets.
    arv_camera_gv_set_stream_options(h.camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
  }
  h.stream = arv_camera_create_stream(h.camera, nullptr, nullptr, error.out());
  if (h.stream == nullptr || error) return step.Failed("creating the stream");
  if (ARV_IS_GV_STREAM(h.stream)) {
    // The kernel's default receive buffer (~200 kB) is smaller than one 640x480 frame: any
    // scheduling hiccup of the stream thread then drops packets and frames. Ask for a few
    // frames' worth (Linux caps it at net.core.rmem_max, which large ROIs may need raised).
    const size_t wanted = std::clamp<size_t>(4 * static_cast<size_t>(payload), 1 << 20, 32 << 20);
    g_object_set(h.stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                 static_cast<gint>(wanted), nullptr);
  }
  for (int i = 0; i < settings.buffers; ++i) {
    arv_stream_push_buffer(h.stream, arv_buffer_new_allocate(payload));
  }
  return cam;
}

Status AravisCamera::StartAcquisition() {
  GErrorSlot error;
  arv_camera_start_acquisition(handles_->camera, error.out());
  if (error) {
    return Unavailable("camera " + id() + ": starting acquisition failed: " + error.message());
  }
  acquiring_ = true;
  return Status::Ok();
}

Result<std::optional<MonoFrame>> AravisCamera::Pop(std::chrono::microseconds timeout) {
  using Clock = std::chrono::steady_clock;
  const auto deadline = Clock::now() + timeout;
  Handles& h = *handles_;
  while (true) {
    if (control_lost()) {
      return Unavailable("camera " + id() + " lost its control channel (no heartbeat answer)");
    }
    const auto left =
        std::chrono::duration_cast<std::chrono::microseconds>(deadline - Clock::now()).count();
    if (left <= 0) return std::optional<MonoFrame>();
    ArvBuffer* buffer = arv_stream_timeout_pop_buffer(h.stream, static_cast<guint64>(left));
    if (buffer == nullptr) return std::optional<MonoFrame>();

    // Check everything before trusting the bytes: status, payload type, geometry, format.
    std::optional<MonoFrame> frame;
    if (arv_buffer_get_status(buffer) == ARV_BUFFER_STATUS_SUCCESS &&
        arv_buffer_get_payload_type(buffer) == ARV_BUFFER_PAYLOAD_TYPE_IMAGE &&
        arv_buffer_get_image_width(buffer) == info_.roi.width &&
        arv_buffer_get_image_height(buffer) == info_.roi.height &&
        arv_buffer_get_image_pixel_format(buffer) == h.pixel_format) {
      size_t size = 0;
      const void* data = arv_buffer_get_image_data(buffer, &size);
      Result<cv::Mat> grey =
          ToGrey(data, size, info_.roi.width, info_.roi.height, info_.pixel_format);
      if (grey.ok()) {
        frame.emplace();
        frame->image = std::move(grey.value());
        const guint64 camera_ns = arv_buffer_get_timestamp(buffer);
        const guint64 host_ns = arv_buffer_get_system_timestamp(buffer);
        frame->t_ns = static_cast<int64_t>(
            settings_.timestamps == TimestampSource::kCamera && camera_ns != 0 ? camera_ns
                                                                               : host_ns);
        frame->unix_time_ns = static_cast<int64_t>(host_ns);
        frame->frame_id = arv_buffer_get_frame_id(buffer);
      }
    }
    arv_stream_push_buffer(h.stream, buffer);
    if (frame) {
      ++frames_;
      return frame;
    }
    ++incomplete_;
  }
}

Status AravisCamera::SoftwareTrigger() {
  GErrorSlot error;
  arv_camera_software_trigger(handles_->camera, error.out());
  if (error) {
    return Unavailable("camera " + id() + ": software trigger failed: " + error.message());
  }
  return Status::Ok();
}

Status AravisCamera::Ping() {
  GErrorSlot error;
  // A feature the stream does not depend on; with Aravis's default (no register cache) this is
  // a real read on the wire.
  arv_camera_get_integer(handles_->camera, "Width", error.out());
  if (error) {
    return Unavailable("camera " + id() + " does not answer: " + error.message());
  }
  return Status::Ok();
}

CameraStats AravisCamera::Stats() const {
  CameraStats stats;
  stats.frames = frames_;
  stats.incomplete = incomplete_;
  ArvStream* stream = handles_->stream;
  if (stream == nullptr) return stats;
  guint64 completed = 0, failures = 0, underruns = 0;
  arv_stream_get_statistics(stream, &completed, &failures, &underruns);
  stats.underruns = underruns;
  if (ARV_IS_GV_STREAM(stream)) {
    stats.resent_packets = arv_stream_get_info_uint64_by_name(stream, "n_resent_packets");
    stats.missing_packets = arv_stream_get_info_uint64_by_name(stream, "n_missing_packets");
  }
  return stats;
}

}  // namespace stevi::drivers
