#include "server/calibration_manager.h"

#include "server/field_mapping.h"

#include "core/common/format.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/calibration/chessboard.h"
#include "core/calibration/report.h"
#include "core/geometry/stereo_rig.h"

namespace stevi::server {
namespace {

// A capture that stops before its last pair: the client cancelled it, or the server is stopping.
Error CaptureCancelled() { return Cancelled("capture cancelled"); }

constexpr int kDefaultCapturePairs = 20;
constexpr double kDefaultCaptureInterval = 0.5;
constexpr auto kCaptureFrameTimeout = std::chrono::seconds(5);

v1::CalibrationSummary ToSummary(const calibration::CalibrationSummary& s, bool active) {
  v1::CalibrationSummary out;
  out.set_calibration_id(s.id.Name());
  out.set_created_unix_ns(s.created_unix_ms * 1'000'000);
  out.set_passed(s.passed);
  out.set_rms_px(s.rms_px);
  out.set_baseline_m(s.baseline_m);
  out.set_width(s.image_size.width);
  out.set_height(s.image_size.height);
  out.set_active(active);
  return out;
}

// The fraction of a grid's cells (over the image) whose centre lies inside some view's board.
double Coverage(const std::vector<std::vector<cv::Point2f>>& hulls, cv::Size image, cv::Size grid) {
  if (image.area() <= 0 || hulls.empty()) return 0;
  int covered = 0;
  for (int gy = 0; gy < grid.height; ++gy) {
    for (int gx = 0; gx < grid.width; ++gx) {
      const cv::Point2f centre((gx + 0.5f) * image.width / grid.width,
                               (gy + 0.5f) * image.height / grid.height);
      for (const auto& hull : hulls) {
        if (cv::pointPolygonTest(hull, centre, false) >= 0) {
          ++covered;
          break;
        }
      }
    }
  }
  return static_cast<double>(covered) / (grid.width * grid.height);
}

cv::Mat1b Grey(const cv::Mat& image) {
  cv::Mat1b grey;
  if (image.channels() == 1) {
    image.convertTo(grey, CV_8U);
  } else if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  }
  return grey;
}

// The cv::CALIB_* bits of `flags` this service maps onto the solver's options.
void ApplyCalibrationFlags(int flags, calibration::CalibrationModel& m,
                           std::vector<std::string>& problems) {
  const auto take = [&](int bit, bool& option) {
    if (flags & bit) {
      option = true;
      flags &= ~bit;
    }
  };
  take(cv::CALIB_FIX_INTRINSIC, m.fix_intrinsics);
  take(cv::CALIB_SAME_FOCAL_LENGTH, m.same_focal_length);
  take(cv::CALIB_FIX_ASPECT_RATIO, m.fix_aspect_ratio);
  take(cv::CALIB_FIX_PRINCIPAL_POINT, m.fix_principal_point);
  take(cv::CALIB_ZERO_TANGENT_DIST, m.zero_tangent_distortion);
  take(cv::CALIB_FIX_K3, m.fix_k3);
  take(cv::CALIB_RATIONAL_MODEL, m.rational_model);
  if (flags != 0) {
    problems.push_back("flags: unsupported cv::CALIB_* bits " + std::to_string(flags) +
                       " (supported: FIX_INTRINSIC, SAME_FOCAL_LENGTH, FIX_ASPECT_RATIO, "
                       "FIX_PRINCIPAL_POINT, ZERO_TANGENT_DIST, FIX_K3, RATIONAL_MODEL)");
  }
}

}  // namespace

Result<calibration::CalibrationOptions> ToCalibrationOptions(const v1::CalibrationSettings& s) {
  calibration::CalibrationOptions o;
  // The board has no default: a proto3 zero is "not given", which the field list would keep.
  std::vector<std::string> problems;
  if (s.board().columns() == 0 || s.board().rows() == 0 || s.board().square_m() == 0) {
    problems.push_back("board: columns, rows and square_m are required");
  }
  AppendPrefixed(problems, "", FieldsFromProto(s, o));
  if (s.has_flags()) ApplyCalibrationFlags(s.flags(), o.model, problems);
  AppendPrefixed(problems, "", o.Validate());
  if (!problems.empty()) {
    std::vector<std::string> prefixed;
    AppendPrefixed(prefixed, "settings.", problems);
    return InvalidArgument(prefixed);
  }
  return o;
}

