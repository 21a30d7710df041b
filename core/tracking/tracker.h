// The multi-target tracker: one constant-velocity Kalman filter per obstacle in the cam frame,
// Hungarian assignment on the pixel distance between detections and predictions, gates on depth,
// area, perimeter and distance, a tentative / confirmed / coasting life cycle, range smoothing with
// the fading-memory filter and a straight-line time to collision. Derivations: README.md.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "core/common/fields.h"
#include "core/detection/detection.h"
#include "core/tracking/fading_filter.h"
#include "core/tracking/hungarian.h"
#include "core/tracking/kalman.h"

namespace stevi::tracking {

// A detection and a track are paired only when every gate passes (README.md, "Assignment and
// gates"). A ratio gate compares the larger of two values with the smaller; a value <= 0 on either
// side (unknown) passes it. To disable a gate, make it very large (but finite).
struct GateOptions {
  // Hard cap on the detection depth against the track's predicted depth (depth ratio = disparity
  // ratio), >= 1. The depth gate proper is depth_sigmas below.
  double max_depth_ratio = 1.3;
  // Depth gate: |detection depth - predicted depth| <= depth_sigmas * sqrt(sigma_d^2 + P_zz), with
  // sigma_d the detection's depth sigma (from range_sigma_m) floored at min_depth_sigma_fraction
  // of its depth and P_zz the variance of the track's predicted depth. > 0.
  double depth_sigmas = 3.0;
  // Floor of a detection's depth sigma as a fraction of its depth, >= 0: the disparity's own
  // spread understates a blob's error (a fragment, a cut blob, a mixed median).
  double min_depth_sigma_fraction = 0.05;
  // Position gate: the detection's box must overlap the track's predicted box (its full size at
  // the predicted centre) grown by this many sigmas of the predicted centre on each side, > 0. The
  // box follows the prediction's covariance, which grows while a track coasts.
  double position_sigmas = 3.0;
  // Detection area against the track's last measured area (pixels^2 ratio), >= 1. Applied only
  // to a detection larger than the last one, on a track measured in the previous frame, neither
  // cut: a smaller blob is a partial view (a fragment, a partly hidden obstacle), not another
  // obstacle.
  double max_area_ratio = 3.0;
  // Detection perimeter against the track's last measured perimeter, >= 1 (as max_area_ratio).
  double max_perimeter_ratio = 2.5;
  // Distance (pixels) between the detection's centre (re-anchored when its size differs from the
  // track's) and the track's predicted centre, > 0.
  double max_distance_px = 80;

  std::vector<std::string> Validate() const;
  bool operator==(const GateOptions&) const = default;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(
        s.max_depth_ratio,
        Field("max_depth_ratio", "", "hard cap on the depth ratio to the prediction").AtLeast(1));
    v.Number(s.max_area_ratio,
             Field("max_area_ratio", "", "area ratio to the last; larger blobs only, unless cut")
                 .AtLeast(1));
    v.Number(s.max_perimeter_ratio,
             Field("max_perimeter_ratio", "",
                   "perimeter ratio to the last; larger blobs only, unless cut")
                 .AtLeast(1));
    v.Number(s.max_distance_px,
             Field("max_distance_px", "pixels", "predicted centre to detection centre").Above(0));
    v.Number(s.depth_sigmas,
             Field("depth_sigmas", "", "depth gate in sigmas of detection and prediction")
                 .Above(0)
                 .AtMost(100));
    v.Number(s.min_depth_sigma_fraction, Field("min_depth_sigma_fraction", "",
                                               "floor of a detection's depth sigma over its depth")
                                             .In(0, 1));
    v.Number(s.position_sigmas,
             Field("position_sigmas", "", "predicted box grown by this many sigmas of its centre")
                 .Above(0)
                 .AtMost(100));
  }
};

