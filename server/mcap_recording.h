// stevi-server --record-mcap FILE: the flight as an MCAP file that Foxglove opens, with the
// channels the station serves (drivers/mcap/flight_log.h). It subscribes like any client: to the
// track frames (the broadcaster), to the left and disparity previews (the preview hub, at the
// image rate) and, once a second, to the status; a thread of its own writes the file, so the
// pipeline never waits for the disk. No gRPC here.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "core/common/error.h"
#include "drivers/mcap/flight_log.h"
#include "server/runtime/broadcaster.h"
#include "server/runtime/engine.h"
#include "server/runtime/preview_hub.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::server {

// As in service.h, which this header does not include (it brings gRPC).
using FrameBroadcaster = Broadcaster<std::shared_ptr<const v1::TrackFrame>>;
using FrameSubscription = Subscription<std::shared_ptr<const v1::TrackFrame>>;
class RecordingManager;

struct McapRecordingOptions {
  std::string file;  // never an existing file
  drivers::FlightLogOptions log;
  int image_max_width_px = 4096;  // the images at their full size up to this width
  int image_jpeg_quality = 85;
};

// What the MCAP recording did, for status and the shutdown log.
struct McapRecordingStatus {
  std::string file;
  bool active = false;
  drivers::FlightLogCounts counts;
  uint64_t frames_dropped = 0;  // track frames the writer's queue had no room for
  std::string error;            // why it stopped writing early (a full disk), else empty
};

// Thread-safe.
class McapRecording {
 public:
  // Creates the file and subscribes. kAlreadyExists for an existing file, kResourceExhausted
  // when the broadcaster or the preview hub has no room for another subscriber.
  static Result<std::unique_ptr<McapRecording>> Start(McapRecordingOptions options,
                                                      const Engine& engine,
                                                      FrameBroadcaster& broadcaster,
                                                      PreviewHub& previews,
                                                      const RecordingManager* recording);
  ~McapRecording();
  McapRecording(const McapRecording&) = delete;
  McapRecording& operator=(const McapRecording&) = delete;

  // Writes what is queued, closes the file (summary and index) and unsubscribes. After the
  // broadcaster was closed (shutdown) every frame it published is in the file. Idempotent.
  McapRecordingStatus Stop();
  McapRecordingStatus Status() const;

 private:
  McapRecording(McapRecordingOptions options, const Engine& engine, FrameBroadcaster& broadcaster,
                PreviewHub& previews, const RecordingManager* recording);
  void Run();
  // One pass over both queues; false when the frames' subscription has ended.
  bool Drain();
  void WriteStatus(int64_t unix_time_ns);
  void Fail(const Error& error);

  const McapRecordingOptions options_;
  const Engine& engine_;
  FrameBroadcaster& broadcaster_;
  PreviewHub& previews_;
  const RecordingManager* recording_;
  std::unique_ptr<drivers::FlightLog> log_;  // the writer thread's
  std::shared_ptr<FrameSubscription> frames_;
  std::shared_ptr<PreviewSubscription> images_;
  int64_t next_status_ns_ = 0;  // the writer thread's

  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool wake_ = false;           // (mu_) something arrived
  bool stop_ = false;           // (mu_)
  McapRecordingStatus status_;  // (mu_)
  std::thread thread_;
};

}  // namespace stevi::server
