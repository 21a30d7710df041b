// stevi.v1.CalibrationService: thin gRPC reactors over the CalibrationManager. The long work
// (calibrating, capturing) runs on the manager's worker thread, never on a gRPC thread.
#pragma once

#include <grpcpp/grpcpp.h>

#include "server/auth.h"
#include "server/calibration_manager.h"
#include "stevi/v1/calibration_service.grpc.pb.h"

namespace stevi::server {

class CalibrationServiceImpl final : public v1::CalibrationService::CallbackService {
 public:
  CalibrationServiceImpl(CalibrationManager& manager, const Authorizer& auth)
      : manager_(manager), auth_(auth) {}

  grpc::ServerReadReactor<v1::CalibrationUpload>* Calibrate(
      grpc::CallbackServerContext* context, v1::CalibrationReport* response) override;
  grpc::ServerWriteReactor<v1::CaptureProgress>* CaptureCalibration(
      grpc::CallbackServerContext* context, const v1::CaptureCalibrationRequest* request) override;
  grpc::ServerUnaryReactor* ListCalibrations(grpc::CallbackServerContext* context,
                                             const v1::ListCalibrationsRequest* request,
                                             v1::ListCalibrationsResponse* response) override;
  grpc::ServerUnaryReactor* GetCalibration(grpc::CallbackServerContext* context,
                                           const v1::GetCalibrationRequest* request,
                                           v1::CalibrationRecord* response) override;
  grpc::ServerUnaryReactor* ActivateCalibration(grpc::CallbackServerContext* context,
                                                const v1::ActivateCalibrationRequest* request,
                                                v1::CalibrationRecord* response) override;

 private:
  CalibrationManager& manager_;
  const Authorizer& auth_;
};

}  // namespace stevi::server
