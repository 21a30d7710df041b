#include "client/mavlink/translate.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace stevi::client::mavlink {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kRadToDeg = 180.0 / kPi;
constexpr uint16_t kUnknown = std::numeric_limits<uint16_t>::max();
constexpr int64_t kMaxGeoidUndulationMm = 150'000;
// Above this, max_cm + 1 would read as UINT16_MAX (unknown).
constexpr uint16_t kLargestMaxCm = 65533;

// Azimuth folded into [0, 360).
double Wrap360(double deg) {
  double w = std::fmod(deg, 360.0);
  if (w < 0) w += 360.0;
  return w >= 360.0 ? 0.0 : w;
}

// The overlap (degrees) of [a0, a0 + aw) and [b0, b0 + bw) on the circle.
double CircularOverlap(double a0, double aw, double b0, double bw) {
  double total = 0;
  // b shifted by whole turns so that each copy near a is counted once.
  for (const double shift : {-360.0, 0.0, 360.0}) {
    const double lo = std::max(a0, b0 + shift);
    const double hi = std::min(a0 + aw, b0 + shift + bw);
    if (hi > lo) total += hi - lo;
  }
  return total;
}

bool IsHeld(const v1::Track& t) {
  return t.state() == v1::TRACK_STATE_CONFIRMED || t.state() == v1::TRACK_STATE_COASTING;
}

// A range in centimetres within the limits: nearer than min_cm is min_cm (never 0).
uint16_t ClampedCm(double range_m, const SectorLimits& limits) {
  const double cm = std::round(range_m * 100.0);
  if (!(cm >= limits.min_cm)) return std::max<uint16_t>(limits.min_cm, 1);
  return static_cast<uint16_t>(std::min<double>(cm, limits.max_cm));
}

// Each sector from the range scan: the nearest return of the bins whose centre lies in it, else
// clear when the scan covers at least half of it, else unknown. A bin goes to the sector of its
// centre, not to every sector it touches: a bin straddling an edge would otherwise put an obstacle
// in the next sector too. (The scan's bins are centred on multiples of their width, so 1-degree
// bins nest in the 5-degree sectors; a centre on an edge goes to both, to be safe.)
void FillFromScan(const v1::RangeScan& scan, const SectorLimits& limits,
                  std::array<uint16_t, 72>& distances) {
  const double width = scan.bin_width_deg();
  std::array<double, kSectors> covered{};
  std::array<std::optional<double>, kSectors> nearest{};
  for (int b = 0; b < scan.range_m_size(); ++b) {
    const double lo = scan.start_azimuth_deg() + b * width;
    for (int s = 0; s < kSectors; ++s) {
      covered[static_cast<size_t>(s)] +=
          CircularOverlap(Wrap360(s * kSectorDeg - kSectorDeg / 2), kSectorDeg, Wrap360(lo), width);
    }
    const double r = scan.range_m(b);
    if (!(r > 0) || !std::isfinite(r)) continue;
    // The sectors holding the bin's centre (two when it lies on their shared edge).
    const double centre = Wrap360(lo + width / 2) / kSectorDeg;
    for (const double edge_side : {-1e-9, 1e-9}) {
      const auto s = static_cast<size_t>(std::lround(centre + edge_side) % kSectors);
      if (!nearest[s] || r < *nearest[s]) nearest[s] = r;
    }
  }
  for (size_t s = 0; s < kSectors; ++s) {
    if (nearest[s] && std::round(*nearest[s] * 100.0) <= limits.max_cm) {
      distances[s] = ClampedCm(*nearest[s], limits);
    } else if (covered[s] >= kSectorDeg / 2) {
      distances[s] = static_cast<uint16_t>(limits.max_cm + 1);
    } else {
      distances[s] = kUnknown;
    }
  }
}

}  // namespace

double BodyBearingDeg(const v1::PointBody& p) {
  return Wrap360(std::atan2(p.y_m(), p.x_m()) * kRadToDeg);
}

double BodyHorizontalRangeM(const v1::PointBody& p) { return std::hypot(p.x_m(), p.y_m()); }

int SectorOf(double bearing_deg) {
  const int s = static_cast<int>(std::lround(Wrap360(bearing_deg) / kSectorDeg));
  return s % kSectors;
}

