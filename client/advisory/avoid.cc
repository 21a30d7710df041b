#include "client/advisory/avoid.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <tuple>
#include <utility>

#include "client/advisory/text_out.h"

namespace stevi::client {
namespace {

std::string Got(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), " (got %g)", value);
  return buffer;
}

double Dot(const Ned& a, const Ned& b) { return a.n * b.n + a.e * b.e + a.d * b.d; }

Ned Minus(const Ned& a, const Ned& b) { return {a.n - b.n, a.e - b.e, a.d - b.d}; }

bool Finite(const Ned& a) { return std::isfinite(a.n) && std::isfinite(a.e) && std::isfinite(a.d); }

bool Finite(const Encounter& e) {
  return std::isfinite(e.bearing_deg) && std::isfinite(e.distance_m) && std::isfinite(e.t_cpa_s) &&
         std::isfinite(e.d_cpa_m) && std::isfinite(e.protected_radius_m);
}

AdvisoryLevel Classify(double distance_m, double t_cpa_s, double d_cpa_m, double radius_m,
                       const AvoidOptions& o) {
  if (d_cpa_m < radius_m && t_cpa_s <= o.avoid_time_s) return AdvisoryLevel::kAvoid;
  if (d_cpa_m < o.warning_radius_factor * radius_m && t_cpa_s <= o.warning_time_s) {
    return AdvisoryLevel::kWarning;
  }
  if ((d_cpa_m < o.caution_radius_factor * radius_m && t_cpa_s <= o.caution_time_s) ||
      distance_m < o.caution_range_m) {
    return AdvisoryLevel::kCaution;
  }
  return AdvisoryLevel::kClear;
}

// True when `a` is more urgent than `b`.
bool Worse(const Encounter& a, const Encounter& b) {
  if (a.level != b.level) return a.level > b.level;
  return std::tie(a.t_cpa_s, a.d_cpa_m, a.track_id) < std::tie(b.t_cpa_s, b.d_cpa_m, b.track_id);
}

Advisory NoData(std::int64_t t_ns, std::string reason) {
  Advisory a;
  a.t_ns = t_ns;
  a.level = AdvisoryLevel::kNoData;
  a.reason = std::move(reason);
  return a;
}

}  // namespace

std::string_view AdvisoryLevelName(AdvisoryLevel level) {
  switch (level) {
    case AdvisoryLevel::kNoData: return "NO_DATA";
    case AdvisoryLevel::kClear: return "CLEAR";
    case AdvisoryLevel::kCaution: return "CAUTION";
    case AdvisoryLevel::kWarning: return "WARNING";
    case AdvisoryLevel::kAvoid: return "AVOID";
  }
  return "NO_DATA";
}

std::vector<std::string> AvoidOptions::Validate() const {
  std::vector<std::string> problems;
  if (!(std::isfinite(protected_radius_m) && protected_radius_m > 0)) {
    problems.push_back("protected_radius_m: must be > 0 metres and finite" +
                       Got(protected_radius_m));
  }
  if (!(std::isfinite(sigma_factor) && sigma_factor >= 0)) {
    problems.push_back("sigma_factor: must be >= 0 and finite" + Got(sigma_factor));
  }
  if (!(std::isfinite(avoid_time_s) && avoid_time_s > 0)) {
    problems.push_back("avoid_time_s: must be > 0 seconds and finite" + Got(avoid_time_s));
  }
  if (!(std::isfinite(warning_time_s) && warning_time_s >= avoid_time_s)) {
    problems.push_back("warning_time_s: must be >= avoid_time_s and finite" + Got(warning_time_s));
  }
  if (!(std::isfinite(caution_time_s) && caution_time_s >= warning_time_s)) {
    problems.push_back("caution_time_s: must be >= warning_time_s and finite" +
                       Got(caution_time_s));
  }
  if (!(std::isfinite(warning_radius_factor) && warning_radius_factor >= 1)) {
    problems.push_back("warning_radius_factor: must be >= 1 and finite" +
                       Got(warning_radius_factor));
  }
  if (!(std::isfinite(caution_radius_factor) && caution_radius_factor >= warning_radius_factor)) {
    problems.push_back("caution_radius_factor: must be >= warning_radius_factor and finite" +
                       Got(caution_radius_factor));
  }
  if (!(std::isfinite(caution_range_m) && caution_range_m >= 0)) {
    problems.push_back("caution_range_m: must be >= 0 metres and finite" + Got(caution_range_m));
  }
  if (!(min_score >= 0 && min_score <= 1)) {
    problems.push_back("min_score: must be in [0, 1]" + Got(min_score));
  }
  return problems;
}

std::vector<std::string> AdvisorOptions::Validate() const {
  std::vector<std::string> problems;
  for (std::string& p : avoid.Validate()) problems.push_back("avoid." + std::move(p));
  if (no_data_after_ns <= 0) {
    problems.push_back("no_data_after_ns: must be > 0 nanoseconds" +
                       Got(static_cast<double>(no_data_after_ns)));
  }
  return problems;
}

bool ObstacleIsValid(const Obstacle& o) {
  return Finite(o.position_m) && Finite(o.velocity_mps) && std::isfinite(o.sigma_horizontal_m) &&
         std::isfinite(o.sigma_vertical_m) && o.sigma_horizontal_m >= 0 &&
         o.sigma_vertical_m >= 0 && std::isfinite(o.range_rate_sigma_mps) &&
         o.range_rate_sigma_mps >= 0;
}