v1::CalibrationReport ToProto(const calibration::CalibrationReport& r,
                              const std::string& calibration_id, bool applied) {
  v1::CalibrationReport out;
  out.set_calibration_id(calibration_id);
  out.set_passed(r.passed);
  out.set_applied(applied);
  for (const calibration::GateFailure& f : r.failures) out.add_failures(f.message);
  for (const std::string& w : r.warnings) out.add_warnings(w);
  out.set_pairs_total(r.pairs_given);
  out.set_pairs_used(r.pairs_used);
  out.set_rms_px(r.rms_px);
  out.set_rms_left_px(r.rms_left_px);
  out.set_rms_right_px(r.rms_right_px);
  out.set_epipolar_error_px(r.epipolar_mean_px);
  out.set_coverage_union_left(r.coverage_union_left);
  out.set_coverage_union_right(r.coverage_union_right);
  for (const calibration::PairReport& p : r.pairs) {
    v1::PairResult* pr = out.add_pairs();
    pr->set_name(p.name);
    pr->set_used(true);
    pr->set_rms_px(
        std::sqrt(0.5 * (p.rms_left_px * p.rms_left_px + p.rms_right_px * p.rms_right_px)));
    pr->set_coverage_left(p.coverage_left);
    pr->set_coverage_right(p.coverage_right);
  }
  for (const calibration::RejectedPair& p : r.rejected) {
    v1::PairResult* pr = out.add_pairs();
    pr->set_name(p.name);
    pr->set_used(false);
    pr->set_rejected_reason(std::string(calibration::RejectReasonName(p.reason)) +
                            (p.detail.empty() ? "" : ": " + p.detail));
  }
  out.set_f_px(r.rectified_f_px);
  out.set_baseline_m(r.baseline_m);
  out.set_width(r.image_size.width);
  out.set_height(r.image_size.height);
  out.set_swapped_left_right(r.swap_left_right);
  out.set_text(calibration::FormatReportText(r));
  return out;
}

Result<std::unique_ptr<CalibrationManager>> CalibrationManager::Open(const std::string& data_dir,
                                                                     Engine& engine) {
  Result<calibration::OpenedStore> opened = calibration::CalibrationStore::Open(data_dir);
  if (!opened.ok()) return opened.error();
  std::unique_ptr<CalibrationManager> manager(
      new CalibrationManager(std::move(opened->store), engine));
  manager->problems_ = std::move(opened->problems);
  if (std::optional<calibration::CalibrationId> active = manager->store_->ActiveId()) {
    // Applied, not persisted: when the store fell back from an unreadable choice, the operator's
    // choice in the `active` file stays for the start after the file is repaired.
    Result<v1::CalibrationRecord> applied = manager->ActivateLocked(*active, /*persist=*/false);
    if (!applied.ok()) {
      manager->problems_.push_back("the stored active calibration " + active->Name() +
                                   " was not applied: " + applied.error().message);
    }
  }
  return manager;
}

CalibrationManager::CalibrationManager(std::unique_ptr<calibration::CalibrationStore> store,
                                       Engine& engine)
    : store_(std::move(store)), engine_(engine), worker_([this] { WorkerLoop(); }) {}

CalibrationManager::~CalibrationManager() { Stop(); }

void CalibrationManager::Stop() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (worker_.joinable()) worker_.join();
}

bool CalibrationManager::Stopping() const {
  std::lock_guard lock(mu_);
  return stopping_;
}

bool CalibrationManager::Post(std::function<void()> job) {
  {
    std::lock_guard lock(mu_);
    if (stopping_) return false;
    jobs_.push_back(std::move(job));
  }
  cv_.notify_all();
  return true;
}

void CalibrationManager::WorkerLoop() {
  while (true) {
    std::function<void()> job;
    {
      std::unique_lock lock(mu_);
      cv_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
      if (jobs_.empty()) return;  // stopping, nothing left
      job = std::move(jobs_.front());
      jobs_.pop_front();
    }
    // A job that finds the manager stopping ends early (Capture checks), so this drains quickly.
    job();
  }
}

