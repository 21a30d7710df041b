// Calibrations kept on disk: one YAML file per calibration, its report beside it, and the id of
// the active one.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/calibration/report.h"
#include "core/common/error.h"
#include "core/geometry/calibration_io.h"

namespace stevi::calibration {

// A stored calibration's id: 1, 2, 3, ... in the order they were added, never reused.
struct CalibrationId {
  std::int64_t value = 0;

  // "cal-000001" (at least six digits), the stem of its files.
  std::string Name() const;
  // Parses "cal-000001" (also without the leading zeros); nullopt for anything else.
  static std::optional<CalibrationId> Parse(const std::string& name);

  friend bool operator==(const CalibrationId&, const CalibrationId&) = default;
  friend auto operator<=>(const CalibrationId&, const CalibrationId&) = default;
};

// One line of List().
struct CalibrationSummary {
  CalibrationId id;
  std::int64_t created_unix_ms = 0;  // the report's created_unix_ms
  double rms_px = 0;
  bool passed = false;
  bool swap_left_right = false;
  double baseline_m = 0;  // |T|
  cv::Size image_size;
};

struct StoredCalibration {
  CalibrationId id;
  geometry::StereoCalibration calibration;
  CalibrationReport report;
  std::string yaml_text;  // the calibration file as stored (OpenCV FileStorage YAML)
};

class CalibrationStore;

struct OpenedStore {
  std::unique_ptr<CalibrationStore> store;
  // What was wrong in the directory, one line each ("cal-000003.yaml: M1: expected a 3x3 matrix";
  // "active: points to cal-000007, which is missing; using cal-000002 (the last good one)").
  std::vector<std::string> problems;
};

// A directory of calibrations:
//   cal-000001.yaml          the calibration (SaveCalibrationYaml: readable by OpenCV's tools)
//   cal-000001.report.yaml   its CalibrationReport (ReportToYaml), with the created time
//   active                   one line, the active calibration's name ("cal-000001")
// Every file is written atomically (temporary file, fsync, rename, fsync of the directory) and
// no stored calibration is ever deleted or overwritten. A calibration that failed its quality gates
// (report.passed = false) can be added and inspected, but not activated. Thread-safe: every method
// takes one mutex.
class CalibrationStore {
 public:
  // Opens (creating it when missing) the directory and reads every calibration in it. Unreadable
  // files do not fail the open: they are left out and listed in `problems`, and their ids are
  // still never reused. The active calibration is the one the `active` file names, when it is
  // readable and passed its gates; otherwise (a missing, corrupt or failed calibration, or an
  // unreadable `active` file) the last good one (the highest id that is readable and passed) is
  // used, and the problem says so. Open() never writes: the `active` file is left as it was until
  // the next Activate(). Errors: kInvalidArgument when the path is not a directory and cannot be
  // created.
  static Result<OpenedStore> Open(const std::string& directory);

  CalibrationStore(const CalibrationStore&) = delete;
  CalibrationStore& operator=(const CalibrationStore&) = delete;

  // The readable calibrations, by increasing id.
  std::vector<CalibrationSummary> List() const;

  // One calibration, read from disk. kNotFound for an unknown id (or a file that went missing);
  // kInvalidArgument when its files no longer parse.
  Result<StoredCalibration> Get(CalibrationId id) const;

  // Stores a calibration and its report under the next id: the report file first, then the
  // calibration file (whose presence marks the entry complete). The report's created_unix_ms is
  // set to now when it is 0. Does not activate it. kInvalidArgument for an invalid calibration,
  // kInternal when writing fails (nothing is listed then).
  Result<CalibrationId> Add(const geometry::StereoCalibration& calibration,
                            const CalibrationReport& report);

  // Makes `id` the active calibration and persists that. kNotFound for an unknown id;
  // kFailedPrecondition when its report did not pass the quality gates (the failed gates are
  // named); kInternal when the `active` file cannot be written (the active one is unchanged then).
  Status Activate(CalibrationId id);

  // The active calibration's id, if any.
  std::optional<CalibrationId> ActiveId() const;
  // The active calibration; kFailedPrecondition when there is none.
  Result<StoredCalibration> Active() const;

  const std::string& directory() const { return directory_; }

 private:
  explicit CalibrationStore(std::string directory) : directory_(std::move(directory)) {}
  std::string CalibrationPath(CalibrationId id) const;
  std::string ReportPath(CalibrationId id) const;
  Result<StoredCalibration> ReadLocked(CalibrationId id) const;
  // Open's steps. The calibrations of `calibration_ids` whose file and report are readable into
  // entries_; a problem for each one left out (and a report without its calibration), and in
  // `left_out` why, by id. Then the active calibration the `active` file names (raising `max_id`
  // to its id), or the last good one with a problem when it cannot be used.
  void LoadEntries(const std::set<std::int64_t>& calibration_ids,
                   const std::set<std::int64_t>& report_ids, std::vector<std::string>& problems,
                   std::map<std::int64_t, std::string>& left_out);
  void LoadActive(const std::map<std::int64_t, std::string>& left_out, std::int64_t& max_id,
                  std::vector<std::string>& problems);

  const std::string directory_;
  mutable std::mutex mu_;
  std::vector<CalibrationSummary> entries_;  // readable calibrations, by id
  std::int64_t next_id_ = 1;
  std::optional<CalibrationId> active_;
};

}  // namespace stevi::calibration