struct TrackerOptions {
  KalmanOptions kalman;
  GateOptions gates;
  // M-of-N confirmation: a tentative track becomes confirmed when it has confirm_hits (M) hits
  // (updates with a detection) within its last confirm_window (N) updates, counting the one that
  // created it; 1 <= M <= N <= 64. The defaults M = 3, N = 5 are exactly the rule "3 hits in all"
  // with tentative_delete_misses = 2: a tentative track never misses twice in a row, so its third
  // hit comes by its fifth update at the latest (in general, within 1 + (M - 1) K updates for
  // tentative_delete_misses K). A smaller N asks for denser evidence: M = 3, N = 4 does not
  // confirm a track seen every other frame.
  int confirm_hits = 3;
  int confirm_window = 5;
  // A tentative track is deleted at this many consecutive misses, 1..delete_misses. 2 lets it
  // survive one dropped detection (detectors recognise 60-80 % of obstacles per frame) while
  // clutter dies within two frames.
  int tentative_delete_misses = 2;
  // A confirmed track is deleted at this many consecutive misses, >= 1. Until then it coasts on
  // its prediction: 15 frames carry an obstacle through an occlusion of 14 frames.
  int delete_misses = 15;
  // Memory of the range smoothing (fading_filter.h), in (0, 1].
  double fading_beta = 0.7;
  // Detections scoring below this (0..1) are ignored: they neither update nor start tracks.
  // 0 takes every detection.
  double min_score = 0.0;
  // Frame intervals longer than this (seconds, > 0) are predicted as this long: a stalled source
  // or a clock jump must not fling the predictions away (the gates then decide).
  double max_dt_s = 1.0;
  // Two tracks whose boxes overlap at this IoU or more, at depths consistent within the depth gate,
  // are one obstacle: the younger is merged into the older, in (0, 1].
  double merge_iou = 0.5;

  // Every problem, as "field: problem" ("gates.max_depth_ratio: must be >= 1 (got 0.5)").
  std::vector<std::string> Validate() const;
  bool operator==(const TrackerOptions&) const = default;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Nested(s.kalman, Field("kalman"));
    v.Nested(s.gates, Field("gates"));
    v.Number(s.confirm_hits, Field("confirm_hits", "", "hits to confirm a track").AtLeast(1));
    // At least confirm_hits: checked in Validate().
    v.Number(
        s.confirm_window,
        Field("confirm_window", "updates",
              "confirm_hits must fall within a track's last this many updates; >= confirm_hits")
            .In(1, 64));
    // At most delete_misses: checked in Validate().
    v.Number(s.tentative_delete_misses,
             Field("tentative_delete_misses", "",
                   "misses that delete a tentative track; <= delete_misses")
                 .AtLeast(1));
    v.Number(s.delete_misses,
             Field("delete_misses", "", "misses that delete a confirmed track").AtLeast(1));
    v.Number(s.fading_beta, Field("fading_beta", "", "range smoothing memory").Above(0).AtMost(1));
    v.Number(
        s.min_score,
        Field("min_score", "", "detections scoring below this are ignored; 0 takes all").In(0, 1));
    v.Number(s.max_dt_s, Field("max_dt_s", "s", "longest prediction step").Above(0));
    v.Number(
        s.merge_iou,
        Field("merge_iou", "", "box overlap (IoU) at which two tracks merge").Above(0).AtMost(1));
  }
};

enum class TrackState {
  kTentative,  // not yet confirm_hits hits within confirm_window updates
  kConfirmed,  // measured this frame
  kCoasting,   // confirmed, not measured this frame: the state is predicted
};

std::string_view TrackStateName(TrackState state);

