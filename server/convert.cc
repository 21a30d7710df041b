#include "server/convert.h"

#include "drivers/recording/recording_reader.h"

#include <cctype>

#include <google/protobuf/util/json_util.h>

#include <opencv2/imgcodecs.hpp>

#include "core/pipeline/annotate.h"
#include "server/field_mapping.h"

namespace stevi::server {

v1::Algorithm ToProto(pipeline::Algorithm algorithm) {
  std::string name = "ALGORITHM_";
  for (char c : pipeline::AlgorithmName(algorithm)) name += static_cast<char>(std::toupper(c));
  v1::Algorithm out = v1::ALGORITHM_UNSPECIFIED;
  v1::Algorithm_Parse(name, &out);
  return out;
}

v1::PipelineConfig ToProto(const pipeline::PipelineConfig& config) {
  v1::PipelineConfig p;
  FieldsToProto(config, p);
  return p;
}

std::vector<std::string> MergeFromProto(const v1::PipelineConfig& update,
                                        pipeline::PipelineConfig& config) {
  std::vector<std::string> problems = FieldsFromProto(update, config);
  // The stixel world comes with its own matcher: an update that selects it and names no matcher
  // kind gets the dense one (pipeline::ConfigForAlgorithm).
  if (update.algorithm() == v1::ALGORITHM_STIXELS &&
      update.matcher().kind() == v1::MATCHER_KIND_UNSPECIFIED) {
    config.matcher.kind = pipeline::ConfigForAlgorithm(pipeline::Algorithm::kStixels).matcher.kind;
  }
  return problems;
}

void ToProto(const std::vector<pipeline::StageTiming>& timings,
             google::protobuf::RepeatedPtrField<v1::StageTiming>* out) {
  out->Clear();
  for (const pipeline::StageTiming& t : timings) {
    v1::StageTiming* pt = out->Add();
    pt->set_stage(t.stage);
    pt->set_ms(t.ms);
  }
}

namespace {
void SetBox(const cv::Rect& r, v1::BoundingBox* box) {
  box->set_x(r.x);
  box->set_y(r.y);
  box->set_width(r.width);
  box->set_height(r.height);
}
// A 3-D point into a PointCam or PointBody (both x_m, y_m, z_m).
template <class Point>
void SetPoint(const cv::Vec3d& p, Point* point) {
  point->set_x_m(p[0]);
  point->set_y_m(p[1]);
  point->set_z_m(p[2]);
}
void SetScan(const detection::RangeScan& scan, v1::RangeScan* out) {
  out->set_start_azimuth_deg(scan.start_azimuth_deg);
  out->set_bin_width_deg(scan.bin_width_deg);
  out->mutable_range_m()->Assign(scan.range_m.begin(), scan.range_m.end());
  out->set_min_range_m(scan.min_range_m);
  out->set_max_range_m(scan.max_range_m);
}
}  // namespace

v1::TruthFrame ToTruthFrame(const drivers::FrameTruth& truth, int64_t capture_time_ns) {
  v1::TruthFrame f;
  f.set_source_index(truth.index);
  f.set_capture_time_ns(capture_time_ns);
  for (const drivers::ObstacleTruth& o : truth.obstacles) {
    v1::TruthObstacle* t = f.add_obstacles();
    t->set_id(o.id);
    t->set_name(o.name);
    if (o.visible_px > 0) SetBox(o.bbox, t->mutable_bbox());
    t->set_visible_px(o.visible_px);
    SetPoint(o.position_cam_m, t->mutable_position_cam());
    t->set_depth_m(o.depth_m);
    t->set_range_m(o.range_m);
  }
  return f;
}

std::string ToJsonLine(const google::protobuf::Message& message) {
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  options.always_print_primitive_fields = true;
  std::string out;
  if (!google::protobuf::util::MessageToJsonString(message, &out, options).ok()) return "{}";
  return out;
}

v1::TrackState ToProto(tracking::TrackState state) {
  switch (state) {
    case tracking::TrackState::kTentative: return v1::TRACK_STATE_TENTATIVE;
    case tracking::TrackState::kConfirmed: return v1::TRACK_STATE_CONFIRMED;
    case tracking::TrackState::kCoasting: return v1::TRACK_STATE_COASTING;
  }
  return v1::TRACK_STATE_UNSPECIFIED;
}

// One conversion for the wire and the recording format (drivers/recording).
geo::VehicleState FromProto(const v1::VehicleState& p) { return drivers::VehicleStateFromProto(p); }

v1::VehicleState ToProto(const geo::VehicleState& s) { return drivers::VehicleStateToProto(s); }

v1::GeoStatus ToProto(geo::GeoStatus status) {
  switch (status) {
    case geo::GeoStatus::kOk: return v1::GEO_STATUS_OK;
    case geo::GeoStatus::kNoPose: return v1::GEO_STATUS_NO_POSE;
    case geo::GeoStatus::kPoseTooOld: return v1::GEO_STATUS_POSE_TOO_OLD;
    case geo::GeoStatus::kFrameTooOld: return v1::GEO_STATUS_FRAME_TOO_OLD;
    case geo::GeoStatus::kPoseGap: return v1::GEO_STATUS_POSE_GAP;
  }
  return v1::GEO_STATUS_UNSPECIFIED;
}

v1::TrackFrame ToTrackFrame(const pipeline::FrameResult& result) {
  v1::TrackFrame f;
  f.set_frame_id(result.frame_id);
  f.set_capture_time_ns(result.capture_time_ns);
  f.set_capture_unix_time_ns(result.capture_unix_time_ns);
  f.set_source_index(result.source_index);
  f.set_pair_skew_ns(result.pair_skew_ns);
  f.set_algorithm(ToProto(result.algorithm));
  if (result.rig) {
    f.set_calibration_id(result.rig->calibration_id());
    f.set_image_width(result.rig->image_size().width);
    f.set_image_height(result.rig->image_size().height);
  }
  f.set_binning(result.binning);
  ToProto(result.timings, f.mutable_timings());
  for (size_t i = 0; i < result.tracks.size(); ++i) {
    const tracking::Track& track = result.tracks[i];
    const detection::Detection& d = track.detection;
    v1::Track* t = f.add_tracks();
    t->set_track_id(track.id);
    SetBox(d.bbox, t->mutable_bbox());
    if (track.state == tracking::TrackState::kCoasting) {
      // Not detected this frame: depth and range are the prediction's.
      t->set_depth_m(track.position_cam_m[2]);
      t->set_range_m(cv::norm(track.position_cam_m));
    } else {
      t->set_depth_m(d.depth_m);
      t->set_range_m(d.range_m);
    }
    t->set_range_sigma_m(d.range_sigma_m);
    t->set_valid_fraction(d.valid_fraction);
    t->set_disparity_sigma_px(d.disparity_sigma_px);
    SetPoint(track.position_cam_m, t->mutable_position_cam());
    if (i < result.track_position_body_m.size()) {
      SetPoint(result.track_position_body_m[i], t->mutable_position_body());
    }
    t->set_disparity_px(d.disparity_px);
    t->set_score(d.score);
    t->set_extractor(d.extractor);
    t->set_area_px(d.area_px);
    t->set_state(ToProto(track.state));
    t->set_age_frames(static_cast<uint32_t>(std::max(track.age_frames, 0)));
    t->set_hits(static_cast<uint32_t>(std::max(track.hits, 0)));
    t->set_misses(static_cast<uint32_t>(std::max(track.misses, 0)));
    v1::VelocityCam* v = t->mutable_velocity_cam();
    v->set_x_mps(track.velocity_cam_mps[0]);
    v->set_y_mps(track.velocity_cam_mps[1]);
    v->set_z_mps(track.velocity_cam_mps[2]);
    t->set_range_rate_mps(track.range_rate_mps);
    t->set_range_rate_sigma_mps(track.range_rate_sigma_mps);
    v1::VelocityCam* vs = t->mutable_velocity_sigma_cam();
    vs->set_x_mps(track.velocity_sigma_mps[0]);
    vs->set_y_mps(track.velocity_sigma_mps[1]);
    vs->set_z_mps(track.velocity_sigma_mps[2]);
    if (track.time_to_collision_s) t->set_time_to_collision_s(*track.time_to_collision_s);
    if (track.closest_approach_m) t->set_closest_approach_m(*track.closest_approach_m);
    t->set_smoothed_range_m(track.smoothed_range_m);
    SetPoint(track.position_sigma_m, t->mutable_position_sigma_cam());
    if (i < result.track_geo.size() && result.track_geo[i]) {
      const geo::GeoPoint& g = *result.track_geo[i];
      t->mutable_geodetic()->set_lat_deg(g.lat_deg);
      t->mutable_geodetic()->set_lon_deg(g.lon_deg);
      t->mutable_geodetic()->set_alt_m(g.alt_m);
      t->mutable_velocity_ned()->set_n_mps(g.velocity_ned_mps.x());
      t->mutable_velocity_ned()->set_e_mps(g.velocity_ned_mps.y());
      t->mutable_velocity_ned()->set_d_mps(g.velocity_ned_mps.z());
      t->mutable_position_sigma_m()->set_horizontal_m(g.sigma.horizontal_m);
      t->mutable_position_sigma_m()->set_vertical_m(g.sigma.vertical_m);
    }
  }
  if (result.range_scan) SetScan(*result.range_scan, f.mutable_range_scan());
  if (result.pose) {
    f.set_geo_status(ToProto(result.pose->status));
    f.set_geo_message(result.pose->message);
    if (result.pose->pose) *f.mutable_vehicle() = ToProto(result.pose->pose->state);
  }
  return f;
}

Result<PreviewRequest> ToPreviewRequest(const v1::StreamPreviewRequest& request) {
  PreviewRequest out;
  std::vector<std::string> problems;
  for (int i = 0; i < request.kinds_size(); ++i) {
    const std::string field = "kinds[" + std::to_string(i) + "]";
    switch (request.kinds(i)) {
      case v1::PREVIEW_KIND_ANNOTATED_LEFT: out.kinds.push_back(PreviewKind::kAnnotatedLeft); break;
      case v1::PREVIEW_KIND_DISPARITY: out.kinds.push_back(PreviewKind::kDisparity); break;
      case v1::PREVIEW_KIND_LEFT: out.kinds.push_back(PreviewKind::kLeft); break;
      case v1::PREVIEW_KIND_UNSPECIFIED:
        problems.push_back(field + ": PREVIEW_KIND_UNSPECIFIED is not a kind");
        break;
      default: problems.push_back(field + ": unknown kind " + std::to_string(request.kinds(i)));
    }
  }
  if (request.rate_hz() != 0) out.rate_hz = request.rate_hz();
  if (request.max_width_px() != 0) out.max_width_px = request.max_width_px();
  if (request.jpeg_quality() != 0) out.jpeg_quality = request.jpeg_quality();
  std::vector<std::string> invalid = out.Validate();
  // With an unknown kind, the kinds' own problems are those above (the indices of `out.kinds`
  // are not the request's).
  if (!problems.empty()) {
    std::erase_if(invalid, [](const std::string& p) { return p.rfind("kinds", 0) == 0; });
  }
  problems.insert(problems.end(), invalid.begin(), invalid.end());
  if (!problems.empty()) return InvalidArgument(problems);
  return out;
}

v1::PreviewKind ToProto(PreviewKind kind) {
  switch (kind) {
    case PreviewKind::kAnnotatedLeft: return v1::PREVIEW_KIND_ANNOTATED_LEFT;
    case PreviewKind::kDisparity: return v1::PREVIEW_KIND_DISPARITY;
    case PreviewKind::kLeft: return v1::PREVIEW_KIND_LEFT;
  }
  return v1::PREVIEW_KIND_UNSPECIFIED;
}

v1::Preview ToProto(const Preview& preview) {
  v1::Preview p;
  p.set_frame_id(preview.frame_id);
  p.set_capture_time_ns(preview.capture_time_ns);
  p.set_capture_unix_time_ns(preview.capture_unix_time_ns);
  p.set_kind(ToProto(preview.kind));
  p.set_jpeg(preview.jpeg);
  p.set_width(preview.width);
  p.set_height(preview.height);
  p.set_scale(preview.scale);
  p.set_calibration_id(preview.calibration_id);
  return p;
}

Result<v1::DisparitySnapshot> ToSnapshot(const pipeline::FrameResult& result, bool annotated) {
  v1::DisparitySnapshot s;
  s.set_frame_id(result.frame_id);
  s.set_capture_time_ns(result.capture_time_ns);
  s.set_width(result.disparity.fixed.cols);
  s.set_height(result.disparity.fixed.rows);
  s.set_binning(result.binning);
  s.set_disparity_scale(stereo::DisparityMap::kScale);
  s.set_min_disparity(result.disparity.min_disparity);
  s.set_num_disparities(result.disparity.num_disparities);

  std::vector<uchar> png;
  const auto encode = [&](const cv::Mat& image, std::string* out) {
    png.clear();
    if (image.empty() || !cv::imencode(".png", image, png)) return false;
    out->assign(png.begin(), png.end());
    return true;
  };
  if (!encode(stereo::ToFixedPoint16U(result.disparity), s.mutable_disparity_png16()) ||
      !encode(stereo::ToColour(result.disparity), s.mutable_disparity_colour_png()) ||
      !encode(result.rectified_left, s.mutable_left_png()) ||
      (annotated && !encode(pipeline::AnnotateTracks(result), s.mutable_annotated_png()))) {
    return Internal("snapshot: PNG encoding failed");
  }
  if (result.rig) {
    const geometry::StereoRig& rig = *result.rig;
    s.set_f_px(rig.f_px());
    s.set_baseline_m(rig.baseline_m());
    s.set_cx(rig.cx());
    s.set_cy(rig.cy());
    s.set_calibration_id(rig.calibration_id());
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) s.add_q(rig.Q()(i, j));
    }
  }
  return s;
}

}  // namespace stevi::server
