#include "core/tracking/fading_filter.h"

#include <cmath>
#include <stdexcept>

namespace stevi::tracking {

FadingMemoryFilter::FadingMemoryFilter(double beta) : beta_(beta) {
  if (!(beta > 0 && beta <= 1)) {
    throw std::invalid_argument("FadingMemoryFilter: beta must be in (0, 1]");
  }
}

void FadingMemoryFilter::Reset() {
  value_ = 0;
  rate_ = 0;
  count_ = 0;
}

void FadingMemoryFilter::Update(double measured, double dt_s) {
  if (count_ == 0) {
    value_ = measured;
    rate_ = 0;
    count_ = 1;
    return;
  }
  // Expanding-memory gains for the measurement after n = count_ others, until they fall to the
  // fading ones (README.md, fading_filter.h).
  const double fading_g = 1 - beta_ * beta_;
  const double fading_h = (1 - beta_) * (1 - beta_);
  const double n = count_;
  double g = 2 * (2 * n + 1) / ((n + 1) * (n + 2));
  double h = 6 / ((n + 1) * (n + 2));
  if (g <= fading_g) {
    g = fading_g;
    h = fading_h;
  }
  if (!(dt_s > 0)) {
    value_ += g * (measured - value_);
    return;
  }
  const double predicted = value_ + rate_ * dt_s;
  const double residual = measured - predicted;
  value_ = predicted + g * residual;
  rate_ += h * residual / dt_s;
  ++count_;
}

}  // namespace stevi::tracking
