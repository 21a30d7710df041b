#include "tests/testing/odometry_sequence.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "tests/testing/truth_match.h"

namespace stevi::testing {

std::optional<OdometrySequence> LoadOdometrySequence(const std::string& data_dir,
                                                     std::string& problem) {
  OdometrySequence seq;
  seq.name = kKittiOdomSeqB;
  seq.folder = (std::filesystem::path(data_dir) / kKittiOdomSeqBFolder).string();
  std::ifstream poses(seq.folder + "/poses.txt");
  if (!poses) {
    problem = "missing " + seq.folder + "/poses.txt";
    return std::nullopt;
  }
  std::string line;
  while (std::getline(poses, line)) {
    if (line.empty()) continue;
    std::istringstream in(line);
    double m[12];
    for (double& v : m) in >> v;
    if (!in) {
      problem = "malformed pose line " + std::to_string(seq.poses.size() + 1) + " in poses.txt";
      return std::nullopt;
    }
    CamPose p;
    p.R = cv::Matx33d(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    p.t = cv::Vec3d(m[3], m[7], m[11]);
    seq.poses.push_back(p);
  }
  for (size_t k = 0; k < seq.poses.size(); ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "%06zu.png", k);
    cv::Mat1b l = cv::imread(seq.folder + "/image_l/" + name, cv::IMREAD_GRAYSCALE);
    cv::Mat1b r = cv::imread(seq.folder + "/image_r/" + name, cv::IMREAD_GRAYSCALE);
    if (l.empty() || r.empty() || l.size() != r.size()) {
      problem = "missing or unreadable pair " + std::string(name) + " under " + seq.folder;
      return std::nullopt;
    }
    seq.left.push_back(l);
    seq.right.push_back(r);
  }
  if (seq.left.empty()) {
    problem = "no poses in " + seq.folder + "/poses.txt";
    return std::nullopt;
  }
  return seq;
}

std::vector<LabelledBox> LoadCarLabels(const std::string& path, std::string& problem) {
  std::vector<LabelledBox> labels;
  std::ifstream in(path);
  if (!in) {
    problem = "missing label file " + path;
    return {};
  }
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    std::istringstream fields(line);
    LabelledBox b;
    fields >> b.car >> b.frame >> b.box.x >> b.box.y >> b.box.width >> b.box.height;
    if (!fields || b.box.width <= 0 || b.box.height <= 0) {
      problem = path + ":" + std::to_string(number) + ": expected 'car frame x y width height'";
      return {};
    }
    labels.push_back(b);
  }
  return labels;
}

std::string CarLabelPath() {
#ifdef STEVI_SOURCE_DIR
  return std::string(STEVI_SOURCE_DIR) + "/tests/testing/kitti_odom_seq_b_cars.txt";
#else
  return "tests/testing/kitti_odom_seq_b_cars.txt";
#endif
}

std::optional<ReferenceGround> FitReferenceGround(const cv::Mat1b& left, const cv::Mat1b& right,
                                                  double f_px, double baseline_m, double cx,
                                                  double cy) {
  constexpr int kDisparities = 128, kBlock = 5;
  // Padding on the left lets SGBM match the leftmost columns (shared data README).
  cv::Mat1b l, r;
  cv::copyMakeBorder(left, l, 0, 0, kDisparities, 0, cv::BORDER_REPLICATE);
  cv::copyMakeBorder(right, r, 0, 0, kDisparities, 0, cv::BORDER_REPLICATE);
  const cv::Ptr<cv::StereoSGBM> sgbm =
      cv::StereoSGBM::create(0, kDisparities, kBlock, 8 * kBlock * kBlock, 32 * kBlock * kBlock, 1,
                             0, 10, 100, 2, cv::StereoSGBM::MODE_SGBM_3WAY);
  cv::Mat1s fixed;
  sgbm->compute(l, r, fixed);
  ReferenceGround g;
  g.disparity_px = cv::Mat1f(left.size(), 0.0f);
  for (int y = 0; y < left.rows; ++y) {
    for (int x = 0; x < left.cols; ++x) {
      const int16_t v = fixed(y, x + kDisparities);
      if (v > 0) g.disparity_px(y, x) = static_cast<float>(v) / 16.0f;
    }
  }
  const GtScene scene = ExtractGtObstacles(g.disparity_px, f_px, baseline_m, cx, cy);
  if (!scene.ground) return std::nullopt;
  g.plane = *scene.ground;
  return g;
}

double HeightAbovePlane(const GroundPlane& plane, double f_px, double baseline_m, double cx,
                        double cy, const cv::Vec3d& p) {
  // d = a u + b v + c with u = f X / Z + cx, v = f Y / Z + cy, d = f B / Z:
  // a f X + b f Y + (a cx + b cy + c) Z = f B. The camera (origin) is on the positive side.
  const cv::Vec3d n(plane.a * f_px, plane.b * f_px, plane.a * cx + plane.b * cy + plane.c);
  const double norm = cv::norm(n);
  if (norm <= 0) return 0.0;
  return (f_px * baseline_m - n.dot(p)) / norm;
}

bool HitsLabel(const cv::Rect& box, const cv::Rect& label) {
  return IoU(box, label) >= 0.3 || InsideFraction(label, box) >= 0.5;
}

namespace {

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

bool Excluded(const OdoTrackFrame& t, const std::vector<LabelledBox>& exclude) {
  for (const LabelledBox& b : exclude) {
    if (b.frame == t.frame && HitsLabel(t.box, b.box)) return true;
  }
  return false;
}

}  // namespace