SectorLimits LimitsOf(const v1::RangeScan& scan) {
  SectorLimits limits;
  const double min_cm = std::ceil(std::max(0.0, scan.min_range_m()) * 100.0);
  const double max_cm = std::floor(std::max(0.0, scan.max_range_m()) * 100.0);
  limits.max_cm =
      static_cast<uint16_t>(std::clamp(max_cm, 1.0, static_cast<double>(kLargestMaxCm)));
  limits.min_cm =
      static_cast<uint16_t>(std::clamp(min_cm, 1.0, static_cast<double>(limits.max_cm)));
  return limits;
}

std::optional<ObstacleDistance> ObstacleDistanceOf(const v1::TrackFrame& frame, std::string& why) {
  if (!frame.has_range_scan() || frame.range_scan().range_m_size() == 0 ||
      !(frame.range_scan().bin_width_deg() > 0)) {
    why = "the frames carry no range scan (PipelineConfig.range_scan.enabled is false)";
    return std::nullopt;
  }
  const v1::RangeScan& scan = frame.range_scan();
  const SectorLimits limits = LimitsOf(scan);
  ObstacleDistance m;
  m.time_usec = static_cast<uint64_t>(std::max<int64_t>(0, frame.capture_unix_time_ns() / 1000));
  m.sensor_type = kMavDistanceSensorUnknown;  // MAVLink has no stereo camera type
  m.min_distance = limits.min_cm;
  m.max_distance = limits.max_cm;
  m.increment = static_cast<uint8_t>(kSectorDeg);
  m.increment_f = static_cast<float>(kSectorDeg);
  m.angle_offset = 0;
  m.frame = kMavFrameBodyFrd;
  FillFromScan(scan, limits, m.distances);
  for (const v1::Track& t : frame.tracks()) {
    if (!IsHeld(t) || !t.has_position_body()) continue;
    const double range = BodyHorizontalRangeM(t.position_body());
    if (!std::isfinite(range) || std::round(range * 100.0) > limits.max_cm) continue;
    uint16_t& d = m.distances[static_cast<size_t>(SectorOf(BodyBearingDeg(t.position_body())))];
    const uint16_t cm = ClampedCm(range, limits);
    if (d == kUnknown || d > limits.max_cm || cm < d) d = cm;
  }
  why.clear();
  return m;
}

std::array<char, 9> CallsignOf(uint64_t track_id) {
  constexpr char kDigits[] = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ";
  std::array<char, 9> callsign{'S', 'T', 'V', '0', '0', '0', '0', '0', '\0'};
  uint64_t n = track_id % (36ULL * 36 * 36 * 36 * 36);
  for (int i = 7; i >= 3; --i) {
    callsign[static_cast<size_t>(i)] = kDigits[n % 36];
    n /= 36;
  }
  return callsign;
}

uint32_t IcaoAddressOf(uint64_t track_id, uint32_t icao_base) {
  return (icao_base + static_cast<uint32_t>(track_id % (1U << 20))) & 0xFFFFFFU;
}

std::vector<AdsbVehicle> AdsbTracks::Of(const v1::TrackFrame& frame) {
  std::vector<AdsbVehicle> out;
  std::unordered_map<uint64_t, int64_t> seen;
  if (frame.geo_status() != v1::GEO_STATUS_OK) {
    last_detected_ns_.clear();
    return out;
  }
  for (const v1::Track& t : frame.tracks()) {
    if (!IsHeld(t) || !t.has_geodetic()) continue;
    int64_t detected_ns = frame.capture_time_ns();
    if (t.state() == v1::TRACK_STATE_COASTING) {
      const auto it = last_detected_ns_.find(t.track_id());
      if (it != last_detected_ns_.end()) detected_ns = it->second;
    }
    seen[t.track_id()] = detected_ns;
    AdsbVehicle a;
    a.icao_address = IcaoAddressOf(t.track_id(), options_.icao_base);
    a.lat = static_cast<int32_t>(std::lround(t.geodetic().lat_deg() * 1e7));
    a.lon = static_cast<int32_t>(std::lround(t.geodetic().lon_deg() * 1e7));
    a.altitude_type = kAdsbAltitudeTypeGeometric;
    a.flags = kAdsbFlagsValidCoords | kAdsbFlagsValidVelocity | kAdsbFlagsValidCallsign |
              kAdsbFlagsVerticalVelocityValid;
    if (options_.geoid_undulation_m) {
      const double msl_mm = (t.geodetic().alt_m() - *options_.geoid_undulation_m) * 1000.0;
      a.altitude = static_cast<int32_t>(std::lround(std::clamp(msl_mm, -2e9, 2e9)));
      a.flags |= kAdsbFlagsValidAltitude;
    }
    const v1::VelocityNed& v = t.velocity_ned();
    const double speed = std::hypot(v.n_mps(), v.e_mps());
    a.hor_velocity = static_cast<uint16_t>(std::lround(std::clamp(speed * 100.0, 0.0, 65535.0)));
    a.ver_velocity =
        static_cast<int16_t>(std::lround(std::clamp(-v.d_mps() * 100.0, -32768.0, 32767.0)));
    // A course only when the track moves: below 0.5 m/s its direction is noise.
    if (speed >= 0.5) {
      a.heading = static_cast<uint16_t>(
          std::lround(Wrap360(std::atan2(v.e_mps(), v.n_mps()) * kRadToDeg) * 100.0) % 36000);
      a.flags |= kAdsbFlagsValidHeading;
    }
    a.callsign = CallsignOf(t.track_id());
    a.emitter_type = kAdsbEmitterTypeNoInfo;  // class-agnostic: stevi does not know what it is
    const double since_s = static_cast<double>(frame.capture_time_ns() - detected_ns) * 1e-9;
    a.tslc = static_cast<uint8_t>(std::clamp(std::floor(since_s), 0.0, 255.0));
    if (options_.simulated) a.flags |= kAdsbFlagsSimulated;
    out.push_back(a);
  }
  last_detected_ns_ = std::move(seen);
  return out;
}

