// Where stereo pairs come from: the synthetic rig, image sequences and videos, cameras, replays.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/common/stereo_frame.h"
#include "core/geo/vehicle_state.h"
#include "core/geometry/stereo_rig.h"
#include "drivers/truth.h"

namespace stevi::drivers {

// Health counters of a source, for status. Sources that pair two devices fill the pairing fields;
// the others leave them 0.
struct SourceCounters {
  uint64_t pairs = 0;               // pairs delivered
  uint64_t unpaired_dropped = 0;    // frames dropped without a partner within the tolerance
  uint64_t incomplete_dropped = 0;  // incomplete or corrupt buffers dropped
  uint64_t reconnects = 0;          // successful reopenings after a device was lost
  int64_t last_skew_ns = 0;         // right minus left capture time of the last pair
  int64_t max_abs_skew_ns = 0;      // largest |skew| of a delivered pair since the start
  double mean_abs_skew_ns = 0;      // mean |skew| over the recent pairs (up to 100)
};

// Thread-compatible: one thread calls Next(). Rig() and the accessors are safe from any thread.
class StereoSource {
 public:
  virtual ~StereoSource() = default;

  // A short description for status and logs ("synthetic 640x480 f=700px B=0.6m").
  virtual std::string Describe() const = 0;

  // The rig whose calibration the frames follow (an ideal rectified rig for synthetic frames).
  virtual std::shared_ptr<const geometry::StereoRig> Rig() const = 0;

  // The size of the images Next() delivers: the rig's, or (a source without a calibration yet,
  // such as cameras) the source's own.
  virtual cv::Size ImageSize() const { return Rig() ? Rig()->image_size() : cv::Size(); }

  // Produces the next frame as soon as it can (no pacing: the caller paces, see NominalFps()).
  // kOutOfRange at the end of a finite sequence; kUnavailable when a device is down;
  // kInvalidArgument for an unreadable or mismatched pair (naming the file).
  virtual Result<StereoFrame> Next() = 0;

  // Frames per second the source should be paced at when played live; 0 = as fast as it can (or
  // the source paces itself: a camera, a replay at its recorded timing).
  virtual double NominalFps() const = 0;

  // Health counters; safe from any thread while another calls Next().
  virtual SourceCounters Counters() const { return {}; }

  // Makes a Next() blocked in another thread return at once, and every later call too, with
  // kUnavailable: the owner is stopping. Safe from any thread. A source whose Next() never waits
  // long (a synthetic scene, image files) need not override it.
  virtual void Interrupt() {}

  // Optional capabilities: a source that has none keeps these defaults.
  // The vehicle states recorded with the frames (a replay), each at its frame's Unix time: the
  // poses to georeference them with.
  virtual std::vector<geo::VehicleState> RecordedVehicleStates() const { return {}; }
  // What the operator should know about how the source was opened (a replay's unreadable
  // calibration, a truncated recording).
  virtual std::vector<std::string> Notes() const { return {}; }
  // The truth of the frame last returned by Next(), for a source that knows it (the synthetic
  // rig); nullptr otherwise.
  virtual const FrameTruth* LastTruth() const { return nullptr; }
};

}  // namespace stevi::drivers
