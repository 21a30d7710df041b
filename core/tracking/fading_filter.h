// Range smoothing: the fading-memory g-h filter (value and rate), with the real time step.
#pragma once

namespace stevi::tracking {

// The first-order (straight-line) fading-memory polynomial filter. With prediction
// x_pred = x + rate * dt and residual r = z - x_pred, each measurement z does
//   x    = x_pred + G r,        G = 1 - beta^2,
//   rate = rate + (H / dt) r,   H = (1 - beta)^2,
// the least-squares line fit with weights beta^k on the k-th oldest measurement. beta in (0, 1]:
// smaller forgets faster; beta = 1 never forgets. For a constant-rate input the estimate is exact
// once started, and for white noise of sigma s on uniform steps the steady-state errors are
//   value: s * sqrt((1 - beta)(1 + 4 beta + 5 beta^2) / (1 + beta)^3)   (0.618 s at beta = 0.7),
//   rate:  s / dt * sqrt(2 (1 - beta)^3 / (1 + beta)^3)                 (0.105 s / dt at 0.7).
// The thesis's x_n = x_{n-1} + (1 - beta)(z_n - x_{n-1}) is the zeroth-order member of this
// family; the first-order one also estimates the rate, so it does not lag a closing obstacle.
//
// Start: the fading gains are poor for the first measurements (the rate starts unknown), so the
// filter starts as the expanding-memory filter (the unweighted least-squares line over all the
// measurements so far), g_n = 2(2n+1) / ((n+1)(n+2)), h_n = 6 / ((n+1)(n+2)) for the measurement
// after n others, and switches to G and H once g_n falls to G. The first measurement sets the
// value, the second the two-point rate. (Brookner, Tracking and Kalman Filtering Made Easy, 1.2.)
//
// Thread-compatible.
class FadingMemoryFilter {
 public:
  // beta must be in (0, 1]; anything else is a programming error (std::invalid_argument).
  explicit FadingMemoryFilter(double beta = 0.7);

  // Adds a measurement taken `dt_s` seconds after the previous one (ignored for the first). A
  // measurement at the same time (dt_s <= 0) only blends into the value with the current gain.
  void Update(double measured, double dt_s);

  // The value `dt_s` seconds after the last measurement (the value itself before the second).
  double Predict(double dt_s) const { return value_ + rate_ * dt_s; }

  // Forgets every measurement (beta stays).
  void Reset();

  bool initialized() const { return count_ > 0; }
  double value() const { return value_; }
  // Units of the value per second. 0 until the second measurement.
  double rate() const { return rate_; }
  double beta() const { return beta_; }
  // Measurements used so far (same-time ones are not counted).
  int count() const { return count_; }

 private:
  double beta_;
  double value_ = 0;
  double rate_ = 0;
  int count_ = 0;
};

}  // namespace stevi::tracking
