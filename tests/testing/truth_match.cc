#include "tests/testing/truth_match.h"

#include <algorithm>
#include <tuple>

namespace stevi::testing {

double IoU(const cv::Rect& a, const cv::Rect& b) {
  const double inter = (a & b).area();
  const double uni = a.area() + b.area() - inter;
  return uni > 0 ? inter / uni : 0;
}

double InsideFraction(const cv::Rect& inner, const cv::Rect& outer) {
  return inner.area() > 0 ? static_cast<double>((inner & outer).area()) / inner.area() : 0.0;
}

std::vector<std::pair<int, int>> MatchByIoU(const std::vector<cv::Rect>& detections,
                                            const std::vector<cv::Rect>& truths, double min_iou) {
  std::vector<std::tuple<double, int, int>> candidates;
  for (int d = 0; d < static_cast<int>(detections.size()); ++d) {
    for (int t = 0; t < static_cast<int>(truths.size()); ++t) {
      const double iou = IoU(detections[d], truths[t]);
      if (iou >= min_iou) candidates.emplace_back(iou, d, t);
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const auto& a, const auto& b) { return std::get<0>(a) > std::get<0>(b); });
  std::vector<bool> used_d(detections.size()), used_t(truths.size());
  std::vector<std::pair<int, int>> matches;
  for (const auto& [iou, d, t] : candidates) {
    if (used_d[d] || used_t[t]) continue;
    used_d[d] = used_t[t] = true;
    matches.emplace_back(d, t);
  }
  return matches;
}

double MedianOverId(const cv::Mat1i& ids, const cv::Mat1f& values, int id) {
  std::vector<float> picked;
  for (int y = 0; y < ids.rows; ++y) {
    for (int x = 0; x < ids.cols; ++x) {
      if (ids(y, x) == id) picked.push_back(values(y, x));
    }
  }
  if (picked.empty()) return 0;
  auto mid = picked.begin() + static_cast<std::ptrdiff_t>(picked.size() / 2);
  std::nth_element(picked.begin(), mid, picked.end());
  return *mid;
}

}  // namespace stevi::testing
