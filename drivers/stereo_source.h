// Where stereo pairs come from: the synthetic rig, image sequences and videos, cameras, replays.
#pragma once

#include <memory>
#include <string>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/geometry/stereo_rig.h"

namespace stevi::drivers {

// Thread-compatible: one thread calls Next(). Rig() and the accessors are safe from any thread.
class StereoSource {
 public:
  virtual ~StereoSource() = default;

  // A short description for status and logs ("synthetic 640x480 f=700px B=0.6m").
  virtual std::string Describe() const = 0;

  // The rig whose calibration the frames follow (an ideal rectified rig for synthetic frames).
  virtual std::shared_ptr<const geometry::StereoRig> Rig() const = 0;

  // Produces the next frame as soon as it can (no pacing: the caller paces, see NominalFps()).
  // kOutOfRange at the end of a finite sequence; kUnavailable when a device is down;
  // kInvalidArgument for an unreadable or mismatched pair (naming the file).
  virtual Result<StereoFrame> Next() = 0;

  // Frames per second the source should be paced at when played live; 0 = as fast as it can.
  virtual double NominalFps() const = 0;
};

}  // namespace stevi::drivers