// One live track after an update. Positions and velocities are in the cam frame, relative to the
// camera.
struct Track {
  std::uint64_t id = 0;  // from 1, strictly increasing, never reused by a Tracker
  TrackState state = TrackState::kTentative;
  int age_frames = 0;  // updates since creation, counting the creating one
  int hits = 0;        // updates with a detection
  int misses = 0;      // consecutive updates without one
  // The last detection. When it is not from this frame, bbox and centroid_px are moved to the
  // predicted centre (same size); the other fields are those of the last detection.
  detection::Detection detection;
  cv::Vec3d position_cam_m;    // filtered (Kalman)
  cv::Vec3d velocity_cam_mps;  // filtered (Kalman)
  // 1-sigma of each cam axis from the filter's covariance (the diagonal; depth noise lies along
  // the viewing ray, so off-axis x and y share some of it).
  cv::Vec3d position_sigma_m;
  cv::Vec3d velocity_sigma_mps;
  double range_m = 0;           // raw: the last detection's range
  double smoothed_range_m = 0;  // fading filter, predicted to this frame when not measured
  double range_rate_mps = 0;    // d|p|/dt of the Kalman state; negative = closing
  // 1-sigma of range_rate_mps from the velocity covariance along the line of sight: large while a
  // track is young, so a consumer can tell a measured approach from velocity noise.
  double range_rate_sigma_mps = 0;
  // Straight-line extrapolation of the filtered relative position p and velocity v: the time of
  // the closest approach t* = -p.v / |v|^2 (seconds from this frame) and the miss distance
  // |p + v t*| (metres). Set only for a closing obstacle: t* > 0 and a range rate below minus
  // twice its own 1-sigma (a hovering obstacle's velocity noise is not an approach). Whether it is
  // a collision is for the caller to judge from closest_approach_m and the vehicle's size.
  std::optional<double> time_to_collision_s;
  std::optional<double> closest_approach_m;
};

// The camera's own motion since the previous update, from the vehicle's poses at the two frames and
// the camera's mount (core/pipeline: Pipeline::Finish): a point fixed in the world that was at p in
// the previous frame's cam frame is at cam_now_from_cam_prev * p in this frame's.
struct EgoMotion {
  Eigen::Isometry3d cam_now_from_cam_prev = Eigen::Isometry3d::Identity();
};

// Thread-compatible: call Update() from one thread at a time.
class Tracker {
 public:
  // The options must be valid (call Validate() first); invalid options are a programming error
  // (std::invalid_argument listing the problems).
  explicit Tracker(TrackerOptions options = {});

  // Tracks the detections of one frame captured at `t_ns` (any monotonic clock, nanoseconds) and
  // returns every live track (tentative, confirmed, coasting) in increasing id order. The time step
  // is the real interval since the previous update (0 for a repeated or earlier timestamp, at most
  // max_dt_s). Detections without a finite position in front of the camera are ignored. The camera
  // must be valid (else std::invalid_argument).
  //
  // With `ego` (the camera's motion since the previous update), every track is first carried into
  // this frame's cam frame (a static obstacle's prediction lands where it is seen now), and the
  // filters' velocities are over the ground: a new track starts at rest in the world, and a static
  // obstacle keeps a zero velocity while the camera drives or turns. The published velocity,
  // range rate and time to collision stay relative to the camera (README.md, "Ego-motion").
  // Without it, the velocities are relative to the camera, as the thesis's; an update without
  // ego-motion after one with it converts them back with the camera's last motion.
  std::vector<Track> Update(const std::vector<detection::Detection>& detections, int64_t t_ns,
                            const CameraModel& camera,
                            const std::optional<EgoMotion>& ego = std::nullopt);

  // Drops every track and the time reference. Ids keep increasing: an id is never reused.
  void Reset();

  // Replaces the options between updates, keeping the tracks (std::invalid_argument if invalid).
  // Existing tracks keep the fading_beta they started with.
  void SetOptions(TrackerOptions options);
  const TrackerOptions& options() const { return options_; }

  // The id the next new track will get.
  std::uint64_t next_id() const { return next_id_; }

