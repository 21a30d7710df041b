#include "core/extraction/morphology.h"

#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace stevi::extraction {
namespace {

bool ValidSize(int size) { return size >= 1 && size % 2 == 1 && size <= kMaxElementSize; }

int CvShape(StructuringShape shape) {
  switch (shape) {
    case StructuringShape::kRect: return cv::MORPH_RECT;
    case StructuringShape::kCross: return cv::MORPH_CROSS;
    case StructuringShape::kEllipse: break;
  }
  return cv::MORPH_ELLIPSE;
}

// 0/255 copy of a mask whose foreground is any non-zero value.
cv::Mat1b Binary(const cv::Mat1b& mask) {
  cv::Mat1b out;
  cv::compare(mask, 0, out, cv::CMP_NE);
  return out;
}

cv::Mat1b Apply(const cv::Mat1b& mask, StructuringShape shape, int size, int op) {
  CV_Assert(ValidSize(size));
  cv::Mat1b binary = Binary(mask);
  if (size == 1 || mask.empty()) return binary;
  const cv::Mat element = cv::getStructuringElement(CvShape(shape), cv::Size(size, size));
  cv::Mat1b out;
  // The default border value is neutral for each operation (+inf for erosion, -inf for dilation).
  cv::morphologyEx(binary, out, op, element);
  return out;
}

}  // namespace

std::vector<std::string> MorphologyOptions::Validate() const { return fields::Check(*this); }

cv::Mat1b Dilate(const cv::Mat1b& mask, StructuringShape shape, int size) {
  return Apply(mask, shape, size, cv::MORPH_DILATE);
}

cv::Mat1b Erode(const cv::Mat1b& mask, StructuringShape shape, int size) {
  return Apply(mask, shape, size, cv::MORPH_ERODE);
}

cv::Mat1b Open(const cv::Mat1b& mask, StructuringShape shape, int size) {
  return Apply(mask, shape, size, cv::MORPH_OPEN);
}

cv::Mat1b Close(const cv::Mat1b& mask, StructuringShape shape, int size) {
  return Apply(mask, shape, size, cv::MORPH_CLOSE);
}

cv::Mat1b FillHoles(const cv::Mat1b& mask) {
  if (mask.empty()) return cv::Mat1b();
  // Pad with one background pixel so that one flood fill from a corner reaches every background
  // region that touches the image border.
  constexpr uchar kOutside = 128;
  cv::Mat1b padded(mask.rows + 2, mask.cols + 2, uchar{0});
  cv::Mat1b inside = padded(cv::Rect(1, 1, mask.cols, mask.rows));
  cv::compare(mask, 0, inside, cv::CMP_NE);  // writes into padded: same size and type
  cv::floodFill(padded, cv::Point(0, 0), cv::Scalar(kOutside), nullptr, cv::Scalar(), cv::Scalar(),
                4);
  // Foreground (255) and holes (0) are everything the fill did not reach.
  cv::Mat1b filled;
  cv::compare(inside, kOutside, filled, cv::CMP_NE);
  return filled;
}

cv::Mat1b CloseFillOpen(const cv::Mat1b& edges, const MorphologyOptions& options) {
  // The fill goes between the closing's dilation and erosion: the dilated contours enclose their
  // regions even where the closing as a whole would re-open a gap (a 1-pixel-wide straight line
  // with a gap is never bridged by a closing with MORPH_ELLIPSE, whose extreme rows are single
  // pixels). Without filling this is exactly Close, then Open.
  cv::Mat1b mask = Dilate(edges, options.shape, options.close_size);
  if (options.fill_holes) mask = FillHoles(mask);
  mask = Erode(mask, options.shape, options.close_size);
  return Open(mask, options.shape, options.open_size);
}

}  // namespace stevi::extraction
