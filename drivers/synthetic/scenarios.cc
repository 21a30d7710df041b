#include "drivers/synthetic/scenarios.h"

#include <cmath>
#include <numbers>

#include <GeographicLib/LocalCartesian.hpp>

namespace stevi::drivers {

std::vector<std::string> SceneNames() {
  std::vector<std::string> names = {kAirfieldScene, FlightScenario().name, kChessboardScene};
  for (const Scenario& s : EvaluationScenarios()) names.push_back(s.name);
  for (const Scenario& s : TrackingScenarios()) names.push_back(s.name);
  return names;
}

bool IsKnownScene(std::string_view name) {
  return name.empty() || name == kChessboardScene || FindScenario(name).has_value();
}

std::optional<Scenario> FindScenario(std::string_view name) {
  if (name.empty() || name == kAirfieldScene) {
    Scenario airfield;
    airfield.name = kAirfieldScene;
    airfield.description = "obstacles over an airfield (the default scene)";
    return airfield;
  }
  if (Scenario flight = FlightScenario(); flight.name == name) return flight;
  for (std::vector<Scenario> list : {EvaluationScenarios(), TrackingScenarios()}) {
    for (Scenario& s : list) {
      if (s.name == name) return std::move(s);
    }
  }
  return std::nullopt;
}

geo::VehicleState SyntheticRigPose(double camera_height_m) {
  geo::VehicleState s;
  s.lat_deg = 43.6839;
  s.lon_deg = 10.3925;
  s.alt_m = 49.5 + camera_height_m;
  s.yaw_deg = 43;
  return s;
}

std::optional<geo::VehicleState> SceneRigPose(std::string_view name) {
  const std::optional<Scenario> scenario = FindScenario(name);
  if (!scenario) return std::nullopt;
  return SyntheticRigPose(scenario->options.scene.camera_height_m);
}

geo::VehicleState MovedRigPose(const geo::VehicleState& start, const cv::Vec3d& offset_m,
                               const cv::Vec3d& velocity_mps) {
  const double yaw = start.yaw_deg * std::numbers::pi / 180.0;
  const auto to_ned = [&](const cv::Vec3d& v) {  // forward z, right x
    return Eigen::Vector3d(v[2] * std::cos(yaw) - v[0] * std::sin(yaw),
                           v[2] * std::sin(yaw) + v[0] * std::cos(yaw), v[1]);
  };
  const Eigen::Vector3d ned = to_ned(offset_m);
  const GeographicLib::LocalCartesian local(start.lat_deg, start.lon_deg, start.alt_m);
  geo::VehicleState moved = start;
  local.Reverse(ned.y(), ned.x(), -ned.z(), moved.lat_deg, moved.lon_deg, moved.alt_m);
  moved.velocity_ned_mps = to_ned(velocity_mps);
  return moved;
}

std::function<geo::VehicleState(int64_t t_ns)> SceneRigPath(std::string_view name,
                                                            const geo::VehicleState& start) {
  const std::optional<Scenario> scenario = FindScenario(name);
  if (!scenario || scenario->options.scene.rig_velocity_mps == cv::Vec3d(0, 0, 0)) return {};
  const Scene scene = scenario->options.scene;
  return [scene, start](int64_t t_ns) {
    return MovedRigPose(start, scene.RigOffsetAt(static_cast<double>(t_ns) * 1e-9),
                        scene.rig_velocity_mps);
  };
}

}  // namespace stevi::drivers
