// Binary morphology for the SteViE extractor (thesis section 4.2): close the edge contours, fill
// the closed regions, open to separate touching objects.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/common/fields.h"

namespace stevi::extraction {

// Largest accepted structuring element size (pixels).
inline constexpr int kMaxElementSize = 101;

// Shape of the structuring element (OpenCV's MORPH_RECT, MORPH_ELLIPSE, MORPH_CROSS).
enum class StructuringShape { kRect, kEllipse, kCross };

struct MorphologyOptions {
  StructuringShape shape = StructuringShape::kEllipse;
  // Closing (dilate, then erode) to join broken edge contours: element size (pixels, odd; 1 = off).
  int close_size = 7;
  // Opening (erode, then dilate) to cut thin bridges and remove specks after filling: element
  // size (pixels, odd; 1 = off).
  int open_size = 3;
  // Fill the regions enclosed by the closed contours (see FillHoles).
  bool fill_holes = true;

  std::vector<std::string> Validate() const;

  static constexpr fields::ChoiceName<StructuringShape> kShapeNames[] = {
      {StructuringShape::kRect, "rect"},
      {StructuringShape::kEllipse, "ellipse"},
      {StructuringShape::kCross, "cross"}};
  template <class Self, class V>
  static void Fields(Self& s, V& v) {
    using fields::Field;
    v.Choice(s.shape, Field("shape", "", "shape of the structuring elements"), kShapeNames);
    v.Number(
        s.close_size,
        Field("close_size", "pixels", "closing element; 1 = off").Odd().In(1, kMaxElementSize));
    v.Number(s.open_size,
             Field("open_size", "pixels", "opening element; 1 = off").Odd().In(1, kMaxElementSize));
    v.Flag(s.fill_holes, Field("fill_holes", "", "fill the regions the closed contours enclose"));
  }
};

// Single operations on a binary mask (non-zero = foreground) with a size x size element (pixels,
// odd, >= 1; 1 returns a copy). Outside the image counts as neutral: erosion does not eat in from
// the image border and dilation does not grow out of it. The result is 0/255.
cv::Mat1b Dilate(const cv::Mat1b& mask, StructuringShape shape, int size);
cv::Mat1b Erode(const cv::Mat1b& mask, StructuringShape shape, int size);
cv::Mat1b Open(const cv::Mat1b& mask, StructuringShape shape, int size);
cv::Mat1b Close(const cv::Mat1b& mask, StructuringShape shape, int size);

// The mask (non-zero = foreground) with every hole filled: a hole is a background region that
// is not 4-connected to the image border (the dual of the 8-connected foreground). A background
// region that reaches the image border is open, not a hole, and stays background. 0/255.
cv::Mat1b FillHoles(const cv::Mat1b& mask);

// The SteViE chain on an edge map: dilate, FillHoles (when enabled), erode (the dilation and
// erosion make the closing, with the fill in between so that regions enclosed only by the
// dilated contours are filled), then Open. 0/255, the input's size. `options` must be valid.
cv::Mat1b CloseFillOpen(const cv::Mat1b& edges, const MorphologyOptions& options);

}  // namespace stevi::extraction
