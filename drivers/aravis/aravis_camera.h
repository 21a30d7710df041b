// One GenICam camera (GigE Vision, USB3 Vision, Aravis's fake) through Aravis's C API.
// This header does not include Aravis: the library links it privately.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/error.h"
#include "drivers/aravis/stereo_pairer.h"

namespace stevi::drivers {

enum class TriggerMode {
  kFreeRun,   // the camera paces itself at the frame rate
  kSoftware,  // the host triggers each frame (AravisCamera::SoftwareTrigger)
  kHardware,  // an external signal on a line of the camera (e.g. "Line0")
};
const char* TriggerModeName(TriggerMode mode);

// Which time a frame carries.
enum class TimestampSource {
  // The camera's timestamp (arv_buffer_get_timestamp), else the host's time of arrival. Pairing
  // two cameras by it needs clocks in one time base (PTP, or Aravis's fake cameras).
  kCamera,
  // The host's wall-clock time at the arrival of the frame's first packet.
  kHost,
};

// The pixel formats delivered as grey. Bayer mosaics are converted with cv::cvtColor.
enum class PixelFormat { kMono8, kBayerRG8, kBayerGR8, kBayerGB8, kBayerBG8 };
// GenICam names ("Mono8", "BayerRG8", ...).
const char* PixelFormatName(PixelFormat format);
std::optional<PixelFormat> ParsePixelFormat(std::string_view name);
// "Mono8, BayerRG8, BayerGR8, BayerGB8, BayerBG8".
std::string SupportedPixelFormats();

// A copy of one packed 8-bit image of `format` as CV_8UC1 (Bayer is demosaiced, then converted
// to grey). kInvalidArgument when `size` is not width * height.
Result<cv::Mat> ToGrey(const void* data, size_t size, int width, int height, PixelFormat format);

// A device as discovered by Aravis.
struct DeviceEntry {
  std::string id;       // Aravis device id, e.g. "Aravis-Fake-GV01" (vendor-model-serial)
  std::string serial;   // e.g. "GV01"
  std::string address;  // IP address for GigE Vision, else empty or a bus id
  std::string vendor;
  std::string model;
  std::string protocol;  // "GigEVision", "USB3Vision", "Fake"
};
// "Aravis-Fake-GV01 (serial GV01, 127.0.0.1)".
std::string DescribeDevice(const DeviceEntry& device);

// Discovers the devices (arv_update_device_list: about 1 s while GigE discovery waits for
// answers). Thread-safe (a process-wide lock serialises Aravis's device list).
std::vector<DeviceEntry> ListDevices();

// Enables or disables one of Aravis's interfaces ("GigEVision", "USB3Vision", "Fake") for the
// whole process. Tests enable the in-process "Fake" interface (device id "Fake_1").
void SetAravisInterfaceEnabled(const std::string& interface_id, bool enabled);

struct CameraSettings {
  // Device id, serial number or IP address.
  std::string id;
  // Region of interest, pixels, centred on the sensor.
  int roi_width = 640;
  int roi_height = 480;
  // "" picks Mono8 where offered, else the first Bayer*8 format the camera offers.
  std::string pixel_format;
  double frame_rate_hz = 30;  // frames per second (free-run; the trigger rate otherwise)
  double exposure_us = 0;     // 0 = automatic where the camera has it
  double gain_db = -1;        // negative = automatic where the camera has it
  TriggerMode trigger = TriggerMode::kFreeRun;
  std::string trigger_line;  // kHardware: the trigger source, e.g. "Line0"
  int buffers = 8;           // stream buffers (>= 2)
  TimestampSource timestamps = TimestampSource::kCamera;
};

// What the camera was set to, as read back from it.
struct CameraInfo {
  DeviceEntry device;
  cv::Size sensor;
  cv::Rect roi;
  PixelFormat pixel_format = PixelFormat::kMono8;
  double frame_rate_hz = 0;
  bool exposure_auto = false;
  double exposure_us = 0;
  bool gain_auto = false;
  double gain_db = 0;
  TriggerMode trigger = TriggerMode::kFreeRun;
  // Requests the camera could not honour that are not errors ("exposure: no automatic mode,
  // kept 10000 us").
  std::vector<std::string> notes;
};

// Stream health since the camera was opened.
struct CameraStats {
  uint64_t frames = 0;           // complete frames delivered by Pop()
  uint64_t incomplete = 0;       // buffers dropped: missing packets, timeouts, wrong size or format
  uint64_t resent_packets = 0;   // GigE packets recovered by resend requests
  uint64_t missing_packets = 0;  // GigE packets never received
  uint64_t underruns = 0;        // frames lost because no buffer was free
};

// RAII owner of one opened, configured camera and its stream (ArvCamera + ArvStream).
// Thread-compatible: one thread uses it at a time. control_lost() is safe from any thread.
class AravisCamera {
 public:
  // Finds the device (by id, serial number or IP address), opens it and configures it:
  // centred ROI, pixel format, exposure, gain, frame rate, trigger; then creates the stream
  // with settings.buffers buffers. Acquisition is not started.
  // kNotFound when no device matches (the message lists the devices present);
  // kUnavailable when it cannot be opened or stops answering; kInvalidArgument for settings
  // the camera cannot take (naming the camera, the value and what it supports).
  // `refresh_device_list`: rediscover devices before matching even when the last listing
  // already holds the id (after a failed reconnection, the camera may have a new address).
  static Result<std::unique_ptr<AravisCamera>> Open(const CameraSettings& settings,
                                                    bool refresh_device_list = false);

  // Stops acquisition (unless the camera was lost) and releases the stream and the device.
  // A lost GigE camera still costs about 2.5 s here: Aravis tries to release its control
  // channel until its request times out.
  ~AravisCamera();
  AravisCamera(const AravisCamera&) = delete;
  AravisCamera& operator=(const AravisCamera&) = delete;

  const CameraInfo& info() const { return info_; }
  // Device id ("Aravis-Fake-GV01").
  const std::string& id() const { return info_.device.id; }

  Status StartAcquisition();

  // Waits up to `timeout` for the next complete frame. Incomplete or malformed buffers are
  // dropped, counted, and returned to the pool; waiting goes on until the timeout. nullopt on
  // timeout; kUnavailable once the device signalled the loss of its control channel.
  Result<std::optional<MonoFrame>> Pop(std::chrono::microseconds timeout);

  // Triggers one frame (TriggerMode::kSoftware).
  Status SoftwareTrigger();

  // Reads a register of the device: OK while it answers (about 2.5 s to fail on a lost GigE
  // camera).
  Status Ping();

  // Whether the device lost its control channel: for GigE Vision, Aravis's heartbeat thread found
  // the camera gone or controlled by another host (and cleared the device's controller flag);
  // for other devices, the device emitted "control-lost".
  bool control_lost() const;
  // Marks the device as gone, so that the destructor skips the AcquisitionStop it cannot send.
  void MarkLost() { lost_ = true; }

  CameraStats Stats() const;

 private:
  struct Handles;
  AravisCamera();

  std::unique_ptr<Handles> handles_;
  CameraInfo info_;
  CameraSettings settings_;
  bool acquiring_ = false;
  bool lost_ = false;
  uint64_t frames_ = 0;
  uint64_t incomplete_ = 0;
};

}  // namespace stevi::drivers
