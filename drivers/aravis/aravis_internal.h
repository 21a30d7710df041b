// Internal to drivers/aravis: what aravis_camera.cc (devices, opening, the stream) and
// aravis_configure.cc (the configure steps of AravisCamera::Open) share. Includes Aravis: only the
// library's own sources include it. Not part of the drivers' interface.
#pragma once

#include <arv.h>

#include <string>
#include <vector>

#include "core/common/error.h"
#include "drivers/aravis/aravis_camera.h"

namespace stevi::drivers::aravis_internal {

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

inline std::string Str(const char* s) { return s != nullptr ? s : ""; }

inline std::string Join(const std::vector<std::string>& items) {
  std::string out;
  for (const std::string& item : items) {
    if (!out.empty()) out += ", ";
    out += item;
  }
  return out;
}

// Strings of an Aravis "dup" array (the array is freed, the strings belong to Aravis).
inline std::vector<std::string> TakeStrings(const char** strings, guint n) {
  std::vector<std::string> out;
  if (strings == nullptr) return out;
  for (guint i = 0; i < n; ++i) out.push_back(Str(strings[i]));
  g_free(static_cast<gpointer>(strings));
  return out;
}

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

// Configures the opened camera as `settings` ask, in order: pixel format (on some cameras it
// changes the ROI steps), centred region of interest, exposure, gain, frame rate (before the
// trigger: on several vendors setting it switches the FrameStart trigger off), trigger and
// continuous acquisition. `info` gets what the camera took; `arv_format` the ArvPixelFormat the
// stream should carry.
Status ConfigureCamera(ConfigureStep& step, const CameraSettings& settings, CameraInfo& info,
                       guint32& arv_format);

}  // namespace stevi::drivers::aravis_internal