Encounter Assess(const OwnVehicle& own, const Obstacle& obstacle, const AvoidOptions& options) {
  const Ned p = Minus(obstacle.position_m, own.position_m);
  const Ned v = Minus(obstacle.velocity_mps, own.velocity_mps);
  const double vv = Dot(v, v);
  double t = vv > 0 ? std::max(0.0, -Dot(p, v) / vv) : 0.0;
  // A relative speed so small that the quotient overflows: as good as no relative motion.
  if (!std::isfinite(t)) t = 0;
  const Ned at_cpa{p.n + v.n * t, p.e + v.e * t, p.d + v.d * t};

  Encounter e;
  e.track_id = obstacle.track_id;
  double bearing = std::atan2(p.e, p.n) * 180.0 / std::numbers::pi;
  if (bearing < 0) bearing += 360;
  if (bearing >= 360) bearing -= 360;  // -tiny + 360 rounds to 360
  e.bearing_deg = bearing;
  e.distance_m = std::sqrt(Dot(p, p));
  e.t_cpa_s = t;
  e.d_cpa_m = std::sqrt(Dot(at_cpa, at_cpa));
  e.protected_radius_m =
      options.protected_radius_m +
      options.sigma_factor * std::max(obstacle.sigma_horizontal_m, obstacle.sigma_vertical_m);
  // Speed towards the vehicle along the line of sight; it must stand out of the velocity noise.
  const double closing_speed = e.distance_m > 0 ? -Dot(p, v) / e.distance_m : 0.0;
  const bool established = obstacle.hits == 0 || obstacle.hits >= options.min_hits_to_extrapolate;
  const bool closing = established && vv > 0 && Dot(p, v) < 0 &&
                       closing_speed > options.sigma_factor * obstacle.range_rate_sigma_mps;
  if (!closing && e.distance_m >= e.protected_radius_m) {
    e.level =
        e.distance_m < options.caution_range_m ? AdvisoryLevel::kCaution : AdvisoryLevel::kClear;
  } else {
    e.level = Classify(e.distance_m, e.t_cpa_s, e.d_cpa_m, e.protected_radius_m, options);
  }
  return e;
}

Advisory AssessFrame(std::int64_t t_ns, const OwnVehicle& own,
                     const std::vector<Obstacle>& obstacles, const AvoidOptions& options) {
  if (!Finite(own.position_m) || !Finite(own.velocity_mps)) {
    return NoData(t_ns, "vehicle state not finite");
  }
  Advisory advisory;
  advisory.t_ns = t_ns;
  advisory.level = AdvisoryLevel::kClear;
  for (const Obstacle& obstacle : obstacles) {
    if (options.ignore_tentative && obstacle.state == ObstacleState::kTentative) continue;
    if (obstacle.score < options.min_score) continue;
    if (!ObstacleIsValid(obstacle)) {
      ++advisory.invalid_obstacles;
      continue;
    }
    const Encounter e = Assess(own, obstacle, options);
    if (!Finite(e)) {  // finite but huge inputs
      ++advisory.invalid_obstacles;
      continue;
    }
    if (e.level == AdvisoryLevel::kClear) continue;
    if (!advisory.worst || Worse(e, *advisory.worst)) advisory.worst = e;
  }
  if (advisory.worst) advisory.level = advisory.worst->level;
  return advisory;
}

Advisor::Advisor(AdvisorOptions options) : options_(std::move(options)) {
  if (std::vector<std::string> problems = options_.Validate(); !problems.empty()) {
    std::string message = "AdvisorOptions:";
    for (const std::string& p : problems) message.append(" ").append(p).append(";");
    throw std::invalid_argument(message);
  }
}

Advisory Advisor::OnFrame(std::int64_t now_ns, const OwnVehicle& own,
                          const std::vector<Obstacle>& obstacles) {
  last_ = AssessFrame(now_ns, own, obstacles, options_.avoid);
  last_frame_ns_ = now_ns;
  return last_;
}

Advisory Advisor::OnTick(std::int64_t now_ns) const {
  if (!last_frame_ns_) return NoData(now_ns, "no frame yet");
  if (now_ns < *last_frame_ns_) return NoData(now_ns, "clock before the last frame");
  const std::int64_t age_ns = now_ns - *last_frame_ns_;
  if (age_ns > options_.no_data_after_ns) {
    std::string reason = "no frame for ";
    text::AppendInt(reason, age_ns / 1'000'000);
    reason += " ms";
    return NoData(now_ns, std::move(reason));
  }
  return last_;
}

std::string AdvisoryJson(const Advisory& a) {
  std::string out = "{\"t_ns\":";
  text::AppendInt(out, a.t_ns);
  out += ",\"level\":";
  text::AppendJsonString(out, AdvisoryLevelName(a.level));
  if (a.worst) {
    const Encounter& e = *a.worst;
    out += ",\"track_id\":";
    text::AppendUint(out, e.track_id);
    // Rounded first so that 359.96 degrees is written as 0.0, not 360.0.
    double bearing = std::round(e.bearing_deg * 10) / 10;
    if (bearing >= 360) bearing -= 360;
    out += ",\"bearing_deg\":";
    text::AppendFixed(out, bearing, 1);
    out += ",\"distance_m\":";
    text::AppendFixed(out, e.distance_m, 2);
    out += ",\"t_cpa_s\":";
    text::AppendFixed(out, e.t_cpa_s, 2);
    out += ",\"d_cpa_m\":";
    text::AppendFixed(out, e.d_cpa_m, 2);
  }
  if (a.level == AdvisoryLevel::kNoData) {
    out += ",\"reason\":";
    text::AppendJsonString(out, a.reason);
  }
  if (a.invalid_obstacles > 0) {
    out += ",\"invalid_obstacles\":";
    text::AppendInt(out, a.invalid_obstacles);
  }
  out += '}';
  return out;
}

}  // namespace stevi::client
