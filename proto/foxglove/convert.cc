#include "proto/foxglove/convert.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <set>

#include <google/protobuf/descriptor.pb.h>

namespace stevi::to_foxglove {
namespace {

void SetTime(int64_t unix_time_ns, google::protobuf::Timestamp* t) {
  // Floor division, so that nanos stays in [0, 1e9) before 1970 too.
  int64_t seconds = unix_time_ns / 1'000'000'000;
  int64_t nanos = unix_time_ns % 1'000'000'000;
  if (nanos < 0) {
    nanos += 1'000'000'000;
    --seconds;
  }
  t->set_seconds(seconds);
  t->set_nanos(static_cast<int32_t>(nanos));
}

void SetColor(double r, double g, double b, double a, foxglove::Color* c) {
  c->set_r(r);
  c->set_g(g);
  c->set_b(b);
  c->set_a(a);
}

// Confirmed green, coasting amber, tentative grey: as the annotated preview draws them.
void StateColor(v1::TrackState state, foxglove::Color* c) {
  switch (state) {
    case v1::TRACK_STATE_CONFIRMED: SetColor(0.2, 0.9, 0.3, 1, c); return;
    case v1::TRACK_STATE_COASTING: SetColor(1.0, 0.7, 0.1, 1, c); return;
    default: SetColor(0.7, 0.7, 0.7, 1, c); return;
  }
}

std::string Label(const v1::Track& t) {
  char text[96];
  if (t.has_time_to_collision_s()) {
    std::snprintf(text, sizeof text, "#%llu %.1f m TTC %.1f s",
                  static_cast<unsigned long long>(t.track_id()), t.range_m(),
                  t.time_to_collision_s());
  } else {
    std::snprintf(text, sizeof text, "#%llu %.1f m", static_cast<unsigned long long>(t.track_id()),
                  t.range_m());
  }
  return text;
}

void SetVector(double x, double y, double z, foxglove::Vector3* v) {
  v->set_x(x);
  v->set_y(y);
  v->set_z(z);
}

// The rotation that takes +x onto the unit vector (x, y, z) (the shortest arc).
void RotationFromX(double x, double y, double z, foxglove::Quaternion* q) {
  // q = (1 + x, 0, -z, y) normalised: the half-way rotation about +x cross v.
  const double w = 1 + x;
  if (w < 1e-9) {  // v = -x: half a turn about z
    q->set_x(0);
    q->set_y(0);
    q->set_z(1);
    q->set_w(0);
    return;
  }
  const double n = std::sqrt(w * w + z * z + y * y);
  q->set_x(0);
  q->set_y(-z / n);
  q->set_z(y / n);
  q->set_w(w / n);
}

}  // namespace

foxglove::CompressedImage ToCompressedImage(const v1::Preview& preview,
                                            const std::string& frame_id) {
  foxglove::CompressedImage image;
  SetTime(preview.capture_unix_time_ns(), image.mutable_timestamp());
  image.set_data(preview.jpeg());
  image.set_format("jpeg");
  image.set_frame_id(frame_id);
  return image;
}

foxglove::ImageAnnotations ToImageAnnotations(const v1::TrackFrame& frame, double scale) {
  foxglove::ImageAnnotations out;
  for (const v1::Track& t : frame.tracks()) {
    const double x0 = t.bbox().x() * scale, y0 = t.bbox().y() * scale;
    const double x1 = (t.bbox().x() + t.bbox().width()) * scale;
    const double y1 = (t.bbox().y() + t.bbox().height()) * scale;
    foxglove::PointsAnnotation* box = out.add_points();
    SetTime(frame.capture_unix_time_ns(), box->mutable_timestamp());
    box->set_type(foxglove::PointsAnnotation::LINE_LOOP);
    for (const auto& [x, y] : {std::pair{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}) {
      foxglove::Point2* p = box->add_points();
      p->set_x(x);
      p->set_y(y);
    }
    StateColor(t.state(), box->mutable_outline_color());
    box->set_thickness(2);
    foxglove::TextAnnotation* text = out.add_texts();
    SetTime(frame.capture_unix_time_ns(), text->mutable_timestamp());
    text->mutable_position()->set_x(x0);
    text->mutable_position()->set_y(std::max(0.0, y0 - 4));
    text->set_text(Label(t));
    text->set_font_size(14);
    StateColor(t.state(), text->mutable_text_color());
    SetColor(0, 0, 0, 0.6, text->mutable_background_color());
  }
  return out;
}

foxglove::SceneUpdate ToSceneUpdate(const v1::TrackFrame& frame, const std::string& frame_id) {
  foxglove::SceneUpdate update;
  foxglove::SceneEntityDeletion* clear = update.add_deletions();
  SetTime(frame.capture_unix_time_ns(), clear->mutable_timestamp());
  clear->set_type(foxglove::SceneEntityDeletion::ALL);
  for (const v1::Track& t : frame.tracks()) {
    foxglove::SceneEntity* e = update.add_entities();
    SetTime(frame.capture_unix_time_ns(), e->mutable_timestamp());
    e->set_frame_id(frame_id);
    e->set_id("track-" + std::to_string(t.track_id()));
    const v1::PointCam& p = t.position_cam();
    const v1::PointCam& s = t.position_sigma_cam();
    foxglove::CubePrimitive* cube = e->add_cubes();
    SetVector(p.x_m(), p.y_m(), p.z_m(), cube->mutable_pose()->mutable_position());
    cube->mutable_pose()->mutable_orientation()->set_w(1);
    SetVector(std::max(0.5, 4 * s.x_m()), std::max(0.5, 4 * s.y_m()), std::max(0.5, 4 * s.z_m()),
              cube->mutable_size());
    StateColor(t.state(), cube->mutable_color());
    cube->mutable_color()->set_a(0.5);
    const v1::VelocityCam& v = t.velocity_cam();
    const double speed =
        std::sqrt(v.x_mps() * v.x_mps() + v.y_mps() * v.y_mps() + v.z_mps() * v.z_mps());
    if (speed > 0.05) {
      foxglove::ArrowPrimitive* arrow = e->add_arrows();
      SetVector(p.x_m(), p.y_m(), p.z_m(), arrow->mutable_pose()->mutable_position());
      RotationFromX(v.x_mps() / speed, v.y_mps() / speed, v.z_mps() / speed,
                    arrow->mutable_pose()->mutable_orientation());
      arrow->set_shaft_length(std::max(0.0, speed - 0.3));
      arrow->set_shaft_diameter(0.1);
      arrow->set_head_length(0.3);
      arrow->set_head_diameter(0.3);
      StateColor(t.state(), arrow->mutable_color());
    }
    foxglove::TextPrimitive* text = e->add_texts();
    SetVector(p.x_m(), p.y_m() - std::max(0.5, 2 * s.y_m()) - 0.3, p.z_m(),
              text->mutable_pose()->mutable_position());
    text->mutable_pose()->mutable_orientation()->set_w(1);
    text->set_billboard(true);
    text->set_font_size(14);
    text->set_scale_invariant(true);
    SetColor(1, 1, 1, 1, text->mutable_color());
    text->set_text(Label(t));
  }
  return update;
}

bool ToLocationFix(const v1::TrackFrame& frame, const std::string& frame_id,
                   foxglove::LocationFix& fix) {
  if (frame.geo_status() != v1::GEO_STATUS_OK || !frame.has_vehicle()) return false;
  fix = ToLocationFix(frame.vehicle(), frame_id);
  if (frame.vehicle().unix_time_ns() == 0)
    SetTime(frame.capture_unix_time_ns(), fix.mutable_timestamp());
  return true;
}

foxglove::LocationFix ToLocationFix(const v1::VehicleState& v, const std::string& frame_id) {
  foxglove::LocationFix fix;
  SetTime(v.unix_time_ns(), fix.mutable_timestamp());
  fix.set_frame_id(frame_id);
  fix.set_latitude(v.position().lat_deg());
  fix.set_longitude(v.position().lon_deg());
  fix.set_altitude(v.position().alt_m());
  const double h = v.position_sigma_horizontal_m(), z = v.position_sigma_vertical_m();
  if (h > 0 && z > 0) {
    // East, north, up variances on the diagonal (ENU, row-major 3x3).
    for (int i = 0; i < 9; ++i) fix.add_position_covariance(0);
    fix.set_position_covariance(0, h * h);
    fix.set_position_covariance(4, h * h);
    fix.set_position_covariance(8, z * z);
    fix.set_position_covariance_type(foxglove::LocationFix::DIAGONAL_KNOWN);
  }
  return fix;
}

std::string FileDescriptorSetFor(const google::protobuf::Descriptor* descriptor) {
  google::protobuf::FileDescriptorSet set;
  std::set<const google::protobuf::FileDescriptor*> seen;
  // Depth-first, each file after its dependencies.
  std::function<void(const google::protobuf::FileDescriptor*)> add =
      [&](const google::protobuf::FileDescriptor* file) {
        if (!seen.insert(file).second) return;
        for (int i = 0; i < file->dependency_count(); ++i) add(file->dependency(i));
        file->CopyTo(set.add_file());
      };
  add(descriptor->file());
  return set.SerializeAsString();
}

}  // namespace stevi::to_foxglove
