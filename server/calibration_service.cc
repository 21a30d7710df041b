#include "server/calibration_service.h"

#include <atomic>
#include <deque>
#include <memory>
#include <mutex>
#include <utility>

#include "server/grpc_status.h"
#include "server/tsan_handover.h"

namespace stevi::server {
namespace {

// Calibrate: reads the settings and the pairs, then calibrates on the manager's worker.
// Lifetime: deleted in OnDone(); the worker job finishes the call and touches nothing after.
class CalibrateReactor final : public grpc::ServerReadReactor<v1::CalibrationUpload> {
 public:
  CalibrateReactor(CalibrationManager& manager, v1::CalibrationReport* response)
      : manager_(manager), response_(response) {
    StartRead(&upload_);
    HandOver(this);  // not bound to its call until the handler returns it
  }

  void OnReadDone(bool ok) override {
    const CallbackScope scope(this);
    if (!ok) {  // the client has sent everything (or went away: then Finish is a no-op)
      Run();
      return;
    }
    if (upload_.has_settings()) {
      if (have_settings_) return Refuse("settings: sent twice; send them once, first");
      have_settings_ = true;
      settings_ = upload_.settings();
    } else if (upload_.has_pair()) {
      if (!have_settings_) return Refuse("the first message must carry the settings");
      v1::ImagePair& pair = *upload_.mutable_pair();
      bytes_ += static_cast<int64_t>(pair.left().size() + pair.right().size());
      if (static_cast<int>(pairs_.size()) >= kMaxCalibrationPairs) {
        return End(ToGrpcStatus(ResourceExhausted(
            "more than " + std::to_string(kMaxCalibrationPairs) + " pairs in one upload")));
      }
      if (bytes_ > kMaxCalibrationUploadBytes) {
        return End(ToGrpcStatus(ResourceExhausted("the upload exceeds 1 GiB of images in all")));
      }
      pairs_.push_back(calibration::ImagePair{std::move(*pair.mutable_left()),
                                              std::move(*pair.mutable_right()), pair.name()});
    } else {
      return Refuse("a message with neither settings nor a pair");
    }
    HandOver(this);
    StartRead(&upload_);
  }

  // The client cancelled or its deadline passed: the calibration job (queued or running) stores
  // and applies nothing.
  void OnCancel() override {
    const CallbackScope scope(this);
    cancelled_ = true;
  }

  void OnDone() override {
    TakeOver(this);
    CallEnded();
    delete this;
  }

 private:
  void End(const grpc::Status& status) {
    HandOver(this);
    Finish(status);
  }
  void Refuse(const std::string& why) { End(ToGrpcStatus(InvalidArgument(why))); }

  void Run() {
    if (!have_settings_) return Refuse("no settings were sent");
    const bool posted = manager_.Post([this] {
      Result<v1::CalibrationReport> report =
          manager_.Calibrate(settings_, pairs_, [this] { return cancelled_.load(); });
      pairs_.clear();
      if (report.ok()) *response_ = std::move(report).value();
      End(report.ok() ? grpc::Status::OK : ToGrpcStatus(report.error()));
    });
    if (!posted) End(ToGrpcStatus(Unavailable("server shutting down")));
  }

  CalibrationManager& manager_;
  v1::CalibrationReport* response_;
  v1::CalibrationUpload upload_;
  v1::CalibrationSettings settings_;
  bool have_settings_ = false;
  std::vector<calibration::ImagePair> pairs_;
  int64_t bytes_ = 0;
  std::atomic<bool> cancelled_{false};
};

// CaptureCalibration: the worker produces progress messages; this writes them one at a time.
// The state is shared with the worker job, which may outlive the reactor (a cancelled call).
class CaptureReactor final : public grpc::ServerWriteReactor<v1::CaptureProgress> {
 public:
  struct Shared {
    std::mutex mu;
    CaptureReactor* reactor = nullptr;  // null once OnDone ran
    std::deque<v1::CaptureProgress> queue;
    bool writing = false;
    bool cancelled = false;
    std::optional<grpc::Status> final_status;  // set by the worker when it is done
    bool finished = false;
  };

  explicit CaptureReactor(const grpc::Status& refusal) : shared_(std::make_shared<Shared>()) {
    shared_->finished = true;
    HandOver(this);
    Finish(refusal);
  }

  CaptureReactor(CalibrationManager& manager, v1::CaptureCalibrationRequest request)
      : shared_(std::make_shared<Shared>()) {
    shared_->reactor = this;
    std::shared_ptr<Shared> shared = shared_;
    const bool posted = manager.Post([&manager, shared, request = std::move(request)] {
      const Status status = manager.Capture(
          request, [shared](const v1::CaptureProgress& p) { Push(shared, p); },
          [shared] {
            std::lock_guard lock(shared->mu);
            return shared->cancelled;
          });
      std::lock_guard lock(shared->mu);
      shared->final_status = status.ok() ? grpc::Status::OK : ToGrpcStatus(status);
      MaybeFinishLocked(*shared);
    });
    if (!posted) {
      std::lock_guard lock(shared_->mu);
      shared_->final_status = ToGrpcStatus(Unavailable("server shutting down"));
      MaybeFinishLocked(*shared_);
    }
  }

