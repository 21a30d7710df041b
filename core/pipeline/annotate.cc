#include "core/pipeline/annotate.h"

#include <algorithm>
#include <cstdio>

#include <opencv2/imgproc.hpp>

namespace stevi::pipeline {

cv::Mat3b AnnotateDetections(const FrameResult& result) {
  cv::Mat3b out;
  if (result.rectified_left.empty()) return out;
  if (result.rectified_left.channels() == 1) {
    cv::cvtColor(result.rectified_left, out, cv::COLOR_GRAY2BGR);
  } else {
    result.rectified_left.copyTo(out);
  }
  const cv::Scalar box_colour(0, 200, 255), text_colour(0, 0, 0);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  const double scale = 0.45;
  int id = 1;
  for (const detection::Detection& d : result.detections) {
    cv::rectangle(out, d.bbox, box_colour, 2);
    char label[64];
    std::snprintf(label, sizeof label, "#%d %.1f m +-%.1f", id++, d.range_m, d.range_sigma_m);
    int baseline = 0;
    const cv::Size size = cv::getTextSize(label, font, scale, 1, &baseline);
    // Above the box when there is room, else inside its top edge.
    const int top = d.bbox.y - size.height - baseline - 2 >= 0 ? d.bbox.y - size.height - baseline - 2
                                                               : d.bbox.y;
    // Inside the image on the right too.
    const int left = std::max(0, std::min(d.bbox.x, out.cols - size.width - 4));
    const cv::Rect tag(left, top, size.width + 4, size.height + baseline + 2);
    cv::rectangle(out, tag, box_colour, cv::FILLED);
    cv::putText(out, label, cv::Point(tag.x + 2, tag.y + size.height + 1), font, scale, text_colour,
                1, cv::LINE_AA);
  }
  return out;
}

}  // namespace stevi::pipeline
