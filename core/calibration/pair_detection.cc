// The pair detection: each pair's images probed before decoding (type, header size, the size the
// pairs share), then decoded and searched for the chessboard in parallel, and each pair used or
// rejected with its reason (DetectPairs, declared in calibrate.h).
#include "core/calibration/calibrate.h"

#include <map>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/calibration/image_header.h"
#include "core/common/format.h"

namespace stevi::calibration {
namespace {

struct Probe {
  std::optional<cv::Size> size;
  std::optional<RejectReason> reason;  // set when the image cannot be used
  std::string problem;
};

std::span<const std::uint8_t> BytesOf(const ImageData& data) {
  if (const auto* s = std::get_if<std::string>(&data)) {
    return {reinterpret_cast<const std::uint8_t*>(s->data()), s->size()};
  }
  if (const auto* v = std::get_if<std::vector<std::uint8_t>>(&data)) return {v->data(), v->size()};
  return {};
}

// The image's size without decoding it (header for bytes), or why it cannot be used.
Probe ProbeImage(const ImageData& data, cv::Size max_size) {
  Probe p;
  if (const auto* mat = std::get_if<cv::Mat>(&data)) {
    if (mat->empty()) {
      p.reason = RejectReason::kUndecodable;
      p.problem = "empty image";
    } else if (mat->depth() != CV_8U ||
               (mat->channels() != 1 && mat->channels() != 3 && mat->channels() != 4) ||
               mat->dims != 2) {
      p.reason = RejectReason::kUndecodable;
      p.problem = "unsupported image type " + cv::typeToString(mat->type()) +
                  " (expected 8-bit grey, BGR or BGRA)";
    } else {
      p.size = mat->size();
    }
  } else {
    Result<cv::Size> header = ImageHeaderSize(BytesOf(data));
    if (!header.ok()) {
      p.reason = RejectReason::kUndecodable;
      p.problem = header.error().message;
      return p;
    }
    p.size = *header;
  }
  if (p.size && (p.size->width > max_size.width || p.size->height > max_size.height)) {
    p.reason = RejectReason::kTooLarge;
    p.problem = "image of " + SizeText(*p.size) + " pixels exceeds the maximum of " +
                SizeText(max_size) + "; not decoded";
    p.size.reset();
  }
  return p;
}

// An 8-bit grey image of the input (decoding bytes, converting colour cv::Mat).
Result<cv::Mat> GreyImage(const ImageData& data, cv::Size max_size) {
  if (const auto* mat = std::get_if<cv::Mat>(&data)) {
    if (mat->channels() == 1) return *mat;
    cv::Mat grey;
    cv::cvtColor(*mat, grey, mat->channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
    return grey;
  }
  return DecodeGreyImage(BytesOf(data), max_size);
}

// Per-pair rejections so far, by pair index.
using Rejections = std::vector<std::optional<RejectedPair>>;

void Reject(const std::vector<ImagePair>& pairs, Rejections& rejection, int i, RejectReason reason,
            std::string detail) {
  rejection[i] = RejectedPair{i, pairs[i].name, reason, std::move(detail)};
}

// Steps 1 and 2: sizes from the headers, then the calibration's image size, the one most pairs
// share (the earliest on a tie). Pairs that cannot be probed or differ in size are rejected.
cv::Size CommonImageSize(const std::vector<ImagePair>& pairs, const CalibrationOptions& options,
                         Rejections& rejection) {
  const int n = static_cast<int>(pairs.size());
  std::vector<cv::Size> sizes(n);
  std::map<std::pair<int, int>, int> size_counts;
  std::vector<std::pair<int, int>> size_order;  // first appearance, for ties
  for (int i = 0; i < n; ++i) {
    const Probe left = ProbeImage(pairs[i].left, options.max_image_size);
    const Probe right = ProbeImage(pairs[i].right, options.max_image_size);
    if (left.reason || right.reason) {
      std::string detail;
      if (left.reason) detail = "left image: " + left.problem;
      if (right.reason)
        detail += (detail.empty() ? "" : "; ") + std::string("right image: ") + right.problem;
      Reject(pairs, rejection, i, left.reason ? *left.reason : *right.reason, detail);
      continue;
    }
    if (*left.size != *right.size) {
      Reject(pairs, rejection, i, RejectReason::kSizeMismatch,
             "left image is " + SizeText(*left.size) + ", right image is " + SizeText(*right.size));
      continue;
    }
    sizes[i] = *left.size;
    const std::pair<int, int> key(sizes[i].width, sizes[i].height);
    if (size_counts[key]++ == 0) size_order.push_back(key);
  }
  std::pair<int, int> common(0, 0);
  int best = 0;
  for (const auto& key : size_order) {
    if (size_counts[key] > best) {
      best = size_counts[key];
      common = key;
    }
  }
  const cv::Size image_size(common.first, common.second);
  for (int i = 0; i < n; ++i) {
    if (!rejection[i] && sizes[i] != image_size) {
      Reject(pairs, rejection, i, RejectReason::kSizeDiffers,
             "images of " + SizeText(sizes[i]) + ", while " + std::to_string(best) + " pairs are " +
                 SizeText(image_size));
    }
  }
  return image_size;
}

struct ImageOutcome {
  std::optional<Error> decode_error;
  Result<std::vector<cv::Point2f>> corners = Internal("not run");
};

// Step 3: decode and detect, one task per image of every pair not yet rejected. Slot 2i is pair
// i's left image, 2i+1 its right.
std::vector<ImageOutcome> DetectCorners(const std::vector<ImagePair>& pairs,
                                        const CalibrationOptions& options,
                                        const Rejections& rejection) {
  const int n = static_cast<int>(pairs.size());
  std::vector<ImageOutcome> outcomes(2 * static_cast<std::size_t>(n));
  std::vector<int> tasks;
  for (int i = 0; i < n; ++i) {
    if (!rejection[i]) {
      tasks.push_back(2 * i);
      tasks.push_back(2 * i + 1);
    }
  }
  cv::parallel_for_(cv::Range(0, static_cast<int>(tasks.size())), [&](const cv::Range& range) {
    for (int t = range.start; t < range.end; ++t) {
      const int slot = tasks[t];
      const ImagePair& pair = pairs[slot / 2];
      ImageOutcome& outcome = outcomes[slot];
      try {
        Result<cv::Mat> grey =
            GreyImage(slot % 2 == 0 ? pair.left : pair.right, options.max_image_size);
        if (!grey.ok()) {
          outcome.decode_error = grey.error();
          continue;
        }
        outcome.corners = DetectChessboard(*grey, options.board, options.detection);
      } catch (const std::exception& e) {
        outcome.decode_error = Internal(e.what());
      }
    }
  });
  return outcomes;
}

// Step 4: a pair is used when both images decoded and showed the board; otherwise it is rejected
// with the reason.
void JudgeDetections(const std::vector<ImagePair>& pairs, const CalibrationOptions& options,
                     const std::vector<ImageOutcome>& outcomes, Rejections& rejection,
                     DetectedPairs& out) {
  const int n = static_cast<int>(pairs.size());
  for (int i = 0; i < n; ++i) {
    if (rejection[i]) continue;
    const ImageOutcome& left = outcomes[2 * i];
    const ImageOutcome& right = outcomes[2 * i + 1];
    if (left.decode_error || right.decode_error) {
      std::string detail;
      RejectReason reason = RejectReason::kUndecodable;
      for (const auto* side : {&left, &right}) {
        if (!side->decode_error) continue;
        if (side->decode_error->code == ErrorCode::kResourceExhausted)
          reason = RejectReason::kTooLarge;
        if (!detail.empty()) detail += "; ";
        detail += (side == &left ? "left image: " : "right image: ") + side->decode_error->message;
      }
      Reject(pairs, rejection, i, reason, detail);
      continue;
    }
    const bool found_left = left.corners.ok(), found_right = right.corners.ok();
    if (found_left && found_right) {
      out.pairs.push_back(PairCorners{i, pairs[i].name, *left.corners, *right.corners});
      continue;
    }
    const std::string missing = "no board of " + options.board.Name() + " inner corners found in ";
    auto why = [](const ImageOutcome& o) {
      return o.corners.error().code == ErrorCode::kNotFound
                 ? std::string()
                 : " (" + o.corners.error().message + ")";
    };
    if (!found_left && !found_right) {
      Reject(pairs, rejection, i, RejectReason::kNoBoard, missing + "either image" + why(left));
    } else if (!found_left) {
      Reject(pairs, rejection, i, RejectReason::kNoBoardLeft,
             missing + "the left image" + why(left));
    } else {
      Reject(pairs, rejection, i, RejectReason::kNoBoardRight,
             missing + "the right image" + why(right));
    }
  }
}

Result<DetectedPairs> DetectPairsChecked(const std::vector<ImagePair>& pairs,
                                         const CalibrationOptions& options) {
  DetectedPairs out;
  out.pairs_given = static_cast<int>(pairs.size());
  Rejections rejection(pairs.size());
  out.image_size = CommonImageSize(pairs, options, rejection);
  const std::vector<ImageOutcome> outcomes = DetectCorners(pairs, options, rejection);
  JudgeDetections(pairs, options, outcomes, rejection, out);
  for (const std::optional<RejectedPair>& r : rejection) {
    if (r) out.rejected.push_back(*r);
  }
  return out;
}

}  // namespace

Result<DetectedPairs> DetectPairs(const std::vector<ImagePair>& pairs,
                                  const CalibrationOptions& options) {
  if (std::vector<std::string> problems = options.Validate(); !problems.empty()) {
    return InvalidArgument(problems);
  }
  if (pairs.empty()) return InvalidArgument("no image pairs given");
  try {
    return DetectPairsChecked(pairs, options);
  } catch (const std::exception& e) {
    return Internal(std::string("chessboard detection failed (") + e.what() + ")");
  }
}

}  // namespace stevi::calibration