Result<v1::CalibrationReport> CalibrationManager::Calibrate(
    const v1::CalibrationSettings& settings, const std::vector<calibration::ImagePair>& pairs,
    const std::function<bool()>& abandoned) {
  Result<calibration::CalibrationOptions> options = ToCalibrationOptions(settings);
  if (!options.ok()) return options.error();
  if (pairs.empty()) return InvalidArgument("no image pair was uploaded");
  const auto gone = [&] { return abandoned && abandoned(); };
  const Error abandoned_error{ErrorCode::kFailedPrecondition,
                              "the call was cancelled or its deadline passed; nothing was stored"};
  if (gone()) return abandoned_error;  // it waited behind other work for longer than its deadline
  Result<calibration::CalibrationResult> result = calibration::CalibrateStereo(pairs, *options);
  if (!result.ok()) return result.error();
  // The caller has gone: it was told DEADLINE_EXCEEDED or CANCELLED, so nothing may change.
  if (gone()) return abandoned_error;
  calibration::CalibrationReport report = result->report;
  Result<calibration::CalibrationId> id = store_->Add(result->calibration, report);
  if (!id.ok()) return id.error();
  bool applied = false;
  if (settings.apply() && report.passed) {
    Result<v1::CalibrationRecord> activated = Activate(id->Name());
    if (!activated.ok()) {
      report.warnings.push_back("not applied: " + activated.error().message);
    } else {
      applied = true;
    }
  }
  return ToProto(report, id->Name(), applied);
}

Status CalibrationManager::ValidateCapture(const v1::CaptureCalibrationRequest& request) {
  std::vector<std::string> problems;
  if (request.pairs() != 0 && (request.pairs() < 1 || request.pairs() > kMaxCalibrationPairs)) {
    problems.push_back("pairs: must be in 1.." + std::to_string(kMaxCalibrationPairs) +
                       Got(request.pairs()));
  }
  if (!(request.interval_s() >= 0 && request.interval_s() <= 60)) {
    problems.push_back("interval_s: must be in [0, 60] seconds" + Got(request.interval_s()));
  }
  Result<calibration::CalibrationOptions> options = ToCalibrationOptions(request.settings());
  if (!options.ok()) problems.push_back(options.error().message);
  if (!problems.empty()) return InvalidArgument(problems);
  return Status::Ok();
}

Status CalibrationManager::Capture(const v1::CaptureCalibrationRequest& request,
                                   const std::function<void(const v1::CaptureProgress&)>& emit,
                                   const std::function<bool()>& cancelled) {
  if (Status valid = ValidateCapture(request); !valid.ok()) return valid;
  const calibration::CalibrationOptions options = ToCalibrationOptions(request.settings()).value();
  const int count = request.pairs() > 0 ? request.pairs() : kDefaultCapturePairs;
  const double interval_s =
      request.interval_s() > 0 ? request.interval_s() : kDefaultCaptureInterval;
  const auto interval = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(interval_s));
  std::vector<calibration::ImagePair> pairs;
  std::vector<std::vector<cv::Point2f>> hulls_left, hulls_right;
  cv::Size image_size;
  for (int i = 1; i <= count; ++i) {
    if (i > 1) {
      // Wait the interval, but stop at once when asked to.
      std::unique_lock lock(mu_);
      cv_.wait_for(lock, interval, [&] { return stopping_; });
    }
    if (Stopping() || cancelled()) return CaptureCancelled();
    Result<StereoFrame> frame = engine_.WaitForCapture(kCaptureFrameTimeout);
    if (!frame.ok()) return frame.error();
    const cv::Mat1b left = Grey(frame->left), right = Grey(frame->right);
    image_size = left.size();
    Result<std::vector<cv::Point2f>> corners_left =
        calibration::DetectChessboard(left, options.board, options.detection);
    Result<std::vector<cv::Point2f>> corners_right =
        calibration::DetectChessboard(right, options.board, options.detection);
    const auto hull = [](const std::vector<cv::Point2f>& points) {
      std::vector<cv::Point2f> h;
      cv::convexHull(points, h);
      return h;
    };
    if (corners_left.ok()) hulls_left.push_back(hull(*corners_left));
    if (corners_right.ok()) hulls_right.push_back(hull(*corners_right));
    pairs.push_back(calibration::ImagePair{left, right, "capture " + std::to_string(i)});
    v1::CaptureProgress progress;
    v1::CapturedPair* p = progress.mutable_pair();
    p->set_index(i);
    p->set_of(count);
    p->set_board_left(corners_left.ok());
    p->set_board_right(corners_right.ok());
    p->set_coverage_left(Coverage(hulls_left, image_size, options.coverage_grid));
    p->set_coverage_right(Coverage(hulls_right, image_size, options.coverage_grid));
    emit(progress);
  }
  if (Stopping() || cancelled()) return CaptureCancelled();
  Result<v1::CalibrationReport> report = Calibrate(request.settings(), pairs);
  if (!report.ok()) return report.error();
  v1::CaptureProgress last;
  *last.mutable_report() = std::move(report).value();
  emit(last);
  return Status::Ok();
}

