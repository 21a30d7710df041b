// stevi's messages as Foxglove's well-known schemas, so that Foxglove and Lichtblick show a rig's
// previews, boxes, tracks in 3-D and the vehicle's fix with their own panels. Shared by the
// station (live, over the Foxglove WebSocket protocol) and the MCAP flight logs (files).
#pragma once

#include <string>

#include <google/protobuf/descriptor.h>

#include "foxglove/CompressedImage.pb.h"
#include "foxglove/ImageAnnotations.pb.h"
#include "foxglove/LocationFix.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::to_foxglove {

// A preview as a JPEG CompressedImage stamped with its capture's Unix time.
foxglove::CompressedImage ToCompressedImage(const v1::Preview& preview,
                                            const std::string& frame_id);

// Each track's box (a closed line, coloured by state), its id and range, in the pixels of an
// image `scale` times the size of the frame's image (Preview.scale of the image they go on).
foxglove::ImageAnnotations ToImageAnnotations(const v1::TrackFrame& frame, double scale);

// The tracks in the rectified left camera's frame (x right, y down, z forward), `frame_id`: a cube
// per track sized by its position's 2-sigma on each axis (at least 0.5 m), an arrow along its
// velocity (its length: one second's travel) and a text with id, range and time to collision.
// Every update replaces the last (a deletion of all entities first).
foxglove::SceneUpdate ToSceneUpdate(const v1::TrackFrame& frame, const std::string& frame_id);

// The vehicle's state of a georeferenced frame; false when the frame has none (geo_status not OK).
bool ToLocationFix(const v1::TrackFrame& frame, const std::string& frame_id,
                   foxglove::LocationFix& fix);
// A vehicle state (a recording's, an autopilot's) as a fix stamped with the state's time.
foxglove::LocationFix ToLocationFix(const v1::VehicleState& state, const std::string& frame_id);

// The file defining `descriptor` and every file it depends on, transitively, each before the
// files that import it, as a serialized google.protobuf.FileDescriptorSet: a protobuf channel's
// schema, in the Foxglove WebSocket protocol and in MCAP alike.
std::string FileDescriptorSetFor(const google::protobuf::Descriptor* descriptor);

}  // namespace stevi::to_foxglove