StaticWorldScore ScoreStaticWorld(const std::vector<OdoTrackFrame>& tracks,
                                  const std::vector<CamPose>& poses,
                                  const StaticWorldOptions& options,
                                  const std::vector<LabelledBox>& exclude) {
  std::map<uint64_t, std::vector<const OdoTrackFrame*>> by_track;
  for (const OdoTrackFrame& t : tracks) {
    if (t.frame < 0 || t.frame >= static_cast<int>(poses.size()) || Excluded(t, exclude)) continue;
    by_track[t.id].push_back(&t);
  }
  StaticWorldScore s;
  for (const auto& [id, list] : by_track) {
    if (static_cast<int>(list.size()) < options.min_frames) continue;
    ++s.tracks;
    std::vector<cv::Vec3d> world;
    std::vector<double> axis[3];
    for (const OdoTrackFrame* t : list) {
      world.push_back(poses[static_cast<size_t>(t->frame)].ToWorld(t->position_cam_m));
      for (int a = 0; a < 3; ++a) axis[a].push_back(world.back()[a]);
    }
    const cv::Vec3d median(Median(axis[0]), Median(axis[1]), Median(axis[2]));
    for (size_t k = 0; k < list.size(); ++k) {
      const double deviation = cv::norm(world[k] - median);
      const double range = cv::norm(list[k]->position_cam_m);
      const double bound =
          std::max({options.range_fraction * range,
                    options.sigmas * cv::norm(list[k]->position_sigma_m), options.floor_m});
      ++s.track_frames;
      s.consistent += deviation <= bound;
      s.deviation_m.push_back(deviation);
    }
  }
  return s;
}

namespace {

// Whether at least half of the box's pixels with a reference disparity lie on the plane.
bool RoadBox(const cv::Rect& box, const GroundPlane& plane, const cv::Mat1f& disparity) {
  const cv::Rect b = box & cv::Rect(0, 0, disparity.cols, disparity.rows);
  int known = 0, on_plane = 0;
  for (int y = b.y; y < b.br().y; ++y) {
    for (int x = b.x; x < b.br().x; ++x) {
      const float d = disparity(y, x);
      if (d <= 0) continue;
      ++known;
      const double road = plane.DisparityAt(x, y);
      on_plane += std::abs(d - road) <= std::max(1.0, 0.05 * road);
    }
  }
  return known > 0 && 2 * on_plane >= known;
}

}  // namespace

GroundScore ScoreOnGround(const std::vector<OdoTrackFrame>& tracks,
                          const std::vector<std::optional<GroundPlane>>& planes, double f_px,
                          double baseline_m, double cx, double cy, double max_height_m,
                          const std::vector<cv::Mat1f>* reference_disparity) {
  constexpr double kBelowRoadM = 0.5;
  GroundScore s;
  for (const OdoTrackFrame& t : tracks) {
    ++s.track_frames;
    if (t.frame < 0 || t.frame >= static_cast<int>(planes.size())) continue;
    const std::optional<GroundPlane>& plane = planes[static_cast<size_t>(t.frame)];
    if (!plane) continue;
    const double z = t.position_cam_m[2];
    if (z <= 0) continue;
    const double u = (t.box.x + 0.5 * t.box.width - cx) * z / f_px;
    const cv::Vec3d top(u, (t.box.y - cy) * z / f_px, z);
    const cv::Vec3d bottom(u, (t.box.y + t.box.height - cy) * z / f_px, z);
    ++s.scored;
    s.on_ground += HeightAbovePlane(*plane, f_px, baseline_m, cx, cy, top) < max_height_m;
    s.below_road += HeightAbovePlane(*plane, f_px, baseline_m, cx, cy, bottom) < -kBelowRoadM;
    if (reference_disparity && t.frame < static_cast<int>(reference_disparity->size())) {
      s.road_box += RoadBox(t.box, *plane, (*reference_disparity)[static_cast<size_t>(t.frame)]);
    }
  }
  return s;
}

std::vector<CarScore> ScoreCars(const std::vector<OdoTrackFrame>& tracks,
                                const std::vector<LabelledBox>& labels, int skip_frames) {
  std::map<int, std::vector<const LabelledBox*>> by_car;
  for (const LabelledBox& b : labels) by_car[b.car].push_back(&b);
  std::vector<CarScore> scores;
  for (auto& [car, list] : by_car) {
    std::sort(list.begin(), list.end(),
              [](const LabelledBox* a, const LabelledBox* b) { return a->frame < b->frame; });
    CarScore s;
    s.car = car;
    s.labelled_frames = static_cast<int>(list.size());
    s.first_frame = list.front()->frame;
    s.last_frame = list.back()->frame;
    for (size_t k = static_cast<size_t>(std::max(0, skip_frames)); k < list.size(); ++k) {
      ++s.scored_frames;
      const bool hit = std::any_of(tracks.begin(), tracks.end(), [&](const OdoTrackFrame& t) {
        return t.frame == list[k]->frame && HitsLabel(t.box, list[k]->box);
      });
      s.confirmed_iou_frames +=
          std::any_of(tracks.begin(), tracks.end(), [&](const OdoTrackFrame& t) {
            return t.frame == list[k]->frame && IoU(t.box, list[k]->box) >= 0.3;
          });
      if (hit) {
        ++s.confirmed_frames;
      } else {
        s.missed.push_back(list[k]->frame);
      }
    }
    scores.push_back(s);
  }
  return scores;
}

}  // namespace stevi::testing
