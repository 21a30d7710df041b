// Real stereo pairs with ground truth from the shared reference data (data.h): the Middlebury
// 2001/2003/2014 pairs and the KITTI 2015 pairs, with their truth disparity, evaluation mask and
// rig; and the error of a disparity map against that truth. Used by middlebury_test,
// real_pairs_test and stevi-eval-real.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/stereo/disparity.h"

namespace stevi::testing {

struct RealPair {
  std::string name;    // "tsukuba", "motorcycle", "kitti-000005_10"
  std::string folder;  // the pair's folder (absolute, under the data directory)
  bool kitti = false;
  cv::Mat1b left, right;  // rectified, grey (read with IMREAD_GRAYSCALE)
  cv::Mat1f truth_px;     // disparity of the left view, pixels; 0 = unknown
  // 255 where the truth is known and, for the sets that give one, the non-occlusion mask says the
  // pixel is seen by both cameras (KITTI has no such mask: known only).
  cv::Mat1b evaluated;
  bool nonocc_mask = false;
  // The rectified rig. Middlebury 2001/2003 give none: f is then nominal (the image width) and the
  // baseline 0.1 m, which is enough for the disparity, not for depth. Middlebury 2014 has doffs
  // (the principal points differ): Z = f B / (d + doffs); KITTI has doffs 0.
  bool rig_known = false;
  double f_px = 0, baseline_m = 0, cx = 0, cy = 0, doffs = 0;
};

// The classic Middlebury quartet (tsukuba, venus, teddy, cones), plus the 2014 motorcycle.
std::vector<std::string> MiddleburyPairNames(bool with_2014);
// KITTI 2015: the 3 training pairs (truth disp_occ_0) and the 2 "more" pairs (truth disp_gt).
std::vector<std::string> KittiPairNames();

// Loads one named pair from `data_dir`; on failure returns nullopt and says why in `problem`
// (the missing file, or an unknown name).
std::optional<RealPair> LoadRealPair(const std::string& data_dir, const std::string& name,
                                     std::string& problem);

// Loads every named pair; empty (with `problem`) when any is missing.
std::vector<RealPair> LoadRealPairs(const std::string& data_dir,
                                    const std::vector<std::string>& names, std::string& problem);

// Reads a PFM (float, one channel, rows stored bottom to top); empty on error.
cv::Mat1f ReadPfm(const std::string& path);

// The truth on the grid of an image binned by `binning` (geometry::BinImage: block (j, i) covers
// camera pixels binning*j .. binning*j + binning - 1): each block's truth is the median of its
// evaluated camera pixels' truth (camera pixels, not divided), and the block is evaluated when at
// least half of its pixels are. binning 1 returns the pair's own truth and mask.
void TruthOnGrid(const RealPair& pair, int binning, cv::Mat1f& truth_px, cv::Mat1b& evaluated);

// Disparity error over the evaluated pixels of the compared grid, in camera pixels.
struct DisparityScore {
  long evaluated = 0, matched = 0;
  // Raw: an unmatched pixel is bad. Matched: over matched pixels only.
  long bad1_raw = 0, bad3_raw = 0, d1_raw = 0;
  long bad1_matched = 0, bad3_matched = 0, d1_matched = 0;
  double abs_sum_matched = 0;  // sum of |d - truth| over matched pixels
  double abs_sum_raw = 0;      // ... plus the truth itself for each unmatched one (d taken as 0)

  double MatchedPct() const { return Pct(matched, evaluated); }
  double Bad1RawPct() const { return Pct(bad1_raw, evaluated); }
  double Bad3RawPct() const { return Pct(bad3_raw, evaluated); }
  double D1RawPct() const { return Pct(d1_raw, evaluated); }
  double Bad1MatchedPct() const { return Pct(bad1_matched, matched); }
  double Bad3MatchedPct() const { return Pct(bad3_matched, matched); }
  double D1MatchedPct() const { return Pct(d1_matched, matched); }
  double MaeMatched() const { return matched ? abs_sum_matched / matched : 0.0; }
  double MaeRaw() const { return evaluated ? abs_sum_raw / evaluated : 0.0; }

 private:
  static double Pct(long n, long of) { return of ? 100.0 * n / of : 0.0; }
};

// Scores `disparity` (the processed images' grid, binned by `binning` from the pair's) against the
// pair's truth on that grid (TruthOnGrid): the map's disparity is multiplied by `binning`, so every
// error is in camera pixels. bad1 / bad3: |error| > 1 / 3 px. d1: KITTI's D1 outlier, |error| > 3
// px and > 5 % of the truth.
DisparityScore ScoreDisparity(const stereo::DisparityMap& disparity, int binning,
                              const RealPair& pair);

}  // namespace stevi::testing
