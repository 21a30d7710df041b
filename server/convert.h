// The one conversion file between core types and the stevi.v1 protos.
#pragma once

#include <string>
#include <vector>

#include "core/pipeline/config.h"
#include "core/pipeline/pipeline.h"
#include "drivers/synthetic/synthetic_source.h"
#include "server/runtime/preview_hub.h"
#include "stevi/v1/config.pb.h"
#include "stevi/v1/obstacle_service.pb.h"
#include "stevi/v1/truth.pb.h"

namespace stevi::server {

// Every field of the core config, filled.
v1::PipelineConfig ToProto(const pipeline::PipelineConfig& config);

// Overlays the fields that are set in `update` onto `config`. Returns the problems that the proto
// itself carries (an enum value out of range, a negative count), each naming the field; `config`
// is then partly updated and must be discarded. Range checks are left to PipelineConfig::Validate.
// An update that selects ALGORITHM_STIXELS and names no matcher kind selects the dense matcher.
std::vector<std::string> MergeFromProto(const v1::PipelineConfig& update,
                                        pipeline::PipelineConfig& config);

v1::Algorithm ToProto(pipeline::Algorithm algorithm);

// The frame as it goes out to subscribers (detections as per-frame tracks until tracking lands).
v1::TrackFrame ToTrackFrame(const pipeline::FrameResult& result);

// Vehicle states between the wire (degrees, Unix time) and core/geo. FromProto does not validate:
// geo::VehicleState::Validate() (PoseBuffer::Add) names the bad fields.
geo::VehicleState FromProto(const v1::VehicleState& state);
v1::VehicleState ToProto(const geo::VehicleState& state);

// PNG images and the rig's geometry. Fails (kInternal) only when PNG encoding fails.
// With `annotated`, also the left image with the detections drawn on it.
Result<v1::DisparitySnapshot> ToSnapshot(const pipeline::FrameResult& result, bool annotated);

// StreamPreview's request with its defaults applied (0 = rate 5 Hz, width 640, quality 80),
// validated: kInvalidArgument naming every bad field ("kinds[1]: unknown kind 7").
Result<PreviewRequest> ToPreviewRequest(const v1::StreamPreviewRequest& request);
v1::PreviewKind ToProto(PreviewKind kind);
// dropped_previews is left 0: it is the subscriber's.
v1::Preview ToProto(const Preview& preview);

// The synthetic source's truth for one frame.
v1::TruthFrame ToTruthFrame(const drivers::FrameTruth& truth, int64_t capture_time_ns);

// One line of JSON with the proto field names (the format of every tool that prints tracks).
std::string ToJsonLine(const google::protobuf::Message& message);

void ToProto(const std::vector<pipeline::StageTiming>& timings,
             google::protobuf::RepeatedPtrField<v1::StageTiming>* out);

}  // namespace stevi::server