 private:
  struct Entry {
    std::uint64_t id = 0;
    TrackState state = TrackState::kTentative;
    int age_frames = 0;
    int hits = 0;
    int misses = 0;
    // Bit k: the update k updates ago (0 = this one) had a detection.
    std::uint64_t hit_history = 1;
    detection::Detection last;      // the last detection, as measured
    ConstantVelocityKalman kalman;  // on s = (a, b, z): see MeasureAngleDepth
    FadingMemoryFilter range_filter;
    double since_measured_s = 0;  // (clamped) time since the last detection
    // The obstacle's whole size in the image, at depth full_depth_m, and its centroid's offset from
    // the box centre, from the last detection that nothing cut and whose size agreed with the
    // track's: a blob whose size differs (cut, partly hidden, merged with another) is centred from
    // its edge that agrees with the prediction, with this size.
    cv::Size2d full_size;
    double full_depth_m = 0;
    cv::Point2d centroid_offset;
    bool last_cut = false;  // the last detection was cut (its area and perimeter are partial)
    // Born inside another track's box at a depth that track rules out (a fragment that took its
    // disparity from something else, or a nearer obstacle): deleted at its first miss while
    // tentative.
    bool child = false;
    cv::Rect box;  // the box reported this frame
    // Measured this frame in position only (from a blob shared with a nearer obstacle, whose
    // depth is the other's): depth and range are reported from the filter, not the blob.
    bool position_only = false;
  };

  // Which sides of a detection are cut by a nearer detection or by the image border.
  struct Cut {
    bool left = false, right = false, top = false, bottom = false;
    bool any() const { return left || right || top || bottom; }
  };
  // A track predicted to this frame, for gating and the update.
  struct Prediction {
    ConstantVelocityKalman kalman;    // predicted with the measured process noise
    double u = 0, v = 0;              // predicted centre, pixels
    double sigma_u = 0, sigma_v = 0;  // its 1-sigma, pixels
    double z = 0, var_z = 0;          // predicted depth (metres) and its variance
    cv::Size2d size;                  // the full size expected at depth z
    bool valid = false;               // in front of the camera
  };
  // The centre a detection gives a track, and the variance of that centre on u and v (px^2).
  struct Measured {
    cv::Point2d centre;
    double var_u = 0, var_v = 0;
    bool anchored = false;  // the size differed: centred from the edge that agrees
  };
  void FindCuts(const std::vector<detection::Detection>& detections, const CameraModel& camera);
  Prediction Predict(const Entry& entry, double dt, const CameraModel& camera) const;
  // The detection's centre as the track sees it: its centroid when its size agrees with the
  // track's; else the centre of the full box on its edge that agrees with the prediction (or that
  // nothing cuts).
  // `merged`: the detection covers several tracks' predicted boxes.
  Measured Measure(const Entry& entry, const Prediction& p, const detection::Detection& d,
                   const Cut& cut, bool merged) const;
  bool DepthConsistent(const Prediction& p, const detection::Detection& d) const;
  static cv::Rect PredictedBox(const Prediction& p, double grow_u, double grow_v);
  void Correct(Entry& entry, const Prediction& p, const detection::Detection& d, const Cut& cut,
               bool merged, const CameraModel& camera);

  Entry NewEntry(const detection::Detection& detection, const CameraModel& camera);
  Track Output(const Entry& entry, const CameraModel& camera) const;