v1::ListCalibrationsResponse CalibrationManager::List() const {
  v1::ListCalibrationsResponse out;
  const std::optional<calibration::CalibrationId> active = store_->ActiveId();
  for (const calibration::CalibrationSummary& s : store_->List()) {
    *out.add_calibrations() = ToSummary(s, active && *active == s.id);
  }
  if (active) out.set_active_id(active->Name());
  for (const std::string& p : problems_) out.add_store_problems(p);
  return out;
}

Result<v1::CalibrationRecord> CalibrationManager::Get(const std::string& id) const {
  const std::optional<calibration::CalibrationId> parsed = calibration::CalibrationId::Parse(id);
  if (!parsed) {
    return InvalidArgument("calibration_id: expected a name like cal-000001, got '" + id + "'");
  }
  Result<calibration::StoredCalibration> stored = store_->Get(*parsed);
  if (!stored.ok()) return stored.error();
  v1::CalibrationRecord record;
  const std::optional<calibration::CalibrationId> active = store_->ActiveId();
  for (const calibration::CalibrationSummary& s : store_->List()) {
    if (s.id == *parsed) *record.mutable_summary() = ToSummary(s, active && *active == s.id);
  }
  *record.mutable_report() = ToProto(stored->report, parsed->Name(), active && *active == *parsed);
  record.set_yaml(stored->yaml_text);
  return record;
}

Result<v1::CalibrationRecord> CalibrationManager::Activate(const std::string& id) {
  const std::optional<calibration::CalibrationId> parsed = calibration::CalibrationId::Parse(id);
  if (!parsed) {
    return InvalidArgument("calibration_id: expected a name like cal-000001, got '" + id + "'");
  }
  return ActivateLocked(*parsed, /*persist=*/true);
}

Result<v1::CalibrationRecord> CalibrationManager::ActivateLocked(calibration::CalibrationId id,
                                                                 bool persist) {
  std::lock_guard lock(activate_mu_);
  Result<calibration::StoredCalibration> stored = store_->Get(id);
  if (!stored.ok()) return stored.error();
  if (!stored->report.passed) {
    std::string why;
    for (const calibration::GateFailure& f : stored->report.failures) {
      why += (why.empty() ? "" : "; ") + f.message;
    }
    return FailedPrecondition(id.Name() +
                              " failed its quality gates and cannot be activated: " + why);
  }
  const cv::Size source = engine_.source_image_size();
  if (stored->calibration.image_size != source) {
    return FailedPrecondition(id.Name() + " is for " + SizeText(stored->calibration.image_size) +
                              " images, but the source delivers " + SizeText(source));
  }
  // The rectification maps are built here, on the caller's thread, never on the pipeline's.
  Result<geometry::StereoRig> rig =
      geometry::StereoRig::FromCalibration(stored->calibration, id.Name());
  if (!rig.ok()) return rig.error();
  if (persist) {
    if (Status persisted = store_->Activate(id); !persisted.ok()) return persisted.error();
  }
  engine_.SetRig(std::make_shared<const geometry::StereoRig>(std::move(rig).value()),
                 stored->report.swap_left_right);
  v1::CalibrationRecord record;
  for (const calibration::CalibrationSummary& s : store_->List()) {
    if (s.id == id) *record.mutable_summary() = ToSummary(s, true);
  }
  *record.mutable_report() = ToProto(stored->report, id.Name(), true);
  record.set_yaml(stored->yaml_text);
  return record;
}

}  // namespace stevi::server
