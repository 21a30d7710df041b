// Every scene the synthetic source plays, by name, and where its rig is on Earth: the one place
// the server, stevi-process and the tools learn what "--scene NAME" means.
#pragma once

#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "core/geo/vehicle_state.h"
#include "drivers/synthetic/synthetic_source.h"

namespace stevi::drivers {

// The default scene (DefaultScene(): obstacles over an airfield) and the moving calibration board
// (ChessboardSource), which has no vehicle and no Scenario.
inline constexpr char kAirfieldScene[] = "airfield";
inline constexpr char kChessboardScene[] = "chessboard";

// Every name: airfield, flight, chessboard, then EvaluationScenarios() and TrackingScenarios().
std::vector<std::string> SceneNames();
// Whether `name` is one of SceneNames() (the empty name is the default, airfield).
bool IsKnownScene(std::string_view name);

// The scenario of a name: its rig, noise, seed and scene. "" and "airfield" give the default
// scene on the default rig; nullopt for "chessboard" and unknown names.
std::optional<Scenario> FindScenario(std::string_view name);

// The synthetic rig's pose: hovering over the threshold of runway 04R at Pisa airport
// (43.6839 N, 10.3925 E), its camera `camera_height_m` above the ground (the ground there is
// about 49.5 m above the WGS84 ellipsoid: 2 m above sea level plus a 47.5 m geoid undulation),
// level, heading 043 (the runway's).
geo::VehicleState SyntheticRigPose(double camera_height_m);

// The pose of a scene's rig at the start: SyntheticRigPose at its camera height; nullopt for the
// chessboard (no vehicle) and unknown names.
std::optional<geo::VehicleState> SceneRigPose(std::string_view name);

// A rig's pose after it moved `offset_m` (scene frame: x right, z forward, level) from `start` at
// `velocity_mps` (same frame): position and NED velocity turned by the heading.
geo::VehicleState MovedRigPose(const geo::VehicleState& start, const cv::Vec3d& offset_m,
                               const cv::Vec3d& velocity_mps);

// The flight of a scene whose rig moves (Scene::rig_velocity_mps, as "flight"), from `start`, as
// a function of the scene clock (a frame's t_ns); empty for a rig that does not move.
std::function<geo::VehicleState(int64_t t_ns)> SceneRigPath(std::string_view name,
                                                            const geo::VehicleState& start);

}  // namespace stevi::drivers
