#include "core/detection/regions.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <string>

#include <opencv2/imgproc.hpp>

#include "core/detection/patch_refinement.h"
#include "core/detection/surface_filters.h"
#include "core/extraction/blobs.h"

namespace stevi::detection {
namespace {

constexpr int kScale = stereo::DisparityMap::kScale;
// Disparity histogram bins of the depth-mode search: a quarter pixel (fixed-point units).
constexpr int kBinFixed = kScale / 4;
// A region piece needs this many trusted disparities to be ranged at all (it may still join
// others at its range to make a hypothesis).
constexpr int kMinPieceDisparities = 3;
// Trusted disparities of one appearance region this close (pixels at 640 px wide) link into one
// piece, so that a sparsely matched object holds together.
constexpr int kLinkSize640 = 7;
// A depth mode smaller than this fraction of its region's trusted disparities is an outlier
// (mismatches, a halo), not an object of its own.
constexpr double kMinModeFraction = 0.1;
// The sub-pixel bias of a block matcher's disparities (pixel locking), pixels: two medians closer
// than this cannot be told apart.
constexpr double kMatcherBiasPx = 0.1;
// Blobs shorter than this (rows, at 640 px wide) are never given the slope test: too few rows.
constexpr int kMinTerrainRows640 = 12;
// Hypotheses whose disparity's 1-sigma exceeds this fraction of it (7 % of the range) are dropped:
// their range says little. Below it the range is kept with its honest sigma; a bound of 3.5 % lost
// obstacles on the tuning seeds (aircraft at 3-4 px) and no false positives
// (core/detection/README.md, "Measured").
constexpr double kMaxRelativeDisparitySigma = 0.07;
// Hypotheses within this many pixels of the top of the matcher's search range are dropped.
constexpr double kSearchTopMarginPx = 2.0;

struct Piece {
  cv::Rect box;
  int area = 0;
  double sum_x = 0, sum_y = 0;
  std::vector<int16_t> disparities;  // fixed point, the mode's trusted disparities
  int median = 0, lo = 0, hi = 0;    // fixed point: median, 10th and 90th percentiles
  double median_sigma = 0;           // fixed point: 1-sigma of the median
  int region = 0;                    // the appearance region it lies in (0: not asked for)
};

// The 10th, 50th and 90th percentiles of fixed-point disparities, by counting (exact).
std::array<int, 3> Percentiles(const std::vector<int16_t>& v) {
  int lo = INT16_MAX, hi = 0;
  for (int16_t d : v) {
    lo = std::min<int>(lo, d);
    hi = std::max<int>(hi, d);
  }
  thread_local std::vector<int> counts;
  counts.assign(hi - lo + 1, 0);
  for (int16_t d : v) ++counts[d - lo];
  const int n = static_cast<int>(v.size());
  const std::array<int, 3> rank = {(n - 1) / 10, (n - 1) / 2, (9 * (n - 1)) / 10};
  std::array<int, 3> out = {lo, lo, lo};
  int seen = 0, k = 0;
  for (int i = 0; i < static_cast<int>(counts.size()) && k < 3; ++i) {
    seen += counts[i];
    while (k < 3 && seen > rank[k]) out[k++] = lo + i;
  }
  return out;
}

// `block_px`: the matcher's window, over which its errors are correlated.
void Summarise(Piece& p, int block_px) {
  const std::array<int, 3> q = Percentiles(p.disparities);
  p.lo = q[0];
  p.median = q[1];
  p.hi = q[2];
  // The spread from the 10th to the 90th percentile is 2.563 sigma for a normal scatter; the
  // median of n independent values has 1.2533 sigma / sqrt(n). A block matcher's neighbouring
  // disparities share most of their window: about one independent value per half-window square.
  const double independent = std::max(
      1.0, static_cast<double>(p.disparities.size()) / std::max(1.0, 0.25 * block_px * block_px));
  p.median_sigma = 1.2533 * std::max(p.hi - p.lo, 1) / 2.563 / std::sqrt(independent);
}

// The depth modes of a region's trusted disparities: runs of the quarter-pixel histogram separated
// by at least `gap_bins` empty bins. Returns, per mode, its [first, last] bin; modes holding less
// than kMinModeFraction of the values are dropped.
std::vector<std::pair<int, int>> DepthModes(const std::vector<int>& histogram, int n,
                                            int gap_bins) {
  std::vector<std::pair<int, int>> modes;
  int start = -1, last = -1, count = 0;
  const auto close = [&]() {
    if (start >= 0 &&
        count >= std::max(kMinPieceDisparities, static_cast<int>(kMinModeFraction * n))) {
      modes.emplace_back(start, last);
    }
  };
  for (int b = 0; b < static_cast<int>(histogram.size()); ++b) {
    if (histogram[b] == 0) continue;
    if (start >= 0 && b - last > gap_bins) {
      close();
      start = -1;
      count = 0;
    }
    if (start < 0) start = b;
    last = b;
    count += histogram[b];
  }
  close();
  return modes;
}

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

int ScaledKernel(int size_at_640, int width_px) {
  if (size_at_640 <= 1) return 1;
  const int k = static_cast<int>(std::lround(size_at_640 * width_px / 640.0));
  return std::max(1, k | 1);
}

cv::Mat1b ClassifyPixels(const stereo::DisparityMap& disparity, const geometry::StereoRig& rig,
                         const geometry::RangeOptions& range,
                         const std::optional<GroundModel>& ground,
                         const GroundOptions& ground_options) {
  const cv::Mat1s& fixed = disparity.fixed;
  cv::Mat1b out(fixed.size(), uchar{kNoDisparity});
  const double fb = rig.f_px() * rig.baseline_m();
  double floor_px = range.min_disparity_px;
  if (range.max_range_m > 0) floor_px = std::max(floor_px, fb / range.max_range_m);
  const int floor_fixed = static_cast<int>(std::ceil(floor_px * kScale - 1e-9));
  for (int y = 0; y < fixed.rows; ++y) {
    const int16_t* d = fixed[y];
    uchar* o = out[y];
    const double ground_d = ground ? ground->DisparityAt(y) : 0.0;
    const double above_fixed =
        ground ? (ground_d +
                  std::max(ground_options.margin_px, ground_options.margin_fraction * ground_d)) *
                     kScale
               : -1.0;
    for (int x = 0; x < fixed.cols; ++x) {
      if (d[x] < 0) continue;
      if (d[x] < floor_fixed) {
        o[x] = kFar;
      } else {
        o[x] = d[x] <= above_fixed ? kGround : kCandidate;
      }
    }
  }
  return out;
}

// The appearance region a detection's group lies in (0: none, -1: several) and the group's label.
struct RegionOf {
  int region = 0;
  int group = 0;
};

// Step 4 of RangeRegions: a detection alone in its region, where no other trusted disparity (of
// another group, or of the ground) lies, takes the region's box. A few stray disparities
// (kStrayShare of the detection's own) do not stop it.
void ExtendToRegions(const cv::Mat1i& region_labels, const cv::Mat1i& region_stats,
                     const cv::Mat1i& group_labels, const cv::Mat1b& classes,
                     const std::vector<RegionOf>& region_of, std::vector<Detection>& detections) {
  constexpr double kStrayShare = 0.05;
  std::vector<int> per_region(static_cast<size_t>(region_stats.rows), 0);
  for (const RegionOf& r : region_of) {
    if (r.region > 0) ++per_region[static_cast<size_t>(r.region)];
  }
  for (size_t i = 0; i < detections.size(); ++i) {
    const int r = region_of[i].region;
    if (r <= 0 || per_region[static_cast<size_t>(r)] != 1) continue;
    const cv::Rect box(region_stats(r, cv::CC_STAT_LEFT), region_stats(r, cv::CC_STAT_TOP),
                       region_stats(r, cv::CC_STAT_WIDTH), region_stats(r, cv::CC_STAT_HEIGHT));
    int own = 0, other = 0;
    for (int y = box.y; y < box.br().y; ++y) {
      const int* region = region_labels[y];
      const int* group = group_labels[y];
      const uchar* c = classes[y];
      for (int x = box.x; x < box.br().x; ++x) {
        if (region[x] != r) continue;
        if (group[x] == region_of[i].group) {
          ++own;
        } else if (c[x] == kCandidate || c[x] == kGround) {
          ++other;
        }
      }
    }
    if (other > kStrayShare * own) continue;
    Detection& d = detections[i];
    d.bbox |= box;
    d.perimeter_px = 2.0 * (d.bbox.width + d.bbox.height);
    d.valid_fraction =
        std::clamp(static_cast<double>(d.valid_disparities) / d.bbox.area(), 0.0, 1.0);
  }
}

namespace {

// RangeRegions' inputs, passed to its steps.
struct RegionsContext {
  const cv::Mat1b& appearance;
  const cv::Mat1b& classes;
  const stereo::DisparityMap& disparity;
  const geometry::StereoRig& rig;
  const geometry::RangeOptions& range;
  const StereoBlobOptions& options;
  std::string_view extractor;
  const std::optional<GroundModel>& ground;
  const FullResolutionPair* full;
  int width, height;
};

// Step 1a: the appearance cue's pixels with a trusted disparity standing out from the ground
// (`candidates`), and the appearance pixels near a candidate (within kLinkSize640), which take the
// nearest surface's disparity (a grey dilation) in `linked_disparity` so that a sparsely matched
// object holds together; `linked` marks both.
void LinkAppearance(const RegionsContext& ctx, cv::Mat1b& candidates, cv::Mat1s& linked_disparity,
                    cv::Mat1b& linked) {
  const cv::Mat1b& classes = ctx.classes;
  const cv::Mat1b& appearance = ctx.appearance;
  const cv::Mat1s& fixed = ctx.disparity.fixed;
  const int width = ctx.width;
  thread_local cv::Mat1s grown;
  // (Whole-image steps are OpenCV's vectorised operations.)
  cv::compare(classes, static_cast<double>(kCandidate), candidates, cv::CMP_EQ);
  cv::bitwise_and(candidates, appearance, candidates);  // appearance is 0 or not: 255 & a
  cv::compare(candidates, 0, candidates, cv::CMP_NE);
  linked_disparity.create(fixed.size());
  linked_disparity.setTo(stereo::DisparityMap::kInvalid);
  fixed.copyTo(linked_disparity, candidates);
  const int link = ScaledKernel(kLinkSize640, width);
  cv::dilate(linked_disparity, grown,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(link, link)));
  // The appearance pixels that are not candidates take the grown disparity where there is one.
  thread_local cv::Mat1b grow;
  cv::compare(grown, 0, grow, cv::CMP_GE);
  cv::bitwise_and(grow, appearance, grow);
  cv::compare(grow, 0, grow, cv::CMP_NE);
  cv::bitwise_and(grow, ~candidates, grow);
  grown.copyTo(linked_disparity, grow);
  cv::compare(linked_disparity, 0, linked, cv::CMP_GE);
}

// A blob's histogram of its candidates' disparities, in quarter-pixel bins, for every blob of
// step 1b's blobs at once (whole-image passes: a blob's box overlaps others').
struct BlobHistograms {
  std::vector<int> blob_of;    // label -> blob (-1: dropped)
  int bins = 0;                // bins per blob
  std::vector<int> histogram;  // blob b's bins from b * bins
  std::vector<int> counts;     // per blob: its candidates
};

BlobHistograms HistogramBlobs(const RegionsContext& ctx, const extraction::BlobSet& blobs,
                              const cv::Mat1b& candidates) {
  const stereo::DisparityMap& disparity = ctx.disparity;
  const cv::Mat1s& fixed = disparity.fixed;
  const int width = ctx.width, height = ctx.height;
  BlobHistograms h;
  h.blob_of.assign(std::max(1, blobs.label_count), -1);
  for (size_t i = 0; i < blobs.blobs.size(); ++i)
    h.blob_of[blobs.blobs[i].label] = static_cast<int>(i);
  const size_t blob_count = blobs.blobs.size();
  int top_px = disparity.min_disparity + disparity.num_disparities;
  if (disparity.num_disparities <= 0) {  // a map that does not say its search range
    double top = 0;
    cv::minMaxLoc(fixed, nullptr, &top);
    top_px = static_cast<int>(top) / kScale;
  }
  const int bins = (std::max(1, top_px) + 1) * kScale / kBinFixed + 1;
  h.bins = bins;
  h.histogram.assign(blob_count * bins, 0);
  h.counts.assign(blob_count, 0);
  for (int y = 0; y < height; ++y) {
    const int* lab = blobs.labels[y];
    const uchar* c = candidates[y];
    const int16_t* d = fixed[y];
    for (int x = 0; x < width; ++x) {
      if ((lab[x] == 0) | (c[x] == 0)) continue;
      const int b = h.blob_of[lab[x]];
      if (b < 0) continue;
      ++h.histogram[static_cast<size_t>(b) * bins + std::min(bins - 1, d[x] / kBinFixed)];
      ++h.counts[b];
    }
  }
  return h;
}

// Each blob's depth modes, one piece each, appended to `pieces`. Returns, per bin of every blob's
// histogram, the piece of its mode (0: no mode).
std::vector<int> PiecesOfModes(const StereoBlobOptions& options, const BlobHistograms& h,
                               std::vector<Piece>& pieces) {
  const int bins = h.bins;
  const int gap_bins = std::max(
      1, static_cast<int>(std::lround(options.max_disparity_step_px * kScale / kBinFixed)));
  std::vector<int> piece_of_bin(h.histogram.size(), 0);
  std::vector<int> blob_histogram;
  for (size_t b = 0; b < h.counts.size(); ++b) {
    const int n = h.counts[b];
    if (n < kMinPieceDisparities) continue;
    blob_histogram.assign(h.histogram.begin() + b * bins, h.histogram.begin() + (b + 1) * bins);
    // Bins holding fewer than 1 % of the values are empty: a sparse bridge is no mode.
    const int sparse = std::max(1, n / 100);
    for (int& v : blob_histogram) v = v >= sparse ? v : 0;
    std::vector<std::pair<int, int>> modes;
    if (options.max_disparity_step_px > 0) {
      modes = DepthModes(blob_histogram, n, gap_bins);
    } else {
      modes = {{0, bins - 1}};
    }
    for (const auto& [first, last] : modes) {
      pieces.emplace_back();
      for (int k = first; k <= last; ++k)
        piece_of_bin[b * bins + k] = static_cast<int>(pieces.size()) - 1;
    }
  }
  return piece_of_bin;
}

// Each linked pixel goes to the piece of the mode of the disparity it took (its area and
// centroid); a candidate also gives the piece its box and disparity, and its label in
// `piece_labels`.
void LabelPieces(const RegionsContext& ctx, const extraction::BlobSet& blobs,
                 const BlobHistograms& h, const std::vector<int>& piece_of_bin,
                 const cv::Mat1b& candidates, const cv::Mat1s& linked_disparity,
                 const cv::Mat1i& region_labels, std::vector<Piece>& pieces,
                 cv::Mat1i& piece_labels) {
  const cv::Mat1s& fixed = ctx.disparity.fixed;
  const int width = ctx.width, height = ctx.height;
  const int bins = h.bins;
  std::vector<cv::Point> lo(pieces.size(), cv::Point(INT32_MAX, INT32_MAX));
  std::vector<cv::Point> hi(pieces.size(), cv::Point(-1, -1));
  piece_labels.create(fixed.size());
  for (int y = 0; y < height; ++y) {
    const int* lab = blobs.labels[y];
    const uchar* c = candidates[y];
    const int16_t* d = fixed[y];
    const int16_t* l = linked_disparity[y];
    int* out_label = piece_labels[y];
    for (int x = 0; x < width; ++x) {
      out_label[x] = 0;
      if (lab[x] == 0) continue;
      const int b = h.blob_of[lab[x]];
      if (b < 0) continue;
      // A linked pixel goes with the mode of the disparity it took.
      const int k =
          piece_of_bin[static_cast<size_t>(b) * bins + std::min(bins - 1, l[x] / kBinFixed)];
      if (k == 0) continue;
      Piece& p = pieces[k];
      // A piece lies in one region: its pixels are 8-connected appearance pixels.
      if (ctx.options.join_within_region && p.region == 0) p.region = region_labels(y, x);
      ++p.area;
      p.sum_x += x;
      p.sum_y += y;
      if (c[x] == 0) continue;
      // The box is the candidates': linking only holds them together.
      lo[k].x = std::min(lo[k].x, x);
      lo[k].y = std::min(lo[k].y, y);
      hi[k].x = std::max(hi[k].x, x);
      hi[k].y = std::max(hi[k].y, y);
      out_label[x] = k;
      p.disparities.push_back(d[x]);
    }
  }
  for (size_t k = 1; k < pieces.size(); ++k) {
    if (hi[k].x >= 0)
      pieces[k].box = cv::Rect(lo[k].x, lo[k].y, hi[k].x - lo[k].x + 1, hi[k].y - lo[k].y + 1);
  }
}

// Step 1b: the linked pixels joined as neighbours across disparity steps of at most
// max_disparity_step_px, each blob split where its candidates' disparities form separate depth
// modes: the pieces (index 0: nothing), summarised, with their labels in `piece_labels`. A piece's
// box and disparities are its candidates' (linking only holds them together).
std::vector<Piece> CutPieces(const RegionsContext& ctx, const cv::Mat1b& candidates,
                             const cv::Mat1s& linked_disparity, const cv::Mat1b& linked,
                             const cv::Mat1i& region_labels, cv::Mat1i& piece_labels) {
  const StereoBlobOptions& options = ctx.options;
  const int step_fixed =
      std::max(1, static_cast<int>(std::lround(options.max_disparity_step_px * kScale)));
  const extraction::BlobSet blobs =
      options.max_disparity_step_px > 0
          ? extraction::ExtractDisparityBlobs(linked, linked_disparity, step_fixed,
                                              kMinPieceDisparities,
                                              /*shapes=*/false)
          : extraction::ExtractBlobs(linked, kMinPieceDisparities);
  // Per blob: the quarter-pixel histogram of its candidates' disparities, its depth modes, and
  // each mode's piece.
  const BlobHistograms histograms = HistogramBlobs(ctx, blobs, candidates);
  std::vector<Piece> pieces(1);  // piece 0 = nothing
  const std::vector<int> piece_of_bin = PiecesOfModes(options, histograms, pieces);
  LabelPieces(ctx, blobs, histograms, piece_of_bin, candidates, linked_disparity, region_labels,
              pieces, piece_labels);
  const int piece_count = static_cast<int>(pieces.size());
  for (int i = 1; i < piece_count; ++i) {
    if (!pieces[i].disparities.empty()) Summarise(pieces[i], ctx.disparity.block_size);
  }

  return pieces;
}

// Step 2: pieces at one range join across gaps that scale with their size (within one appearance
// region, whatever their gap, when join_within_region). Returns the groups (index 0: nothing),
// their labels in `labels`.
std::vector<Piece> JoinPieces(const RegionsContext& ctx, const std::vector<Piece>& pieces,
                              const cv::Mat1i& piece_labels, cv::Mat1i& labels) {
  const StereoBlobOptions& options = ctx.options;
  const cv::Mat1s& fixed = ctx.disparity.fixed;
  const int width = ctx.width, height = ctx.height;
  const int piece_count = static_cast<int>(pieces.size());
  std::vector<int> parent(piece_count);
  std::iota(parent.begin(), parent.end(), 0);
  const double join_fraction = options.join_gap_fraction;
  if (join_fraction > 0 || options.join_within_region) {
    for (int i = 1; i < piece_count; ++i) {
      const Piece& a = pieces[i];
      if (a.disparities.size() < static_cast<size_t>(kMinPieceDisparities)) continue;
      for (int j = i + 1; j < piece_count; ++j) {
        const Piece& b = pieces[j];
        if (b.disparities.size() < static_cast<size_t>(kMinPieceDisparities)) continue;
        // The same range: the medians agree within three sigmas of their difference (plus the
        // matcher's sub-pixel bias), or each lies within the other's spread (the faces of a
        // deep object).
        const double tolerance =
            3.0 * std::hypot(a.median_sigma, b.median_sigma) + kMatcherBiasPx * kScale;
        const bool same_range =
            std::abs(a.median - b.median) <= tolerance ||
            (a.median >= b.lo && a.median <= b.hi && b.median >= a.lo && b.median <= a.hi);
        if (!same_range) continue;
        const int gap_x =
            std::max(0, std::max(a.box.x, b.box.x) - std::min(a.box.br().x, b.box.br().x));
        const int gap_y =
            std::max(0, std::max(a.box.y, b.box.y) - std::min(a.box.br().y, b.box.br().y));
        const int size = std::max({a.box.width, a.box.height, b.box.width, b.box.height});
        const bool one_region = a.region != 0 && a.region == b.region;
        // In one region, the gap is measured against the smaller piece: a region that holds a
        // large object and a small one at its range (a drone beside a hangar) is not one object.
        const int smaller =
            std::min(std::max(a.box.width, a.box.height), std::max(b.box.width, b.box.height));
        const double allowed =
            one_region ? (options.region_gap_fraction > 0 ? options.region_gap_fraction * smaller
                                                          : static_cast<double>(width + height))
                       : join_fraction * size;
        if (std::max(gap_x, gap_y) > allowed) continue;
        parent[Find(parent, i)] = Find(parent, j);
      }
    }
  }
  std::vector<int> group_of(piece_count, 0);
  std::vector<int> roots;
  for (int i = 1; i < piece_count; ++i) {
    if (pieces[i].area == 0) continue;
    const int root = Find(parent, i);
    if (group_of[root] == 0) {
      roots.push_back(root);
      group_of[root] = static_cast<int>(roots.size());
    }
    group_of[i] = group_of[root];
  }
  const int group_count = static_cast<int>(roots.size());
  std::vector<Piece> groups(group_count + 1);
  for (int i = 1; i < piece_count; ++i) {
    if (pieces[i].area == 0) continue;
    Piece& g = groups[group_of[i]];
    const Piece& p = pieces[i];
    g.region = g.area == 0 ? p.region : (g.region == p.region ? g.region : -1);
    g.box = g.area == 0 ? p.box : (g.box | p.box);
    g.area += p.area;
    g.sum_x += p.sum_x;
    g.sum_y += p.sum_y;
    g.disparities.insert(g.disparities.end(), p.disparities.begin(), p.disparities.end());
  }
  labels.create(fixed.size());
  for (int y = 0; y < height; ++y) {
    const int* p = piece_labels[y];
    int* g = labels[y];
    for (int x = 0; x < width; ++x) g[x] = group_of[p[x]];
  }

  return groups;
}

// Step 3's pixel sizes, scaled with the image.
struct GroupLimits {
  double max_width_px;
  int min_rows, ring_in, ring_out, interior;
};

// The range of a group from its pixels: the sub-pixel fit on the full-resolution pair when there
// is one (over the pixels at the group's own range), else the median of its interior when there is
// enough of it; `d` keeps the median's range otherwise.
void RangeFromPixels(const RegionsContext& ctx, const GroupLimits& limits, const Piece& group,
                     const cv::Mat1b& mask, double median_px, int n, Detection& d) {
  const FullResolutionPair* full = ctx.full;
  const cv::Mat1s& fixed = ctx.disparity.fixed;
  const cv::Mat1b& classes = ctx.classes;
  const int interior = limits.interior;
  bool refined_ok = false;
  if (full != nullptr && !full->left.empty()) {
    if (const std::optional<RefinedDisparity> refined =
            RefineOnFullPair(*full, fixed, classes, group.box, mask, median_px)) {
      d.disparity_px = refined->disparity_px;
      d.disparity_sigma_px = refined->sigma_px;
      refined_ok = true;
    }
  }
  if (!refined_ok && interior > 1) {
    // No fit: the median of the interior when there is enough of it (block matching spreads an
    // object's disparity a few pixels past its borders).
    std::vector<int16_t> inner;
    cv::Mat1b eroded;
    cv::erode(mask, eroded, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(interior, interior)),
              cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
    for (int y = 0; y < eroded.rows; ++y) {
      const uchar* e = eroded[y];
      const uchar* c = classes[group.box.y + y] + group.box.x;
      const int16_t* dd = fixed[group.box.y + y] + group.box.x;
      for (int x = 0; x < eroded.cols; ++x) {
        if (e[x] && c[x] == kCandidate) inner.push_back(dd[x]);
      }
    }
    if (static_cast<int>(inner.size()) >= std::max(30, n / 4)) {
      d.disparity_px = static_cast<double>(Percentiles(inner)[1]) / kScale;
    }
  }
}

// Step 3: a group's filters (size, support, trusted range, terrain), then its range and score;
// nullopt when it is filtered out.
std::optional<Detection> RangeGroup(const RegionsContext& ctx, const GroupLimits& limits,
                                    const cv::Mat1i& labels, int g, Piece& group) {
  const stereo::DisparityMap& disparity = ctx.disparity;
  const geometry::StereoRig& rig = ctx.rig;
  const geometry::RangeOptions& range = ctx.range;
  const StereoBlobOptions& options = ctx.options;
  const std::optional<GroundModel>& ground = ctx.ground;
  const auto& [max_width_px, min_rows, ring_in, ring_out, interior] = limits;
  const int n = static_cast<int>(group.disparities.size());
  if (group.area < options.min_area_px || group.box.width > max_width_px) return std::nullopt;
  // At least the trusted disparities of one independent matcher window (half a block square):
  // fewer are one coherent mismatch as often as an object.
  const int block = std::max(1, disparity.block_size);
  if (n < std::max({options.min_valid_px, kMinPieceDisparities, block * block / 4}))
    return std::nullopt;
  const double box_area = static_cast<double>(group.box.area());
  const double valid_fraction = n / box_area;
  if (static_cast<double>(n) / group.area < options.min_valid_fraction) return std::nullopt;
  // Range from the interior when there is enough of it: block matching spreads an object's
  // disparity a few pixels past its borders.
  const cv::Mat1b mask = labels(group.box) == g;
  Summarise(group, disparity.block_size);
  const double median_px = static_cast<double>(group.median) / kScale;
  if (!geometry::IsTrustedDisparity(median_px, rig.f_px(), rig.baseline_m(), range))
    return std::nullopt;
  // At the top of the search range the matcher has run out of disparities: what is nearer than
  // it can see matches there by chance.
  if (disparity.num_disparities > 0 &&
      median_px > disparity.min_disparity + disparity.num_disparities - 1 - kSearchTopMarginPx) {
    return std::nullopt;
  }
  if (options.max_depth_per_height > 0 && LeanBack(disparity, labels, g, group.box, median_px, rig,
                                                   min_rows) > options.max_depth_per_height) {
    return std::nullopt;  // terrain leaning back, or level ground
  }
  const double height_m =
      group.box.height * (rig.f_px() * rig.baseline_m() / median_px) / rig.f_px();
  const bool too_short = group.box.height < min_rows || height_m < options.min_terrain_height_m;
  // Terrain is below the horizon: the ground model's, or without one the principal point's
  // row (a level camera's horizon).
  const double horizon_row = ground ? ground->horizon_row : rig.cy();
  if (options.max_attached_fraction < 1 && too_short &&
      group.box.y + group.box.height > horizon_row &&
      AttachedFraction(disparity, labels, g, group.box, median_px, range.min_disparity_px, ring_in,
                       ring_out) > options.max_attached_fraction) {
    return std::nullopt;  // a patch of a continuous surface
  }

  Detection d;
  d.bbox = group.box;
  d.centroid_px = cv::Point2d(group.sum_x / group.area, group.sum_y / group.area);
  d.area_px = group.area;
  // Perimeter: of the box (a sparsely matched hypothesis has no outline of its own).
  d.perimeter_px = 2.0 * (group.box.width + group.box.height);
  d.disparity_px = median_px;
  d.valid_disparities = n;
  d.valid_fraction = std::clamp(valid_fraction, 0.0, 1.0);
  // Without a fit: the median's own uncertainty and the matcher's sub-pixel bias.
  d.disparity_sigma_px = std::hypot(group.median_sigma / kScale, kMatcherBiasPx);
  RangeFromPixels(ctx, limits, group, mask, median_px, n, d);
  // A hypothesis whose own disparity is this uncertain says nothing about where it is: its
  // range is not trusted.
  if (d.disparity_sigma_px > kMaxRelativeDisparitySigma * d.disparity_px) return std::nullopt;
  FillRange(d, rig, range);
  // Score: how much of the hypothesis the stereo supports, and how consistently.
  int consistent = 0;
  const double band = std::max(1.0, 0.1 * median_px) * kScale;
  for (int16_t v : group.disparities) consistent += std::abs(v - median_px * kScale) <= band;
  d.score = std::clamp(std::min(1.0, 2.0 * static_cast<double>(n) / group.area), 0.0, 1.0) *
            (static_cast<double>(consistent) / n);
  d.extractor = std::string(ctx.extractor);
  return d;
}

}  // namespace

std::vector<Detection> RangeRegions(const cv::Mat1b& appearance, const cv::Mat1b& classes,
                                    const stereo::DisparityMap& disparity,
                                    const geometry::StereoRig& rig,
                                    const geometry::RangeOptions& range,
                                    const StereoBlobOptions& options, std::string_view extractor,
                                    const std::optional<GroundModel>& ground,
                                    const FullResolutionPair* full) {
  std::vector<Detection> out;
  std::vector<RegionOf> out_region;  // per detection
  const cv::Mat1s& fixed = disparity.fixed;
  if (fixed.empty() || appearance.size() != fixed.size() || classes.size() != fixed.size())
    return out;
  const int width = fixed.cols, height = fixed.rows;
  const RegionsContext ctx{appearance, classes, disparity, rig,   range, options,
                           extractor,  ground,  full,      width, height};

  // 1. Pieces (LinkAppearance, CutPieces). Per-frame buffers, kept between frames of a thread (no
  //    page faults for fresh memory).
  thread_local cv::Mat1s linked_disparity;
  thread_local cv::Mat1b candidates, linked;
  thread_local cv::Mat1i piece_labels, labels;
  LinkAppearance(ctx, candidates, linked_disparity, linked);
  // The appearance regions, when pieces in one of them join whatever their gap.
  // Their boxes (the stats) only when a lone hypothesis takes its region's extent (step 4).
  thread_local cv::Mat1i region_labels;
  thread_local cv::Mat1i region_stats;
  thread_local cv::Mat1d region_centroids;
  const bool extend_to_regions = options.join_within_region && options.region_gap_fraction == 0;
  if (extend_to_regions) {
    cv::connectedComponentsWithStats(appearance, region_labels, region_stats, region_centroids, 8,
                                     CV_32S);
  } else if (options.join_within_region) {
    cv::connectedComponents(appearance, region_labels, 8, CV_32S);
  }
  std::vector<Piece> pieces =
      CutPieces(ctx, candidates, linked_disparity, linked, region_labels, piece_labels);

  // 2. Groups (JoinPieces).
  std::vector<Piece> groups = JoinPieces(ctx, pieces, piece_labels, labels);
  const int group_count = static_cast<int>(groups.size()) - 1;

  // 3. Filters and range (RangeGroup).
  const double max_width_px = options.max_width_fraction * width;
  const int min_rows = std::max(3, ScaledKernel(kMinTerrainRows640, width));
  const int ring_in = std::max(2, ScaledKernel(6, width) - 1);
  const int ring_out = std::max(ring_in + 2, ScaledKernel(12, width));
  const int interior =
      options.interior_erode_px > 0 ? ScaledKernel(2 * options.interior_erode_px + 1, width) : 1;
  const GroupLimits limits{max_width_px, min_rows, ring_in, ring_out, interior};
  for (int g = 1; g <= group_count; ++g) {
    std::optional<Detection> d = RangeGroup(ctx, limits, labels, g, groups[g]);
    if (!d) continue;
    out.push_back(std::move(*d));
    out_region.push_back({groups[g].region, g});
  }
  // 4. A closed outline is one object (region_gap_fraction 0): a hypothesis alone in its region,
  //    with no other trusted disparity in it, takes the region's extent. The stereo matched only
  //    part of the object (a fuselage, the tips of thin wings whose horizontal edges give no
  //    disparity); the outline says how far the object reaches.
  if (extend_to_regions) {
    ExtendToRegions(region_labels, region_stats, labels, classes, out_region, out);
  }
  return out;
}

std::vector<Detection> RangeAppearance(const cv::Mat1b& appearance, std::string_view extractor,
                                       const stereo::DisparityMap& disparity,
                                       const geometry::StereoRig& rig,
                                       const geometry::RangeOptions& range,
                                       const GroundOptions& ground_options,
                                       const StereoBlobOptions& options,
                                       const FullResolutionPair* full) {
  const std::optional<GroundModel> ground =
      ground_options.enabled ? FitGround(disparity, ground_options) : std::nullopt;
  const cv::Mat1b classes = ClassifyPixels(disparity, rig, range, ground, ground_options);
  return RangeRegions(appearance, classes, disparity, rig, range, options, extractor, ground, full);
}

}  // namespace stevi::detection
