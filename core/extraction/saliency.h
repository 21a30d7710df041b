// Bottom-up intensity saliency for the SteViS extractor (thesis section 3.4), after VOCUS
// (Frintrop 2006, "VOCUS: A Visual Attention System for Object Detection and Goal-Directed
// Search", intensity channel).
//
// Definition, with every stage exposed below so that tests can check it against a naive
// implementation:
//
//   1. Grey pyramid i0..iN (BuildGreyPyramid). i0 is the input as float grey levels. Each next
//      level is the previous one smoothed with the 3x3 Gaussian [1 2 1]/4 (x and y, border
//      reflected without repeating the edge pixel) and halved by averaging 2x2 blocks: pixel
//      (x, y) of level k+1 covers pixels 2x..2x+1, 2y..2y+1 of level k (a trailing odd row or
//      column is dropped; a dimension of 1 stays 1). The effective 1-D filter per octave is the
//      binomial [1 3 3 1]/8, and level k's pixel centres sit at 2^k (x + 0.5) - 0.5 in i0, the
//      same convention as the up-sampling below, so maps stay aligned across levels. The blur
//      and the block average run as one separable pass over the rows and columns they keep.
//   2. Centre-surround (CentreSurround). At each level s in options.scales and each radius r in
//      options.surround_radii, the centre c is the pixel of i_s and the surround S is the mean of
//      the other pixels of the (2r+1) x (2r+1) box around it ("the average of the surrounding
//      pixels", VOCUS), with the box clipped to the image. Box sums come from an integral image
//      (double precision). on = max(c - S, 0) and off = max(S - c, 0), in grey levels.
//   3. Across-scale sum. Every on and off map is brought to the size of level
//      options.centre_level (bilinear up-sampling with the exact scale 2^(s - centre_level) and
//      centre-aligned pixels, or PyramidDown steps when s < centre_level). The
//      conspicuity maps ON and OFF are the means of the resampled on and off maps (grey levels).
//   4. Fusion (FuseSaliency). Each of ON and OFF is divided by sqrt(m), VOCUS's uniqueness weight,
//      where m is the number of its local maxima (8-neighbourhood, plateaus count once) at or
//      above options.peak_fraction of its global maximum: a map with one strong peak counts more
//      than a map with many similar ones, so a bright object's on-peak beats the ring of
//      off-responses around it. ON and OFF are not scaled to their own maxima first: they share
//      the grey-level unit, and scaling would inflate a map that holds only weak responses.
//      S = ON / sqrt(m_on) + OFF / sqrt(m_off) is divided by max(max(S), options.min_contrast),
//      so the map lies in [0, 1] with its maximum at 1 unless the scene is flatter than
//      min_contrast. A flat image gives all zeros.
//
// Cost at 640x480 with the defaults: about 1-1.5 ms on one core (the step from level 0 to level 1
// is half of it; levels 2-4 are small).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::extraction {

struct SaliencyOptions {
  // Pyramid level (0 = the input; each level halves the size) at whose resolution the on/off maps
  // are summed and the saliency map is returned. 0..8.
  int centre_level = 2;
  // Pyramid levels whose pixels are the centres. Each in 0..8, distinct, at least one.
  std::vector<int> scales = {2, 3, 4};
  // Surround box radii (pixels of the centre's level). Each in 1..64, distinct, at least one.
  std::vector<int> surround_radii = {3, 7};
  // Divide ON and OFF by sqrt(number of local maxima) before summing them (VOCUS).
  bool uniqueness_weight = true;
  // Local maxima count towards the uniqueness weight when at or above this fraction of the map's
  // global maximum. In (0, 1].
  double peak_fraction = 0.5;
  // The fused map is divided by max(its maximum, min_contrast) (grey levels of weighted
  // centre-surround contrast; >= 0). 0 always scales the maximum to 1; a positive value keeps a
  // nearly flat scene (noise only) from being stretched to full saliency.
  double min_contrast = 0.0;

  std::vector<std::string> Validate() const;
};

// Levels 0..top_level of the grey pyramid (step 1 above), float grey levels. top_level >= 0.
std::vector<cv::Mat1f> BuildGreyPyramid(const cv::Mat1b& grey, int top_level);

// One pyramid step (step 1 above): 3x3 Gaussian, then 2x2 block average.
cv::Mat1f PyramidDown(const cv::Mat1f& level);

// Centre-surround on and off maps (step 2 above) of one pyramid level for one surround radius
// (pixels, >= 1). `on` and `off` get the level's size, grey levels, >= 0.
void CentreSurround(const cv::Mat1f& level, int radius, cv::Mat1f& on, cv::Mat1f& off);

// Number of local maxima of `map` (step 4 above) at or above fraction * its maximum. 0 when the
// maximum is <= 0.
int CountPeaks(const cv::Mat1f& map, double fraction);

// Step 4 above: the saliency map in [0, 1] from the conspicuity maps ON and OFF (same size).
cv::Mat1f FuseSaliency(const cv::Mat1f& on, const cv::Mat1f& off, const SaliencyOptions& options);

// Every intermediate product of ComputeSaliency, at the resolution of options.centre_level.
struct SaliencyMaps {
  cv::Mat1f on;        // conspicuity ON, grey levels
  cv::Mat1f off;       // conspicuity OFF, grey levels
  int on_peaks = 0;    // CountPeaks(on, peak_fraction)
  int off_peaks = 0;   // CountPeaks(off, peak_fraction)
  cv::Mat1f saliency;  // [0, 1]
};

SaliencyMaps ComputeSaliencyMaps(const cv::Mat1b& grey, const SaliencyOptions& options);

// The saliency map in [0, 1] at the resolution of pyramid level options.centre_level. `options`
// must be valid. Thread-safe (no shared state).
cv::Mat1f ComputeSaliency(const cv::Mat1b& grey, const SaliencyOptions& options);

// Up-samples a map `octaves` pyramid levels above a level of size `size` to that size: bilinear,
// exact scale 2^octaves, pixel centres aligned as in BuildGreyPyramid, edges replicated. Used for
// step 3 and to bring the saliency map back to the input's size. octaves >= 0.
cv::Mat1f UpsampleOctaves(const cv::Mat1f& map, int octaves, cv::Size size);

// ComputeSaliency brought to the input's size with UpsampleOctaves.
cv::Mat1f SaliencyAtFullSize(const cv::Mat1b& grey, const SaliencyOptions& options);

}  // namespace stevi::extraction
