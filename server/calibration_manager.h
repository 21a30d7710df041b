// The calibration side of the server: the versioned store in the data directory, calibrating from
// uploaded or captured pairs, and the hot swap of the engine's rig. The RPC logic as plain
// functions of (manager, request); the gRPC reactors in calibration_service.h only move messages.
#pragma once

#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "core/calibration/calibrate.h"
#include "core/calibration/store.h"
#include "core/common/error.h"
#include "server/runtime/engine.h"
#include "stevi/v1/calibration_service.pb.h"

namespace stevi::server {

// Limits of one Calibrate upload.
inline constexpr int kMaxCalibrationPairs = 200;
inline constexpr int64_t kMaxCalibrationUploadBytes = int64_t{1} << 30;  // 1 GiB in all

// Thread-safe. Owns one worker thread for the long jobs (calibrating, capturing), so that they
// never block a gRPC callback thread; Stop() (and the destructor) ends and joins it.
class CalibrationManager {
 public:
  // Opens (creates) the store in `data_dir`. When it has an active calibration that fits the
  // source's image size, the engine switches to it now (a calibration restored after a restart
  // wins over the source's own). Unreadable files never fail the start: they are in problems().
  static Result<std::unique_ptr<CalibrationManager>> Open(const std::string& data_dir,
                                                          Engine& engine);
  ~CalibrationManager();
  void Stop();

  // What the store found wrong at start, and what could not be applied.
  const std::vector<std::string>& problems() const { return problems_; }

  // Calibrates from pairs, stores the result (also one that failed its gates, for inspection) and,
  // with settings.apply and every gate passed, activates it. kInvalidArgument names a bad setting
  // or input (no board anywhere, too few pairs, ...): nothing is stored then and the active
  // calibration is untouched. When `abandoned()` is true before the work starts or before the
  // result is stored (the caller cancelled, or its deadline passed), nothing is stored or applied:
  // kFailedPrecondition.
  Result<v1::CalibrationReport> Calibrate(const v1::CalibrationSettings& settings,
                                          const std::vector<calibration::ImagePair>& pairs,
                                          const std::function<bool()>& abandoned = {});

  // Grabs request.pairs() pairs from the engine's source, one every request.interval_s(), calls
  // `emit` with a progress message per pair, then calibrates (as Calibrate) and emits the report.
  // Stops early with kCancelled when `cancelled()` turns true or the
  // manager stops, and with kUnavailable when the source delivers no frame for 5 s.
  Status Capture(const v1::CaptureCalibrationRequest& request,
                 const std::function<void(const v1::CaptureProgress&)>& emit,
                 const std::function<bool()>& cancelled);
  // Request checks of Capture (before any work is queued): INVALID_ARGUMENT naming the field.
  static Status ValidateCapture(const v1::CaptureCalibrationRequest& request);

  v1::ListCalibrationsResponse List() const;
  Result<v1::CalibrationRecord> Get(const std::string& id) const;
  // Builds the rig (rectification maps) on this thread, persists the active id, then swaps the
  // engine's rig between two frames. kNotFound, kFailedPrecondition (failed gates, another image
  // size than the source's), kInvalidArgument (the calibration does not make a rig).
  Result<v1::CalibrationRecord> Activate(const std::string& id);

  // Runs `job` on the worker thread; false when stopping (the job is dropped).
  bool Post(std::function<void()> job);

 private:
  CalibrationManager(std::unique_ptr<calibration::CalibrationStore> store, Engine& engine);
  // Applies a stored calibration to the engine; with `persist`, the store's `active` file names it.
  Result<v1::CalibrationRecord> ActivateLocked(calibration::CalibrationId id, bool persist);
  void WorkerLoop();
  bool Stopping() const;

  std::unique_ptr<calibration::CalibrationStore> store_;
  Engine& engine_;
  std::vector<std::string> problems_;
  std::mutex activate_mu_;  // one activation (or calibrate-and-apply) at a time

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> jobs_;
  bool stopping_ = false;
  std::thread worker_;
};

// Settings to core options: "settings.board.columns: ..." style problems.
Result<calibration::CalibrationOptions> ToCalibrationOptions(
    const v1::CalibrationSettings& settings);
v1::CalibrationReport ToProto(const calibration::CalibrationReport& report,
                              const std::string& calibration_id, bool applied);

}  // namespace stevi::server