  void OnWriteDone(bool ok) override {
    const CallbackScope scope(this);
    std::lock_guard lock(shared_->mu);
    shared_->writing = false;
    if (!ok) {
      shared_->cancelled = true;
      shared_->queue.clear();
      if (!shared_->finished) {
        shared_->finished = true;
        HandOver(this);
        Finish(ToGrpcStatus(Unavailable("stream write failed")));
      }
      return;
    }
    WriteNextLocked(*shared_);
  }

  void OnCancel() override {
    const CallbackScope scope(this);
    std::lock_guard lock(shared_->mu);
    shared_->cancelled = true;
  }

  void OnDone() override {
    TakeOver(this);
    {
      std::lock_guard lock(shared_->mu);
      shared_->reactor = nullptr;
      shared_->cancelled = true;
    }
    CallEnded();
    delete this;
  }

 private:
  static void Push(const std::shared_ptr<Shared>& shared, const v1::CaptureProgress& progress) {
    std::lock_guard lock(shared->mu);
    if (shared->reactor == nullptr || shared->finished) return;
    shared->queue.push_back(progress);
    WriteNextLocked(*shared);
  }

  static void WriteNextLocked(Shared& s) {
    if (s.reactor == nullptr || s.writing || s.finished) return;
    if (s.queue.empty()) {
      MaybeFinishLocked(s);
      return;
    }
    s.reactor->current_ = std::move(s.queue.front());
    s.queue.pop_front();
    s.writing = true;
    HandOver(s.reactor);
    s.reactor->StartWrite(&s.reactor->current_);
  }

  // Finishes once the worker is done and every message has been written.
  static void MaybeFinishLocked(Shared& s) {
    if (s.reactor == nullptr || s.finished || s.writing || !s.queue.empty() || !s.final_status) {
      return;
    }
    s.finished = true;
    HandOver(s.reactor);
    s.reactor->Finish(*s.final_status);
  }

  std::shared_ptr<Shared> shared_;
  v1::CaptureProgress current_;
};

}  // namespace

grpc::ServerReadReactor<v1::CalibrationUpload>* CalibrationServiceImpl::Calibrate(
    grpc::CallbackServerContext* context, v1::CalibrationReport* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "Calibrate"); !allowed.ok()) {
    return new RefusedReadReactor<v1::CalibrationUpload>(std::move(allowed));
  }
  return new CalibrateReactor(manager_, response);
}

grpc::ServerWriteReactor<v1::CaptureProgress>* CalibrationServiceImpl::CaptureCalibration(
    grpc::CallbackServerContext* context, const v1::CaptureCalibrationRequest* request) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "CaptureCalibration"); !allowed.ok()) {
    return new CaptureReactor(std::move(allowed));
  }
  if (Status valid = CalibrationManager::ValidateCapture(*request); !valid.ok()) {
    return new CaptureReactor(ToGrpcStatus(valid));
  }
  return new CaptureReactor(manager_, *request);
}

grpc::ServerUnaryReactor* CalibrationServiceImpl::ListCalibrations(
    grpc::CallbackServerContext* context, const v1::ListCalibrationsRequest* /*request*/,
    v1::ListCalibrationsResponse* response) {
  *response = manager_.List();
  return Reply(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* CalibrationServiceImpl::GetCalibration(
    grpc::CallbackServerContext* context, const v1::GetCalibrationRequest* request,
    v1::CalibrationRecord* response) {
  Result<v1::CalibrationRecord> record = manager_.Get(request->calibration_id());
  if (!record.ok()) return Reply(context, ToGrpcStatus(record.error()));
  *response = std::move(record).value();
  return Reply(context, grpc::Status::OK);
}

grpc::ServerUnaryReactor* CalibrationServiceImpl::ActivateCalibration(
    grpc::CallbackServerContext* context, const v1::ActivateCalibrationRequest* request,
    v1::CalibrationRecord* response) {
  if (grpc::Status allowed = auth_.CheckControl(*context, "ActivateCalibration"); !allowed.ok()) {
    return Reply(context, allowed);
  }
  // Building the rectification maps takes tens of milliseconds: acceptable on this thread.
  Result<v1::CalibrationRecord> record = manager_.Activate(request->calibration_id());
  if (!record.ok()) return Reply(context, ToGrpcStatus(record.error()));
  *response = std::move(record).value();
  return Reply(context, grpc::Status::OK);
}

}  // namespace stevi::server
