#include "drivers/aravis/stereo_pairer.h"

#include <cstdlib>
#include <limits>
#include <utility>

namespace stevi::drivers {

const char* SideName(Side side) { return side == Side::kLeft ? "left" : "right"; }

std::vector<std::string> PairerOptions::Validate() const {
  std::vector<std::string> problems;
  if (tolerance_ns <= 0) {
    problems.push_back("tolerance_ns: must be > 0 (got " + std::to_string(tolerance_ns) + ")");
  }
  if (max_pending < 1) {
    problems.push_back("max_pending: must be >= 1 (got " + std::to_string(max_pending) + ")");
  }
  return problems;
}

StereoPairer::StereoPairer(PairerOptions options) : options_(options) {
  recent_abs_skew_.reserve(kSkewWindow);
}

std::optional<StereoFrame> StereoPairer::Add(Side side, MonoFrame frame) {
  const Side other = side == Side::kLeft ? Side::kRight : Side::kLeft;
  std::optional<int64_t>& newest = side == Side::kLeft ? newest_left_ : newest_right_;
  const std::optional<int64_t>& other_newest = side == Side::kLeft ? newest_right_ : newest_left_;

  // Out of order: pairing assumes each side's times increase.
  if (newest && frame.t_ns <= *newest) {
    ++dropped_;
    return std::nullopt;
  }
  newest = frame.t_ns;

  // The closest partner within the tolerance.
  std::deque<MonoFrame>& others = queue(other);
  size_t best = others.size();
  int64_t best_distance = std::numeric_limits<int64_t>::max();
  for (size_t i = 0; i < others.size(); ++i) {
    const int64_t distance = std::llabs(others[i].t_ns - frame.t_ns);
    if (distance <= options_.tolerance_ns && distance < best_distance) {
      best = i;
      best_distance = distance;
    }
  }
  if (best < others.size()) {
    MonoFrame partner = std::move(others[best]);
    others.erase(others.begin() + static_cast<std::ptrdiff_t>(best));
    // Whatever is older than the partners cannot pair with anything newer.
    DropOlderThan(other, partner.t_ns);
    DropOlderThan(side, frame.t_ns);
    return side == Side::kLeft ? MakePair(std::move(frame), std::move(partner))
                               : MakePair(std::move(partner), std::move(frame));
  }

  // No partner yet: the other side's frames this one has overtaken by more than the tolerance
  // are hopeless, and so is this one when the other side is already too far ahead.
  DropOlderThan(other, frame.t_ns - options_.tolerance_ns);
  if (other_newest && frame.t_ns < *other_newest - options_.tolerance_ns) {
    ++dropped_;
    return std::nullopt;
  }
  std::deque<MonoFrame>& mine = queue(side);
  mine.push_back(std::move(frame));
  while (mine.size() > static_cast<size_t>(options_.max_pending)) {
    mine.pop_front();
    ++dropped_;
  }
  return std::nullopt;
}

void StereoPairer::ResetSide(Side side) {
  dropped_ += queue(side).size();
  queue(side).clear();
  (side == Side::kLeft ? newest_left_ : newest_right_).reset();
}

void StereoPairer::DropOlderThan(Side side, int64_t t_ns) {
  std::deque<MonoFrame>& q = queue(side);
  while (!q.empty() && q.front().t_ns < t_ns) {
    q.pop_front();
    ++dropped_;
  }
}

StereoFrame StereoPairer::MakePair(MonoFrame left, MonoFrame right) {
  StereoFrame pair;
  pair.t_ns = left.t_ns;
  pair.unix_time_ns = left.unix_time_ns;
  pair.pair_skew_ns = right.t_ns - left.t_ns;
  pair.index = static_cast<int64_t>(pairs_);
  pair.rectified = false;
  pair.left = std::move(left.image);
  pair.right = std::move(right.image);

  ++pairs_;
  const int64_t abs_skew = std::llabs(pair.pair_skew_ns);
  last_skew_ns_ = pair.pair_skew_ns;
  if (abs_skew > max_abs_skew_ns_) max_abs_skew_ns_ = abs_skew;
  if (recent_abs_skew_.size() < kSkewWindow) {
    recent_abs_skew_.push_back(abs_skew);
  } else {
    recent_sum_ -= recent_abs_skew_[recent_next_];
    recent_abs_skew_[recent_next_] = abs_skew;
  }
  recent_next_ = (recent_next_ + 1) % kSkewWindow;
  recent_sum_ += abs_skew;
  return pair;
}

SourceCounters StereoPairer::Counters() const {
  SourceCounters counters;
  counters.pairs = pairs_;
  counters.unpaired_dropped = dropped_;
  counters.last_skew_ns = last_skew_ns_;
  counters.max_abs_skew_ns = max_abs_skew_ns_;
  counters.mean_abs_skew_ns =
      recent_abs_skew_.empty()
          ? 0.0
          : static_cast<double>(recent_sum_) / static_cast<double>(recent_abs_skew_.size());
  return counters;
}

}  // namespace stevi::drivers