std::array<double, 3> EulerDegOfQuaternion(double w, double x, double y, double z) {
  const double roll = std::atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y));
  const double pitch = std::asin(std::clamp(2 * (w * y - z * x), -1.0, 1.0));
  const double yaw = std::atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
  return {roll * kRadToDeg, pitch * kRadToDeg, yaw * kRadToDeg};
}

bool IsAutopilotHeartbeat(const Heartbeat& heartbeat) {
  constexpr uint8_t kMavTypeGcs = 6;
  return heartbeat.autopilot != kMavAutopilotInvalid && heartbeat.type != kMavTypeGcs &&
         heartbeat.type != kMavTypeOnboardController;
}

CommandLong SetMessageInterval(uint8_t target_system, uint8_t target_component, uint32_t message_id,
                               int32_t interval_us) {
  CommandLong c;
  c.target_system = target_system;
  c.target_component = target_component;
  c.command = kMavCmdSetMessageInterval;
  c.param1 = static_cast<float>(message_id);
  c.param2 = static_cast<float>(interval_us);
  return c;
}

std::optional<double> PoseJoiner::geoid_undulation_m() const {
  if (gps_ && gps_->alt_ellipsoid != 0 && gps_->fix_type >= kGpsFixType3dFix) {
    // In 64 bits: two hostile 32-bit heights differ by more than an int holds. The geoid lies
    // within about -107..+86 m of the ellipsoid everywhere (EGM2008); a farther one is a bad
    // message, and the configured undulation stands.
    const int64_t n_mm = static_cast<int64_t>(gps_->alt_ellipsoid) - gps_->alt;
    if (std::abs(n_mm) <= kMaxGeoidUndulationMm) return static_cast<double>(n_mm) / 1000.0;
  }
  return options_.geoid_undulation_m;
}

std::optional<v1::VehicleState> PoseJoiner::OnMessage(const Frame& frame, int64_t host_unix_ns) {
  if (const std::optional<mavlink::Attitude> a = Decode<mavlink::Attitude>(frame)) {
    TakeAttitude({a->roll * kRadToDeg, a->pitch * kRadToDeg, a->yaw * kRadToDeg}, a->time_boot_ms,
                 host_unix_ns, "ATTITUDE");
  } else if (const std::optional<AttitudeQuaternion> q = Decode<AttitudeQuaternion>(frame)) {
    TakeAttitude(EulerDegOfQuaternion(q->q1, q->q2, q->q3, q->q4), q->time_boot_ms, host_unix_ns,
                 "ATTITUDE_QUATERNION");
  } else if (const std::optional<GpsRawInt> g = Decode<GpsRawInt>(frame)) {
    gps_ = *g;
  } else if (const std::optional<SystemTime> t = Decode<SystemTime>(frame)) {
    // 0 until the autopilot knows the time (from GNSS); anything before 2020 is not a Unix time,
    // and anything from 2100 on is a bad message (it would also overflow the nanoseconds).
    constexpr uint64_t k2020Us = 1577836800ULL * 1000000ULL;
    constexpr uint64_t k2100Us = 4102444800ULL * 1000000ULL;
    if (t->time_unix_usec >= k2020Us && t->time_unix_usec < k2100Us) {
      boot_to_unix_us_ =
          static_cast<int64_t>(t->time_unix_usec) - static_cast<int64_t>(t->time_boot_ms) * 1000;
    }
  } else if (const std::optional<GlobalPositionInt> p = Decode<GlobalPositionInt>(frame)) {
    return OnPosition(*p, host_unix_ns);
  }
  return std::nullopt;
}

