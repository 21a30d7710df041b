// The georeferenced track points of TrackFrames, for the KML/GeoJSON exports (`stevi export` and
// `stevi station`).
#pragma once

#include <vector>

#include "client/advisory/export.h"
#include "stevi/v1/obstacle_service.pb.h"

namespace stevi::client {

// Appends the track points of one frame: its tracks that are not tentative and have a geodetic
// position.
void CollectTrackPoints(const v1::TrackFrame& frame, std::vector<TrackPoint>& points);

}  // namespace stevi::client
