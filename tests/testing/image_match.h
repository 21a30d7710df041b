// Pixel-exact image comparison for tests, saying where the first difference is.
#pragma once

#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace stevi::testing {

inline ::testing::AssertionResult ImagesIdentical(const cv::Mat& expected, const cv::Mat& actual) {
  if (expected.type() != actual.type() || expected.size() != actual.size()) {
    return ::testing::AssertionFailure()
           << "expected " << cv::typeToString(expected.type()) << " " << expected.cols << "x"
           << expected.rows << ", got " << cv::typeToString(actual.type()) << " " << actual.cols
           << "x" << actual.rows;
  }
  cv::Mat diff;
  cv::absdiff(expected, actual, diff);
  diff = diff.reshape(1, diff.rows);
  std::vector<cv::Point> where;
  cv::findNonZero(diff, where);
  if (where.empty()) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure()
         << where.size() << " channel values differ, the first at column " << where[0].x
         << " (channel-interleaved) row " << where[0].y;
}

}  // namespace stevi::testing
