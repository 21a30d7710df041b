// The ObstacleService: thin gRPC adapters over the engine. Each unary RPC's logic is a plain
// function of (engine, request, response), testable without a channel.
#pragma once

#include <map>
#include <memory>
#include <mutex>

#include <grpcpp/grpcpp.h>

#include "server/auth.h"
#include "server/runtime/broadcaster.h"
#include "server/runtime/engine.h"
#include "server/runtime/pose_source.h"
#include "server/runtime/preview_hub.h"
#include "server/recording_manager.h"
#include "stevi/v1/obstacle_service.grpc.pb.h"

namespace stevi::server {

using FramePtr = std::shared_ptr<const v1::TrackFrame>;
using FrameBroadcaster = Broadcaster<FramePtr>;

// StreamPreview subscribers at most: ServerConfig.max_streams, and never more than this (each
// holds up to two JPEGs per kind, and the encodings of distinct requests add up).
inline constexpr size_t kMaxPreviewStreams = 16;

// StreamTracks' request: INVALID_ARGUMENT naming the bad field (min_score outside [0, 1]).
grpc::Status ValidateStreamTracksRequest(const v1::StreamTracksRequest& request);
// Drops, in place and keeping the order, the tracks the request's filters exclude: TENTATIVE ones
// with confirmed_only, and those scoring below min_score.
void FilterTracks(const v1::StreamTracksRequest& request, v1::TrackFrame& frame);

// `recording` and `previews` may be null (no recorder, no preview hub).
grpc::Status GetStatusImpl(const Engine& engine, const FrameBroadcaster& broadcaster,
                           const RecordingManager* recording, const PreviewHub* previews,
                           v1::GetStatusResponse* response);
grpc::Status GetPipelineConfigImpl(Engine& engine, v1::PipelineConfig* response);
// Merges, validates, swaps in. Serialised by `mu` so that concurrent updates do not lose fields.
grpc::Status SetPipelineConfigImpl(Engine& engine, std::mutex& mu,
                                   const v1::SetPipelineConfigRequest& request,
                                   v1::PipelineConfig* response);
grpc::Status GetDisparitySnapshotImpl(const Engine& engine,
                                      const v1::GetDisparitySnapshotRequest& request,
                                      v1::DisparitySnapshot* response);

class VehicleStateReactor;

class ObstacleServiceImpl final : public v1::ObstacleService::CallbackService {
 public:
  ObstacleServiceImpl(Engine& engine, FrameBroadcaster& broadcaster, PreviewHub& previews,
                      PoseSource& poses, RecordingManager& recording, const Authorizer& auth)
      : engine_(engine),
        broadcaster_(broadcaster),
        previews_(previews),
        poses_(poses),
        recording_(recording),
        auth_(auth) {}

  grpc::ServerWriteReactor<v1::TrackFrame>* StreamTracks(
      grpc::CallbackServerContext* context, const v1::StreamTracksRequest* request) override;
  // Read access, as StreamTracks: no operator token.
  grpc::ServerWriteReactor<v1::Preview>* StreamPreview(
      grpc::CallbackServerContext* context, const v1::StreamPreviewRequest* request) override;
  grpc::ServerUnaryReactor* GetStatus(grpc::CallbackServerContext* context,
                                      const v1::GetStatusRequest* request,
                                      v1::GetStatusResponse* response) override;
  grpc::ServerUnaryReactor* GetPipelineConfig(grpc::CallbackServerContext* context,
                                              const v1::GetPipelineConfigRequest* request,
                                              v1::PipelineConfig* response) override;
  grpc::ServerUnaryReactor* SetPipelineConfig(grpc::CallbackServerContext* context,
                                              const v1::SetPipelineConfigRequest* request,
                                              v1::PipelineConfig* response) override;
  grpc::ServerUnaryReactor* GetDisparitySnapshot(grpc::CallbackServerContext* context,
                                                 const v1::GetDisparitySnapshotRequest* request,
                                                 v1::DisparitySnapshot* response) override;
  grpc::ServerReadReactor<v1::VehicleState>* PublishVehicleState(
      grpc::CallbackServerContext* context, v1::PublishVehicleStateResponse* response) override;
  grpc::ServerUnaryReactor* StartRecording(grpc::CallbackServerContext* context,
                                           const v1::StartRecordingRequest* request,
                                           v1::RecordingStatus* response) override;
  grpc::ServerUnaryReactor* StopRecording(grpc::CallbackServerContext* context,
                                          const v1::StopRecordingRequest* request,
                                          v1::RecordingStatus* response) override;

  // Ends the PublishVehicleState calls in progress with UNAVAILABLE "server shutting down", and
  // refuses new ones likewise; returns how many were ended. A client stream otherwise holds the
  // server's stop until gRPC's grace cancels it.
  size_t EndVehicleStreams();

 private:
  Engine& engine_;
  FrameBroadcaster& broadcaster_;
  PreviewHub& previews_;
  PoseSource& poses_;
  RecordingManager& recording_;
  const Authorizer& auth_;
  std::mutex config_mu_;
  std::mutex vehicle_mu_;
  bool vehicle_closed_ = false;
  std::map<const grpc::CallbackServerContext*, VehicleStateReactor*> vehicle_streams_;
};

}  // namespace stevi::server
