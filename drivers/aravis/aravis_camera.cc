// AravisCamera (aravis_camera.h): the device list, pixel format names and grey conversion, opening
// a camera and its stream, popping frames. aravis_configure.cc holds the configure steps.
#include "drivers/aravis/aravis_camera.h"

#include "core/common/format.h"

#include <arv.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <utility>

#include <opencv2/imgproc.hpp>

#include "drivers/aravis/aravis_internal.h"

namespace stevi::drivers {

using aravis_internal::ConfigureCamera;
using aravis_internal::ConfigureStep;
using aravis_internal::GErrorSlot;
using aravis_internal::Join;
using aravis_internal::Str;
using aravis_internal::TakeStrings;

namespace {

// Aravis's device list is global: arv_update_device_list() frees the strings that
// arv_get_device_id() & co. returned, and arv_open_device() may refresh the list itself. This
// lock serialises every listing and opening in the process.
std::mutex& DeviceListMutex() {
  static std::mutex mutex;
  return mutex;
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

// The device settings.id names, found and opened under the device-list lock: in the current list
// first (discovery costs about a second), then in a fresh one when it is not there or when
// `refresh_device_list` asks. `info.device` gets the device.
Result<ArvCamera*> OpenDevice(const CameraSettings& settings, bool refresh_device_list,
                              CameraInfo& info) {
  GErrorSlot error;
  std::lock_guard lock(DeviceListMutex());
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
  ArvCamera* camera = arv_camera_new(info.device.id.c_str(), error.out());
  if (camera == nullptr || error) {
    if (camera != nullptr) g_object_unref(camera);
    // Whatever the cause (no answer, another host in control), the camera is not usable now.
    return Unavailable("cannot open camera " + DescribeDevice(info.device) + ": " +
                       error.message());
  }
  return camera;
}

// The stream and its pool of `buffers` buffers. `stream` is set as soon as it exists (the caller
// releases it, also on failure).
Status CreateStream(ConfigureStep& step, int buffers, ArvStream*& stream) {
  const guint payload = arv_camera_get_payload(step.camera, step.error.out());
  if (step.error) return step.Failed("reading the payload size");
  if (arv_camera_is_gv_device(step.camera)) {
    // A plain UDP socket rather than Aravis's packet socket (used when the process has
    // CAP_NET_RAW): a packet socket catches every GVSP packet on the interface until its filter
    // is attached, so a stream reopened while the other camera streams to the same interface
    // takes that camera's frame ids as its own, then drops its real frames as "late" for
    // seconds. The plain socket receives only its own port's packets.
    arv_camera_gv_set_stream_options(step.camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
  }
  stream = arv_camera_create_stream(step.camera, nullptr, nullptr, step.error.out());
  if (stream == nullptr || step.error) return step.Failed("creating the stream");
  if (ARV_IS_GV_STREAM(stream)) {
    // The kernel's default receive buffer (~200 kB) is smaller than one 640x480 frame: any
    // scheduling hiccup of the stream thread then drops packets and frames. Ask for a few
    // frames' worth (Linux caps it at net.core.rmem_max, which large ROIs may need raised).
    const size_t wanted = std::clamp<size_t>(4 * static_cast<size_t>(payload), 1 << 20, 32 << 20);
    g_object_set(stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_FIXED, "socket-buffer-size",
                 static_cast<gint>(wanted), nullptr);
  }
  for (int i = 0; i < buffers; ++i) {
    arv_stream_push_buffer(stream, arv_buffer_new_allocate(payload));
  }
  return Status::Ok();
}

}  // namespace

Result<std::unique_ptr<AravisCamera>> AravisCamera::Open(const CameraSettings& settings,
                                                         bool refresh_device_list) {
  std::unique_ptr<AravisCamera> cam(new AravisCamera());
  cam->settings_ = settings;
  Handles& h = *cam->handles_;
  CameraInfo& info = cam->info_;
  Result<ArvCamera*> opened = OpenDevice(settings, refresh_device_list, info);
  if (!opened.ok()) return opened.error();
  h.camera = *opened;
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

  GErrorSlot error;
  ConfigureStep step{h.camera, name, error, *cam};
  Status done = ConfigureCamera(step, settings, info, h.pixel_format);
  if (done.ok()) done = CreateStream(step, settings.buffers, h.stream);
  if (!done.ok()) return done.error();
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
