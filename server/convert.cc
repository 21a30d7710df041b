#include "server/convert.h"

#include "drivers/recording/recording_reader.h"

#include <google/protobuf/util/json_util.h>

#include <opencv2/imgcodecs.hpp>

#include "core/pipeline/annotate.h"

namespace stevi::server {
namespace {

using pipeline::Algorithm;
using stereo::MatcherKind;
using Mode = stereo::SemiGlobalOptions::Mode;

v1::SemiGlobalMode ToProto(Mode mode) {
  switch (mode) {
    case Mode::kSgbm5Path: return v1::SEMI_GLOBAL_MODE_SGBM_5_PATH;
    case Mode::kFull8Path: return v1::SEMI_GLOBAL_MODE_FULL_8_PATH;
    case Mode::kThreeWay: return v1::SEMI_GLOBAL_MODE_THREE_WAY;
    case Mode::kHH4: return v1::SEMI_GLOBAL_MODE_HH4;
  }
  return v1::SEMI_GLOBAL_MODE_UNSPECIFIED;
}

// Copies a proto optional scalar onto a core field when it is set.
#define STEVI_MERGE(msg, field, target)                \
  do {                                                 \
    if ((msg).has_##field()) (target) = (msg).field(); \
  } while (false)

void ToProto(const detection::StereoBlobOptions& o, v1::BlobConfig* p) {
  p->set_min_area_px(o.min_area_px);
  p->set_max_width_fraction(o.max_width_fraction);
  p->set_min_valid_fraction(o.min_valid_fraction);
  p->set_max_disparity_step_px(o.max_disparity_step_px);
  p->set_interior_erode_px(o.interior_erode_px);
  p->set_max_depth_per_height(o.max_depth_per_height);
  p->set_min_terrain_height_m(o.min_terrain_height_m);
  p->set_max_attached_fraction(o.max_attached_fraction);
  p->set_min_valid_px(o.min_valid_px);
  p->set_join_gap_fraction(o.join_gap_fraction);
  p->set_join_within_region(o.join_within_region);
  p->set_region_gap_fraction(o.region_gap_fraction);
}

void MergeBlobs(const v1::BlobConfig& p, detection::StereoBlobOptions& o) {
  STEVI_MERGE(p, min_area_px, o.min_area_px);
  STEVI_MERGE(p, max_width_fraction, o.max_width_fraction);
  STEVI_MERGE(p, min_valid_fraction, o.min_valid_fraction);
  STEVI_MERGE(p, max_disparity_step_px, o.max_disparity_step_px);
  STEVI_MERGE(p, interior_erode_px, o.interior_erode_px);
  STEVI_MERGE(p, max_depth_per_height, o.max_depth_per_height);
  STEVI_MERGE(p, min_terrain_height_m, o.min_terrain_height_m);
  STEVI_MERGE(p, max_attached_fraction, o.max_attached_fraction);
  STEVI_MERGE(p, min_valid_px, o.min_valid_px);
  STEVI_MERGE(p, join_gap_fraction, o.join_gap_fraction);
  STEVI_MERGE(p, join_within_region, o.join_within_region);
  STEVI_MERGE(p, region_gap_fraction, o.region_gap_fraction);
}

// "<path>: unknown value <n>", the problem of an enum value the schema does not know.
void UnknownEnum(const std::string& path, int value, std::vector<std::string>& problems) {
  problems.push_back(path + ": unknown value " + std::to_string(value));
}

void ToProto(const detection::GroundOptions& o, v1::GroundConfig* p) {
  p->set_enabled(o.enabled);
  p->set_min_row_fraction(o.min_row_fraction);
  p->set_min_row_pixels(o.min_row_pixels);
  p->set_min_row_spread(o.min_row_spread);
  p->set_min_mode_px(o.min_mode_px);
  p->set_min_support_rows(o.min_support_rows);
  p->set_inlier_px(o.inlier_px);
  p->set_min_span_px(o.min_span_px);
  p->set_margin_px(o.margin_px);
  p->set_margin_fraction(o.margin_fraction);
}

void MergeGround(const v1::GroundConfig& p, detection::GroundOptions& o) {
  STEVI_MERGE(p, enabled, o.enabled);
  STEVI_MERGE(p, min_row_fraction, o.min_row_fraction);
  STEVI_MERGE(p, min_row_pixels, o.min_row_pixels);
  STEVI_MERGE(p, min_row_spread, o.min_row_spread);
  STEVI_MERGE(p, min_mode_px, o.min_mode_px);
  STEVI_MERGE(p, min_support_rows, o.min_support_rows);
  STEVI_MERGE(p, inlier_px, o.inlier_px);
  STEVI_MERGE(p, min_span_px, o.min_span_px);
  STEVI_MERGE(p, margin_px, o.margin_px);
  STEVI_MERGE(p, margin_fraction, o.margin_fraction);
}

using extraction::StructuringShape;

v1::StructuringShape ToProto(StructuringShape shape) {
  switch (shape) {
    case StructuringShape::kRect: return v1::STRUCTURING_SHAPE_RECT;
    case StructuringShape::kEllipse: return v1::STRUCTURING_SHAPE_ELLIPSE;
    case StructuringShape::kCross: return v1::STRUCTURING_SHAPE_CROSS;
  }
  return v1::STRUCTURING_SHAPE_UNSPECIFIED;
}

void ToProto(const extraction::MorphologyOptions& o, v1::MorphologyConfig* p) {
  p->set_shape(ToProto(o.shape));
  p->set_close_size(o.close_size);
  p->set_open_size(o.open_size);
  p->set_fill_holes(o.fill_holes);
}

// `path` names the message ("stevie.morphology") in the problems.
void MergeMorphology(const v1::MorphologyConfig& p, extraction::MorphologyOptions& o,
                     const std::string& path, std::vector<std::string>& problems) {
  switch (p.shape()) {
    case v1::STRUCTURING_SHAPE_UNSPECIFIED: break;
    case v1::STRUCTURING_SHAPE_RECT: o.shape = StructuringShape::kRect; break;
    case v1::STRUCTURING_SHAPE_ELLIPSE: o.shape = StructuringShape::kEllipse; break;
    case v1::STRUCTURING_SHAPE_CROSS: o.shape = StructuringShape::kCross; break;
    default: UnknownEnum(path + ".shape", p.shape(), problems);
  }
  STEVI_MERGE(p, close_size, o.close_size);
  STEVI_MERGE(p, open_size, o.open_size);
  STEVI_MERGE(p, fill_holes, o.fill_holes);
}

void ToProto(const extraction::EdgeOptions& o, v1::EdgeConfig* p) {
  p->set_blur_size(o.blur_size);
  p->set_blur_sigma(o.blur_sigma);
  p->set_canny_low(o.canny_low);
  p->set_canny_high(o.canny_high);
  p->set_canny_aperture(o.canny_aperture);
  p->set_l2_gradient(o.l2_gradient);
}

void MergeEdges(const v1::EdgeConfig& p, extraction::EdgeOptions& o) {
  STEVI_MERGE(p, blur_size, o.blur_size);
  STEVI_MERGE(p, blur_sigma, o.blur_sigma);
  STEVI_MERGE(p, canny_low, o.canny_low);
  STEVI_MERGE(p, canny_high, o.canny_high);
  STEVI_MERGE(p, canny_aperture, o.canny_aperture);
  STEVI_MERGE(p, l2_gradient, o.l2_gradient);
}

void ToProto(const extraction::SaliencyOptions& o, v1::SaliencyConfig* p) {
  p->set_centre_level(o.centre_level);
  p->mutable_scales()->Assign(o.scales.begin(), o.scales.end());
  p->mutable_surround_radii()->Assign(o.surround_radii.begin(), o.surround_radii.end());
  p->set_uniqueness_weight(o.uniqueness_weight);
  p->set_peak_fraction(o.peak_fraction);
  p->set_min_contrast(o.min_contrast);
}

// The lists are replaced as a whole when the update holds any element, and kept when it is empty.
void MergeSaliency(const v1::SaliencyConfig& p, extraction::SaliencyOptions& o) {
  STEVI_MERGE(p, centre_level, o.centre_level);
  if (!p.scales().empty()) o.scales.assign(p.scales().begin(), p.scales().end());
  if (!p.surround_radii().empty()) {
    o.surround_radii.assign(p.surround_radii().begin(), p.surround_radii().end());
  }
  STEVI_MERGE(p, uniqueness_weight, o.uniqueness_weight);
  STEVI_MERGE(p, peak_fraction, o.peak_fraction);
  STEVI_MERGE(p, min_contrast, o.min_contrast);
}

void ToProto(const extraction::GraphSegmentationOptions& o, v1::GraphSegmentationConfig* p) {
  p->set_k(o.k);
  p->set_sigma(o.sigma);
  p->set_min_size(o.min_size);
}

void MergeGraph(const v1::GraphSegmentationConfig& p, extraction::GraphSegmentationOptions& o) {
  STEVI_MERGE(p, k, o.k);
  STEVI_MERGE(p, sigma, o.sigma);
  STEVI_MERGE(p, min_size, o.min_size);
}

void ToProto(const detection::SteViEOptions& o, v1::SteViEConfig* p) {
  ToProto(o.edges, p->mutable_edges());
  ToProto(o.morphology, p->mutable_morphology());
  ToProto(o.ground, p->mutable_ground());
  ToProto(o.blobs, p->mutable_blobs());
}

void MergeSteViE(const v1::SteViEConfig& p, detection::SteViEOptions& o,
                 std::vector<std::string>& problems) {
  MergeEdges(p.edges(), o.edges);
  MergeMorphology(p.morphology(), o.morphology, "stevie.morphology", problems);
  MergeGround(p.ground(), o.ground);
  MergeBlobs(p.blobs(), o.blobs);
}

using Segmentation = detection::SteViSOptions::Segmentation;

v1::Segmentation ToProto(Segmentation segmentation) {
  switch (segmentation) {
    case Segmentation::kThreshold: return v1::SEGMENTATION_THRESHOLD;
    case Segmentation::kGraph: return v1::SEGMENTATION_GRAPH;
  }
  return v1::SEGMENTATION_UNSPECIFIED;
}

void ToProto(const detection::SteViSOptions& o, v1::SteViSConfig* p) {
  ToProto(o.saliency, p->mutable_saliency());
  p->set_segmentation(ToProto(o.segmentation));
  p->set_saliency_threshold(o.saliency_threshold);
  ToProto(o.morphology, p->mutable_morphology());
  ToProto(o.graph, p->mutable_graph());
  p->set_graph_level(o.graph_level);
  ToProto(o.ground, p->mutable_ground());
  ToProto(o.blobs, p->mutable_blobs());
}

void MergeSteViS(const v1::SteViSConfig& p, detection::SteViSOptions& o,
                 std::vector<std::string>& problems) {
  MergeSaliency(p.saliency(), o.saliency);
  switch (p.segmentation()) {
    case v1::SEGMENTATION_UNSPECIFIED: break;
    case v1::SEGMENTATION_THRESHOLD: o.segmentation = Segmentation::kThreshold; break;
    case v1::SEGMENTATION_GRAPH: o.segmentation = Segmentation::kGraph; break;
    default: UnknownEnum("stevis.segmentation", p.segmentation(), problems);
  }
  STEVI_MERGE(p, saliency_threshold, o.saliency_threshold);
  MergeMorphology(p.morphology(), o.morphology, "stevis.morphology", problems);
  MergeGraph(p.graph(), o.graph);
  STEVI_MERGE(p, graph_level, o.graph_level);
  MergeGround(p.ground(), o.ground);
  MergeBlobs(p.blobs(), o.blobs);
}

}  // namespace

v1::Algorithm ToProto(Algorithm algorithm) {
  switch (algorithm) {
    case Algorithm::kCanonical: return v1::ALGORITHM_CANONICAL;
    case Algorithm::kSteViE: return v1::ALGORITHM_STEVIE;
    case Algorithm::kSteViS: return v1::ALGORITHM_STEVIS;
  }
  return v1::ALGORITHM_UNSPECIFIED;
}

void ToProto(const tracking::TrackerOptions& o, v1::TrackingConfig* p) {
  v1::KalmanConfig* k = p->mutable_kalman();
  k->set_process_noise(o.kalman.process_noise);
  k->set_measurement_noise(o.kalman.measurement_noise);
  k->set_occluded_process_noise(o.kalman.occluded_process_noise);
  k->set_occluded_measurement_noise(o.kalman.occluded_measurement_noise);
  k->set_initial_velocity_sigma_mps(o.kalman.initial_velocity_sigma_mps);
  v1::GateConfig* g = p->mutable_gates();
  g->set_max_depth_ratio(o.gates.max_depth_ratio);
  g->set_max_area_ratio(o.gates.max_area_ratio);
  g->set_max_perimeter_ratio(o.gates.max_perimeter_ratio);
  g->set_max_distance_px(o.gates.max_distance_px);
  g->set_depth_sigmas(o.gates.depth_sigmas);
  g->set_min_depth_sigma_fraction(o.gates.min_depth_sigma_fraction);
  g->set_position_sigmas(o.gates.position_sigmas);
  p->set_confirm_hits(o.confirm_hits);
  p->set_tentative_delete_misses(o.tentative_delete_misses);
  p->set_delete_misses(o.delete_misses);
  p->set_fading_beta(o.fading_beta);
  p->set_min_score(o.min_score);
  p->set_max_dt_s(o.max_dt_s);
  p->set_merge_iou(o.merge_iou);
}

void MergeTracking(const v1::TrackingConfig& p, tracking::TrackerOptions& o) {
  STEVI_MERGE(p.kalman(), process_noise, o.kalman.process_noise);
  STEVI_MERGE(p.kalman(), measurement_noise, o.kalman.measurement_noise);
  STEVI_MERGE(p.kalman(), occluded_process_noise, o.kalman.occluded_process_noise);
  STEVI_MERGE(p.kalman(), occluded_measurement_noise, o.kalman.occluded_measurement_noise);
  STEVI_MERGE(p.kalman(), initial_velocity_sigma_mps, o.kalman.initial_velocity_sigma_mps);
  STEVI_MERGE(p.gates(), max_depth_ratio, o.gates.max_depth_ratio);
  STEVI_MERGE(p.gates(), max_area_ratio, o.gates.max_area_ratio);
  STEVI_MERGE(p.gates(), max_perimeter_ratio, o.gates.max_perimeter_ratio);
  STEVI_MERGE(p.gates(), max_distance_px, o.gates.max_distance_px);
  STEVI_MERGE(p.gates(), depth_sigmas, o.gates.depth_sigmas);
  STEVI_MERGE(p.gates(), min_depth_sigma_fraction, o.gates.min_depth_sigma_fraction);
  STEVI_MERGE(p.gates(), position_sigmas, o.gates.position_sigmas);
  STEVI_MERGE(p, confirm_hits, o.confirm_hits);
  STEVI_MERGE(p, tentative_delete_misses, o.tentative_delete_misses);
  STEVI_MERGE(p, delete_misses, o.delete_misses);
  STEVI_MERGE(p, fading_beta, o.fading_beta);
  STEVI_MERGE(p, min_score, o.min_score);
  STEVI_MERGE(p, max_dt_s, o.max_dt_s);
  STEVI_MERGE(p, merge_iou, o.merge_iou);
}

void ToProto(const geo::MountOptions& o, v1::MountConfig* p) {
  p->set_roll_deg(o.roll_deg);
  p->set_pitch_deg(o.pitch_deg);
  p->set_yaw_deg(o.yaw_deg);
  p->set_lever_arm_x_m(o.lever_arm_m.x());
  p->set_lever_arm_y_m(o.lever_arm_m.y());
  p->set_lever_arm_z_m(o.lever_arm_m.z());
}

void MergeMount(const v1::MountConfig& p, geo::MountOptions& o) {
  STEVI_MERGE(p, roll_deg, o.roll_deg);
  STEVI_MERGE(p, pitch_deg, o.pitch_deg);
  STEVI_MERGE(p, yaw_deg, o.yaw_deg);
  STEVI_MERGE(p, lever_arm_x_m, o.lever_arm_m.x());
  STEVI_MERGE(p, lever_arm_y_m, o.lever_arm_m.y());
  STEVI_MERGE(p, lever_arm_z_m, o.lever_arm_m.z());
}

v1::PipelineConfig ToProto(const pipeline::PipelineConfig& c) {
  v1::PipelineConfig p;
  p.set_algorithm(ToProto(c.algorithm));
  p.set_max_width_px(c.max_width_px);

  v1::MatcherConfig* m = p.mutable_matcher();
  m->set_kind(c.matcher.kind == MatcherKind::kBlockMatching ? v1::MATCHER_KIND_BLOCK_MATCHING
                                                            : v1::MATCHER_KIND_SEMI_GLOBAL);
  const stereo::BlockMatchingOptions& bm = c.matcher.block_matching;
  v1::BlockMatchingConfig* pbm = m->mutable_block_matching();
  pbm->set_prefilter_size(bm.prefilter_size);
  pbm->set_prefilter_cap(bm.prefilter_cap);
  pbm->set_block_size(bm.block_size);
  pbm->set_num_disparities(bm.num_disparities);
  pbm->set_min_disparity(bm.min_disparity);
  pbm->set_texture_threshold(bm.texture_threshold);
  pbm->set_uniqueness_ratio(bm.uniqueness_ratio);
  pbm->set_speckle_window_size(bm.speckle_window_size);
  pbm->set_speckle_range(bm.speckle_range);
  pbm->set_pad_left(bm.pad_left);
  pbm->set_local_texture_threshold(bm.local_texture_threshold);
  pbm->set_prefilter_type(bm.prefilter_type == stereo::BlockMatchingOptions::PreFilter::kXSobel
                              ? v1::PRE_FILTER_X_SOBEL
                              : v1::PRE_FILTER_NORMALIZED_RESPONSE);

  const stereo::SemiGlobalOptions& sg = c.matcher.semi_global;
  v1::SemiGlobalConfig* psg = m->mutable_semi_global();
  psg->set_block_size(sg.block_size);
  psg->set_num_disparities(sg.num_disparities);
  psg->set_min_disparity(sg.min_disparity);
  psg->set_p1(sg.p1);
  psg->set_p2(sg.p2);
  psg->set_disp12_max_diff(sg.disp12_max_diff);
  psg->set_prefilter_cap(sg.prefilter_cap);
  psg->set_uniqueness_ratio(sg.uniqueness_ratio);
  psg->set_speckle_window_size(sg.speckle_window_size);
  psg->set_speckle_range(sg.speckle_range);
  psg->set_mode(ToProto(sg.mode));
  psg->set_pad_left(sg.pad_left);
  psg->set_texture_threshold(sg.texture_threshold);

  v1::RangeConfig* r = p.mutable_range();
  r->set_min_disparity_px(c.range.min_disparity_px);
  r->set_max_range_m(c.range.max_range_m);
  r->set_disparity_sigma_px(c.range.disparity_sigma_px);

  v1::CanonicalConfig* k = p.mutable_canonical();
  k->set_threshold_range_m(c.canonical.threshold_range_m);
  k->set_open_size_px(c.canonical.open_size_px);
  ToProto(c.canonical.blobs, k->mutable_blobs());

  ToProto(c.stevie, p.mutable_stevie());
  ToProto(c.stevis, p.mutable_stevis());
  ToProto(c.tracking, p.mutable_tracking());
  ToProto(c.mount, p.mutable_mount());
  return p;
}

std::vector<std::string> MergeFromProto(const v1::PipelineConfig& u, pipeline::PipelineConfig& c) {
  std::vector<std::string> problems;
  switch (u.algorithm()) {
    case v1::ALGORITHM_UNSPECIFIED: break;
    case v1::ALGORITHM_CANONICAL: c.algorithm = Algorithm::kCanonical; break;
    case v1::ALGORITHM_STEVIE: c.algorithm = Algorithm::kSteViE; break;
    case v1::ALGORITHM_STEVIS: c.algorithm = Algorithm::kSteViS; break;
    default: problems.push_back("algorithm: unknown value " + std::to_string(u.algorithm()));
  }
  STEVI_MERGE(u, max_width_px, c.max_width_px);

  const v1::MatcherConfig& m = u.matcher();
  switch (m.kind()) {
    case v1::MATCHER_KIND_UNSPECIFIED: break;
    case v1::MATCHER_KIND_BLOCK_MATCHING: c.matcher.kind = MatcherKind::kBlockMatching; break;
    case v1::MATCHER_KIND_SEMI_GLOBAL: c.matcher.kind = MatcherKind::kSemiGlobal; break;
    default: problems.push_back("matcher.kind: unknown value " + std::to_string(m.kind()));
  }
  const v1::BlockMatchingConfig& pbm = m.block_matching();
  stereo::BlockMatchingOptions& bm = c.matcher.block_matching;
  STEVI_MERGE(pbm, prefilter_size, bm.prefilter_size);
  STEVI_MERGE(pbm, prefilter_cap, bm.prefilter_cap);
  STEVI_MERGE(pbm, block_size, bm.block_size);
  STEVI_MERGE(pbm, num_disparities, bm.num_disparities);
  STEVI_MERGE(pbm, min_disparity, bm.min_disparity);
  STEVI_MERGE(pbm, texture_threshold, bm.texture_threshold);
  STEVI_MERGE(pbm, uniqueness_ratio, bm.uniqueness_ratio);
  STEVI_MERGE(pbm, speckle_window_size, bm.speckle_window_size);
  STEVI_MERGE(pbm, speckle_range, bm.speckle_range);
  STEVI_MERGE(pbm, pad_left, bm.pad_left);
  STEVI_MERGE(pbm, local_texture_threshold, bm.local_texture_threshold);
  switch (pbm.prefilter_type()) {
    case v1::PRE_FILTER_UNSPECIFIED: break;
    case v1::PRE_FILTER_X_SOBEL:
      bm.prefilter_type = stereo::BlockMatchingOptions::PreFilter::kXSobel;
      break;
    case v1::PRE_FILTER_NORMALIZED_RESPONSE:
      bm.prefilter_type = stereo::BlockMatchingOptions::PreFilter::kNormalizedResponse;
      break;
    default:
      problems.push_back("matcher.block_matching.prefilter_type: unknown value " +
                         std::to_string(pbm.prefilter_type()));
  }

  const v1::SemiGlobalConfig& psg = m.semi_global();
  stereo::SemiGlobalOptions& sg = c.matcher.semi_global;
  STEVI_MERGE(psg, block_size, sg.block_size);
  STEVI_MERGE(psg, num_disparities, sg.num_disparities);
  STEVI_MERGE(psg, min_disparity, sg.min_disparity);
  STEVI_MERGE(psg, p1, sg.p1);
  STEVI_MERGE(psg, p2, sg.p2);
  STEVI_MERGE(psg, disp12_max_diff, sg.disp12_max_diff);
  STEVI_MERGE(psg, prefilter_cap, sg.prefilter_cap);
  STEVI_MERGE(psg, uniqueness_ratio, sg.uniqueness_ratio);
  STEVI_MERGE(psg, speckle_window_size, sg.speckle_window_size);
  STEVI_MERGE(psg, speckle_range, sg.speckle_range);
  STEVI_MERGE(psg, pad_left, sg.pad_left);
  STEVI_MERGE(psg, texture_threshold, sg.texture_threshold);
  switch (psg.mode()) {
    case v1::SEMI_GLOBAL_MODE_UNSPECIFIED: break;
    case v1::SEMI_GLOBAL_MODE_SGBM_5_PATH: sg.mode = Mode::kSgbm5Path; break;
    case v1::SEMI_GLOBAL_MODE_FULL_8_PATH: sg.mode = Mode::kFull8Path; break;
    case v1::SEMI_GLOBAL_MODE_THREE_WAY: sg.mode = Mode::kThreeWay; break;
    case v1::SEMI_GLOBAL_MODE_HH4: sg.mode = Mode::kHH4; break;
    default:
      problems.push_back("matcher.semi_global.mode: unknown value " + std::to_string(psg.mode()));
  }

  const v1::RangeConfig& r = u.range();
  STEVI_MERGE(r, min_disparity_px, c.range.min_disparity_px);
  STEVI_MERGE(r, max_range_m, c.range.max_range_m);
  STEVI_MERGE(r, disparity_sigma_px, c.range.disparity_sigma_px);

  const v1::CanonicalConfig& k = u.canonical();
  STEVI_MERGE(k, threshold_range_m, c.canonical.threshold_range_m);
  STEVI_MERGE(k, open_size_px, c.canonical.open_size_px);
  MergeBlobs(k.blobs(), c.canonical.blobs);

  MergeSteViE(u.stevie(), c.stevie, problems);
  MergeSteViS(u.stevis(), c.stevis, problems);
  MergeTracking(u.tracking(), c.tracking);
  MergeMount(u.mount(), c.mount);
  return problems;
}

#undef STEVI_MERGE

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
void SetPoint(const cv::Vec3d& p, v1::PointCam* point) {
  point->set_x_m(p[0]);
  point->set_y_m(p[1]);
  point->set_z_m(p[2]);
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
  if (result.pose) {
    f.set_geo_status(ToProto(result.pose->status));
    f.set_geo_message(result.pose->message);
    if (result.pose->pose) *f.mutable_vehicle() = ToProto(result.pose->pose->state);
  }
  return f;
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
    return Error{ErrorCode::kInternal, "snapshot: PNG encoding failed"};
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
