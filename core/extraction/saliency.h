// Bottom-up intensity saliency for the SteViS extractor (thesis section 3.4), after VOCUS
// (Frintrop 2006, "VOCUS: A Visual Attention System for Object Detection and Goal-Directed
// Search", intensity channel), in four stages, each exposed below so that tests can check it
// against a naive implementation: (1) a grey pyramid, (2) centre-surround on and off maps,
// (3) their across-scale sum into the conspicuity maps ON and OFF, (4) the fusion of ON and OFF
// with VOCUS's uniqueness weight into a map in [0, 1].
// Definition and derivation: core/extraction/README.md, "Saliency"; cost: its "Measured".
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"

namespace stevi::extraction {

// Bounds of the saliency options: the deepest pyramid level and the largest surround radius
// (pixels).
inline constexpr int kMaxSaliencyLevel = 8;
inline constexpr int kMaxSurroundRadius = 64;

struct SaliencyOptions {
  // Pyramid level (0 = the input; each level halves the size) at whose resolution the on/off maps
  // are summed and the saliency map is returned.
  int centre_level = 2;
  // Pyramid levels whose pixels are the centres: distinct, at least one.
  std::vector<int> scales = {2, 3, 4};
  // Surround box radii (pixels of the centre's level): distinct, at least one.
  std::vector<int> surround_radii = {3, 7};
  // Divide ON and OFF by sqrt(number of local maxima) before summing them (VOCUS).
  bool uniqueness_weight = true;
  // Local maxima count towards the uniqueness weight when at or above this fraction of the map's
  // global maximum.
  double peak_fraction = 0.5;
  // The fused map is divided by max(its maximum, min_contrast) (grey levels of weighted
  // centre-surround contrast). 0 always scales the maximum to 1; a positive value keeps a
  // nearly flat scene (noise only) from being stretched to full saliency.
  double min_contrast = 0.0;

  // The field checks, and the entries of each list distinct.
  std::vector<std::string> Validate() const;

  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Number(s.centre_level,
             Field("centre_level", "", "pyramid level of the map (0 = full size, each halves it)")
                 .In(0, kMaxSaliencyLevel));
    v.List(s.scales,
           Field("scales", "", "centre pyramid levels, distinct").In(0, kMaxSaliencyLevel));
    v.List(s.surround_radii,
           Field("surround_radii", "pixels", "surround box radii at the centre level, distinct")
               .In(1, kMaxSurroundRadius));
    v.Flag(s.uniqueness_weight,
           Field("uniqueness_weight", "", "divide ON and OFF by sqrt(their peaks)"));
    v.Number(s.peak_fraction,
             Field("peak_fraction", "", "local maxima at this fraction of the maximum are peaks")
                 .Above(0)
                 .AtMost(1));
    v.Number(s.min_contrast,
             Field("min_contrast", "grey levels",
                   "the map is divided by max(its maximum, this); 0 = by its maximum")
                 .AtLeast(0));
  }
};

// Levels 0..top_level of the grey pyramid (stage 1), float grey levels: level 0 is the input,
// each next level PyramidDown of the previous one. top_level >= 0.
std::vector<cv::Mat1f> BuildGreyPyramid(const cv::Mat1b& grey, int top_level);

// One pyramid step (stage 1): the 3x3 Gaussian [1 2 1]/4 in x and y (border reflected without
// repeating the edge pixel), then 2x2 block averages: output pixel (x, y) covers input pixels
// 2x..2x+1, 2y..2y+1; a trailing odd row or column is dropped, a dimension of 1 stays 1.
cv::Mat1f PyramidDown(const cv::Mat1f& level);

// Centre-surround on and off maps (stage 2) of one pyramid level for one surround radius
// (pixels, >= 1): with c the pixel and S the mean of the other pixels of the (2r+1) x (2r+1) box
// around it (clipped to the image), on = max(c - S, 0) and off = max(S - c, 0). `on` and `off`
// get the level's size, grey levels, >= 0.
void CentreSurround(const cv::Mat1f& level, int radius, cv::Mat1f& on, cv::Mat1f& off);

// Number of local maxima of `map` (8-neighbourhood, a plateau counts once; stage 4) at or above
// fraction * its maximum. 0 when the maximum is <= 0.
int CountPeaks(const cv::Mat1f& map, double fraction);

// Stage 4: the saliency map in [0, 1] from the conspicuity maps ON and OFF (same size):
// ON / sqrt(m_on) + OFF / sqrt(m_off) (m: CountPeaks at options.peak_fraction, with
// options.uniqueness_weight; else weights 1), divided by max(its maximum, options.min_contrast).
// A flat image gives all zeros.
cv::Mat1f FuseSaliency(const cv::Mat1f& on, const cv::Mat1f& off, const SaliencyOptions& options);

// Every intermediate product of ComputeSaliency, at the resolution of options.centre_level.
struct SaliencyMaps {
  cv::Mat1f on;        // conspicuity ON, grey levels
  cv::Mat1f off;       // conspicuity OFF, grey levels
  int on_peaks = 0;    // CountPeaks(on, peak_fraction)
  int off_peaks = 0;   // CountPeaks(off, peak_fraction)
  cv::Mat1f saliency;  // [0, 1]
};

// Stages 1-4 on an 8-bit grey image: ON and OFF are the means over options.scales and
// options.surround_radii of the on and off maps brought to the centre level (stage 3: up-sampled
// with UpsampleOctaves, or PyramidDown steps for scales below it). `options` must be valid.
SaliencyMaps ComputeSaliencyMaps(const cv::Mat1b& grey, const SaliencyOptions& options);

// The saliency map in [0, 1] at the resolution of pyramid level options.centre_level. `options`
// must be valid. Thread-safe (no shared state).
cv::Mat1f ComputeSaliency(const cv::Mat1b& grey, const SaliencyOptions& options);

// Up-samples a map `octaves` pyramid levels above a level of size `size` to that size: bilinear,
// exact scale 2^octaves, pixel centres aligned as in BuildGreyPyramid, edges replicated. Used for
// stage 3 and to bring the saliency map back to the input's size. octaves >= 0.
cv::Mat1f UpsampleOctaves(const cv::Mat1f& map, int octaves, cv::Size size);

// ComputeSaliency brought to the input's size with UpsampleOctaves.
cv::Mat1f SaliencyAtFullSize(const cv::Mat1b& grey, const SaliencyOptions& options);

}  // namespace stevi::extraction