  // The stages of Update(), in order. The interval since the previous update (clamped to
  // [0, max_dt_s]), remembering t_ns.
  double TimeStep(int64_t t_ns);
  // The velocity field a camera motion gives the static points, in the cam frame: a point at p
  // seems to move at linear * p + offset (m/s). From the motion's logarithm (its twist over dt), so
  // that it is the same field before and after the motion, and exact for a constant turn.
  struct ApparentMotion {
    Eigen::Matrix3d linear;
    Eigen::Vector3d offset;
  };
  static ApparentMotion ApparentMotionOf(const Eigen::Isometry3d& cam_now_from_cam_prev, double dt);
  // Every track carried through the camera's motion over dt into this frame's cam frame, with its
  // velocity over the ground (converted from relative when it was).
  void ApplyEgoMotion(const EgoMotion& ego, double dt);
  // Every track's velocity from over the ground back to relative to the camera, with the camera's
  // motion of the last ego-motion update.
  void ToRelativeVelocity();
  // Hits within the last confirm_window updates reach confirm_hits.
  bool ConfirmedByHits(const Entry& e) const;
  // usable_: the detections that can be tracked.
  void SelectUsable(const std::vector<detection::Detection>& detections);
  // predictions_: every track predicted by dt.
  void PredictTracks(double dt, const CameraModel& camera);
  // merged_: how many confirmed tracks' predicted boxes each usable detection covers.
  void CountMerges(const std::vector<detection::Detection>& detections);
  // allowed_ (the pairs inside every gate, with their cost), the assignment track_to_detection_
  // and detection_used_.
  void Associate(const std::vector<detection::Detection>& detections);
  // The cost of pairing track `e` with usable detection `k` (`d`) whose box is in the position
  // gate; nullopt when a gate (depth, distance, area, perimeter) forbids the pair.
  std::optional<double> PairCost(const Entry& e, const Prediction& p, const detection::Detection& d,
                                 int k) const;
  // Each track: measured by its detection, in position only by a blob it shares, or coasting.
  void UpdateTracks(const std::vector<detection::Detection>& detections, double dt,
                    const CameraModel& camera);
  void UpdateMeasured(Entry& e, const Prediction& p, const detection::Detection& d, int k,
                      const CameraModel& camera);
  // The usable detection wider than the track that covers half its predicted box or more, with its
  // left or right edge where the prediction's is (the closest wins); -1 when there is none.
  int FindSharedBlob(const Prediction& p,
                     const std::vector<detection::Detection>& detections) const;
  // Track t measured in position only in usable detection k, a blob another track may have taken.
  void UpdatePositionOnly(int t, int k, const std::vector<detection::Detection>& detections,
                          const CameraModel& camera);
  // No detection: free prediction with the occlusion noises.
  void Coast(Entry& e, double dt, const CameraModel& camera);
  // New tracks from the detections no track took that are not fragments of the first num_tracks
  // tracks (the tracks that were predicted).
  void StartTracks(const std::vector<detection::Detection>& detections, int num_tracks,
                   const CameraModel& camera);
  // Two tracks on one obstacle: boxes that overlap (merge_iou, or one mostly inside the other)
  // and depths consistent within the depth gate.
  bool SameObstacle(const Entry& a, const Entry& b) const;
  // Merges the younger of two tracks on one obstacle into the older (id 0 marks it merged).
  void MergeTracks();
  // Merged, missed too often, or predicted wholly out of the image.
  bool Expired(const Entry& e, const CameraModel& camera) const;

  TrackerOptions options_;
  std::vector<Entry> tracks_;
  std::uint64_t next_id_ = 1;
  std::optional<int64_t> last_t_ns_;
  // The filters' velocities are over the ground (the last update had ego-motion), not relative to
  // the camera. The camera's last motion as the velocity field it gives a static point at p:
  // apparent_linear_ * p + apparent_offset_ (m/s, ApparentMotionOf).
  bool ground_velocity_ = false;
  Eigen::Matrix3d apparent_linear_ = Eigen::Matrix3d::Zero();
  Eigen::Vector3d apparent_offset_ = Eigen::Vector3d::Zero();

  // Per-update buffers, kept to avoid reallocating every frame.
  std::vector<int> usable_;              // indices of the detections that can be tracked
  std::vector<AllowedPair> allowed_;     // (track, index into usable_, pixel distance) in gates
  std::vector<int> track_to_detection_;  // index into usable_, or -1
  std::vector<char> detection_used_;
  std::vector<Cut> cuts_;                // per usable detection
  std::vector<Prediction> predictions_;  // per track
  std::vector<int> merged_;              // per usable detection: tracks' boxes it covers
  AssignmentSolver solver_;
};

}  // namespace stevi::tracking
