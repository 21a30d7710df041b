// Matching detections to ground-truth boxes: IoU >= a threshold, one-to-one, best pairs first.
#pragma once

#include <utility>
#include <vector>

#include <opencv2/core.hpp>

namespace stevi::testing {

double IoU(const cv::Rect& a, const cv::Rect& b);

// The fraction of `inner`'s area that lies inside `outer` (0 for an empty `inner`).
double InsideFraction(const cv::Rect& inner, const cv::Rect& outer);

// Greedy one-to-one assignment by decreasing IoU; returns (detection index, truth index) pairs
// whose IoU is at least min_iou.
std::vector<std::pair<int, int>> MatchByIoU(const std::vector<cv::Rect>& detections,
                                            const std::vector<cv::Rect>& truths, double min_iou);

// Median of `values` over the pixels where ids == id (0 when there are none): e.g. the truth
// disparity of one obstacle of the synthetic scene.
double MedianOverId(const cv::Mat1i& ids, const cv::Mat1f& values, int id);

}  // namespace stevi::testing