void PoseJoiner::TakeAttitude(const std::array<double, 3>& roll_pitch_yaw_deg,
                              uint32_t time_boot_ms, int64_t host_unix_ns, const char* message) {
  for (const double angle : roll_pitch_yaw_deg) {
    if (!std::isfinite(angle)) {
      // The last good attitude stays; it ages out if no good one follows.
      rejected_ = std::string(message) + " with a non-finite angle: ignored";
      return;
    }
  }
  attitude_ = Attitude{roll_pitch_yaw_deg[0], roll_pitch_yaw_deg[1], roll_pitch_yaw_deg[2],
                       time_boot_ms, host_unix_ns};
}

std::optional<v1::VehicleState> PoseJoiner::OnPosition(const GlobalPositionInt& m,
                                                       int64_t host_unix_ns) {
  last_position_ns_ = host_unix_ns;
  if (m.lat == 0 && m.lon == 0) {
    waiting_ = "no position fix (GLOBAL_POSITION_INT at 0, 0)";
    return std::nullopt;
  }
  if (std::abs(static_cast<int64_t>(m.lat)) > 900'000'000 ||
      std::abs(static_cast<int64_t>(m.lon)) > 1'800'000'000) {
    rejected_ = "GLOBAL_POSITION_INT outside the Earth (lat " + std::to_string(m.lat) + ", lon " +
                std::to_string(m.lon) + " in 1e-7 degrees): ignored";
    return std::nullopt;
  }
  // The attitude's age on the autopilot's clock when both carry it, else on arrival.
  const bool boot_times = m.time_boot_ms != 0 && attitude_ && attitude_->time_boot_ms != 0;
  const int64_t attitude_age_ms =
      !attitude_   ? std::numeric_limits<int64_t>::max()
      : boot_times ? std::abs(static_cast<int64_t>(m.time_boot_ms) - attitude_->time_boot_ms)
                   : std::abs(host_unix_ns - attitude_->host_unix_ns) / 1'000'000;
  if (attitude_age_ms > options_.max_attitude_age_ms) {
    waiting_ = "no attitude (ATTITUDE or ATTITUDE_QUATERNION) within " +
               std::to_string(options_.max_attitude_age_ms) + " ms of the position";
    return std::nullopt;
  }
  const std::optional<double> undulation = geoid_undulation_m();
  if (!undulation) {
    waiting_ =
        "no ellipsoid height: the autopilot's GPS_RAW_INT has no alt_ellipsoid (or no 3D fix); "
        "give --geoid-undulation";
    return std::nullopt;
  }
  v1::VehicleState s;
  s.set_unix_time_ns(boot_to_unix_us_ && m.time_boot_ms != 0
                         ? (*boot_to_unix_us_ + static_cast<int64_t>(m.time_boot_ms) * 1000) * 1000
                         : host_unix_ns);
  s.mutable_position()->set_lat_deg(m.lat * 1e-7);
  s.mutable_position()->set_lon_deg(m.lon * 1e-7);
  s.mutable_position()->set_alt_m(m.alt / 1000.0 + *undulation);
  s.set_roll_deg(attitude_->roll_deg);
  s.set_pitch_deg(attitude_->pitch_deg);
  s.set_yaw_deg(attitude_->yaw_deg);
  s.mutable_velocity()->set_n_mps(m.vx / 100.0);
  s.mutable_velocity()->set_e_mps(m.vy / 100.0);
  s.mutable_velocity()->set_d_mps(m.vz / 100.0);
  const bool accuracies = gps_ && gps_->h_acc > 0 && gps_->v_acc > 0;
  s.set_position_sigma_horizontal_m(accuracies ? gps_->h_acc / 1000.0
                                               : options_.default_sigma_horizontal_m);
  s.set_position_sigma_vertical_m(accuracies ? gps_->v_acc / 1000.0
                                             : options_.default_sigma_vertical_m);
  s.set_tilt_sigma_deg(options_.sigma_tilt_deg);
  s.set_yaw_sigma_deg(options_.sigma_yaw_deg);
  waiting_.clear();
  return s;
}

}  // namespace stevi::client::mavlink
