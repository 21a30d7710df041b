#include "core/pipeline/annotate.h"

#include <algorithm>
#include <cstdio>

#include <opencv2/imgproc.hpp>

namespace stevi::pipeline {

cv::Mat3b AnnotateTracks(const FrameResult& result) {
  cv::Mat3b out;
  if (result.rectified_left.empty()) return out;
  if (result.rectified_left.channels() == 1) {
    cv::cvtColor(result.rectified_left, out, cv::COLOR_GRAY2BGR);
  } else {
    result.rectified_left.copyTo(out);
  }
  const cv::Scalar text_colour(0, 0, 0);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  const double scale = 0.45;
  for (const tracking::Track& t : result.tracks) {
    const detection::Detection& d = t.detection;
    // Confirmed: orange, thick. Coasting (predicted): blue-grey. Tentative: thin yellow.
    cv::Scalar box_colour(0, 200, 255);
    int thickness = 2;
    if (t.state == tracking::TrackState::kCoasting) {
      box_colour = cv::Scalar(200, 160, 120);
    } else if (t.state == tracking::TrackState::kTentative) {
      box_colour = cv::Scalar(0, 255, 255);
      thickness = 1;
    }
    cv::rectangle(out, d.bbox, box_colour, thickness);
    char label[96];
    const double range =
        t.state == tracking::TrackState::kCoasting ? cv::norm(t.position_cam_m) : d.range_m;
    std::snprintf(label, sizeof label, "#%llu %.1f m +-%.1f%s",
                  static_cast<unsigned long long>(t.id), range, d.range_sigma_m,
                  t.state == tracking::TrackState::kCoasting    ? " (pred)"
                  : t.state == tracking::TrackState::kTentative ? " ?"
                                                                : "");
    int baseline = 0;
    const cv::Size size = cv::getTextSize(label, font, scale, 1, &baseline);
    // Above the box when there is room, else inside its top edge.
    const int top = d.bbox.y - size.height - baseline - 2 >= 0
                        ? d.bbox.y - size.height - baseline - 2
                        : std::max(0, d.bbox.y);
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
