#include "core/tracking/fading_filter.h"

#include <cmath>
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

namespace stevi::tracking {
namespace {

constexpr double kDt = 1.0 / 30;

// Steady-state noise reduction of the fading-memory g-h filter (fading_filter.h): the ratio of the
// filtered value's sigma to the measurement's, and of the rate's sigma to sigma / dt.
double ValueNoiseRatio(double beta) {
  return std::sqrt((1 - beta) * (1 + 4 * beta + 5 * beta * beta) / std::pow(1 + beta, 3));
}
double RateNoiseRatio(double beta) {
  return std::sqrt(2 * std::pow(1 - beta, 3) / std::pow(1 + beta, 3));
}

TEST(FadingMemoryFilter, ConstantRateIsTrackedExactly) {
  // A closing obstacle: range 120 m, -8 m/s. No noise: the two-point start makes the estimate exact
  // and a g-h filter has no lag on a ramp, so it stays exact.
  FadingMemoryFilter filter(0.7);
  for (int k = 0; k < 60; ++k) {
    const double t = k * kDt;
    filter.Update(120 - 8 * t, kDt);
    EXPECT_NEAR(filter.value(), 120 - 8 * t, 1e-9) << "frame " << k;
    if (k >= 1) {
      EXPECT_NEAR(filter.rate(), -8, 1e-9) << "frame " << k;
    }
  }
  EXPECT_NEAR(filter.Predict(0.5), 120 - 8 * (59 * kDt + 0.5), 1e-9);
}

TEST(FadingMemoryFilter, IrregularTimeStepsUseTheRealInterval) {
  // Frames arrive 33, 67 and 100 ms apart (dropped frames): still exact on a ramp.
  FadingMemoryFilter filter(0.5);
  double t = 0;
  const double steps[] = {0.033, 0.067, 0.1};
  for (int k = 0; k < 40; ++k) {
    const double dt = steps[k % 3];
    t += dt;
    filter.Update(80 + 3 * t, dt);
  }
  EXPECT_NEAR(filter.value(), 80 + 3 * t, 1e-9);
  EXPECT_NEAR(filter.rate(), 3, 1e-9);
}

TEST(FadingMemoryFilter, FollowsAClosingRangeWithoutLag) {
  // A range closing at 20 m/s, with 0.5 m noise. A zeroth-order filter would lag by
  // rate * dt * beta / (1 - beta) = 1.56 m at beta 0.7: the first-order filter has no lag, so the
  // mean error over the last 200 frames is far smaller than that.
  FadingMemoryFilter filter(0.7);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.5);
  double mean_error = 0, mean_rate = 0;
  constexpr int kFrames = 400, kTail = 200;
  for (int k = 0; k < kFrames; ++k) {
    const double truth = 200 - 20 * k * kDt;
    filter.Update(truth + noise(rng), kDt);
    if (k >= kFrames - kTail) {
      mean_error += (filter.value() - truth) / kTail;
      mean_rate += filter.rate() / kTail;
    }
  }
  // Sampling error of the means: 0.618 * 0.5 / sqrt(200 / ~4 correlated frames) ~ 0.05 m;
  // 0.105 * 0.5 * 30 / sqrt(200 / ~12) ~ 0.4 m/s.
  EXPECT_LT(std::abs(mean_error), 0.15);
  EXPECT_NEAR(mean_rate, -20, 1.2);
}

TEST(FadingMemoryFilter, ReducesNoiseByTheAnalyticFactor) {
  // 20000 frames of a constant-rate range with white noise of 1 m. RMS errors after the start
  // against the closed form: value 0.618 sigma (1.6x less noise than raw), rate 0.105 sigma / dt.
  for (const double beta : {0.5, 0.7, 0.9}) {
    FadingMemoryFilter filter(beta);
    std::mt19937 rng(42);
    const double sigma = 1.0;
    std::normal_distribution<double> noise(0.0, sigma);
    double sum_value = 0, sum_rate = 0, sum_raw = 0;
    int n = 0;
    for (int k = 0; k < 20000; ++k) {
      const double truth = 500 - 12 * k * kDt;
      const double measured = truth + noise(rng);
      filter.Update(measured, kDt);
      if (k < 200) continue;  // the start
      sum_value += std::pow(filter.value() - truth, 2);
      sum_rate += std::pow(filter.rate() - (-12), 2);
      sum_raw += std::pow(measured - truth, 2);
      ++n;
    }
    const double raw_rms = std::sqrt(sum_raw / n);
    const double value_ratio = std::sqrt(sum_value / n) / raw_rms;
    const double rate_ratio = std::sqrt(sum_rate / n) / (raw_rms / kDt);
    EXPECT_NEAR(value_ratio, ValueNoiseRatio(beta), 0.05 * ValueNoiseRatio(beta))
        << "beta " << beta;
    EXPECT_NEAR(rate_ratio, RateNoiseRatio(beta), 0.08 * RateNoiseRatio(beta)) << "beta " << beta;
    if (beta == 0.7) {
      // The default: RMS error under 0.65 of the raw noise (analytic 0.618).
      EXPECT_LT(value_ratio, 0.65);
    }
  }
}

TEST(FadingMemoryFilter, SameTimeMeasurementDoesNotBreakTheRate) {
  FadingMemoryFilter filter(0.7);
  filter.Update(50, kDt);
  filter.Update(49, kDt);
  ASSERT_NEAR(filter.rate(), -30, 1e-9);
  filter.Update(49.5, 0.0);   // a repeated timestamp
  filter.Update(49.5, -1.0);  // an earlier one
  EXPECT_TRUE(std::isfinite(filter.value()));
  EXPECT_NEAR(filter.rate(), -30, 1e-9);
  EXPECT_EQ(filter.count(), 2);
  EXPECT_GT(filter.value(), 49.0);
  EXPECT_LT(filter.value(), 49.5);
}

TEST(FadingMemoryFilter, BetaOneIsTheExpandingMemoryLeastSquaresLine) {
  // beta = 1 never switches to the (zero) fading gains: every estimate is the least-squares line
  // through all the measurements so far, evaluated at the last time.
  FadingMemoryFilter filter(1.0);
  const double z[] = {10.0, 12.5, 13.0, 16.5, 17.0, 20.5};
  const int n = 6;
  for (int k = 0; k < n; ++k) filter.Update(z[k], 1.0);
  double st = 0, sz = 0, stt = 0, stz = 0;
  for (int k = 0; k < n; ++k) {
    st += k;
    sz += z[k];
    stt += k * k;
    stz += k * z[k];
  }
  const double slope = (n * stz - st * sz) / (n * stt - st * st);
  const double intercept = (sz - slope * st) / n;
  EXPECT_NEAR(filter.rate(), slope, 1e-9);
  EXPECT_NEAR(filter.value(), intercept + slope * (n - 1), 1e-9);
}

TEST(FadingMemoryFilter, ResetForgetsAndBetaIsChecked) {
  FadingMemoryFilter filter(0.7);
  filter.Update(10, kDt);
  filter.Update(11, kDt);
  filter.Reset();
  EXPECT_FALSE(filter.initialized());
  filter.Update(3, kDt);
  EXPECT_EQ(filter.value(), 3);
  EXPECT_EQ(filter.rate(), 0);
  EXPECT_THROW(FadingMemoryFilter(0.0), std::invalid_argument);
  EXPECT_THROW(FadingMemoryFilter(1.5), std::invalid_argument);
}

}  // namespace
}  // namespace stevi::tracking
