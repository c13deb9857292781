// The unscented Kalman filter (type `ukf`) against what is known without it: on a linear model
// the unscented transform is exact, so it must equal the extended filter (and the closed form)
// to rounding whatever its sigma-point parameters; on the rolling model its NEES must be
// consistent on the estimators' harness (the simulated butterfly, estimator_harness.hpp); a late
// measurement must give the on-time belief; bad input is refused naming the field.
#include "flatland/control/choice.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/control/ukf.hpp"
#include "flatland/sim/spec.hpp"

#include "control/estimator_harness.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

using namespace flatland;
using namespace estimator_harness;
using control::EstimatorModel;
using control::UkfConfig;

namespace {

std::unique_ptr<control::Estimator> make_ukf(const EstimatorConfig& config) {
  return std::make_unique<control::Ukf>(nominal_model(), config);
}

// Sigma-point parameters across their range: the defaults (all weights positive), a small
// spread of the scaled transform (alpha 0.01: a centre weight of -9999) and a wide one.
const UkfConfig kSigmaPointChoices[] = {{}, {1e-2, 2.0, 0.0}, {0.5, 0.0, 3.0}};

}  // namespace

// With the constant-velocity model the dynamics are linear (x+ = Phi x): the sigma points'
// recombined mean is Phi x and their covariance Phi P Phi^T, exactly up to rounding, for any
// alpha, beta, kappa. So the UKF must track the EKF (which propagates the same model in closed
// form) to rounding over 0.4 s of ticks with latency-compensated updates, and the variance of
// s_h must follow its closed form P00 + 2 t P01 + t^2 P11 + q^2 t^3 / 3 before the first update.
// "Rounding" grows as the spread shrinks: each point x + sqrt(n + lambda) L_j is stored with an
// absolute error of ~1e-16 (s_h ~ 1), and the deviations carry weights 1 / (2 alpha^2 (n + kappa)),
// so the mean's error is ~1e-16 / alpha^2 per step and the covariance's, relative to the
// deviations (alpha sigma), ~1e-16 / (alpha sigma) with sigma >= 2e-4: hence the bounds
// 1e-12 / alpha^2 and 1e-10 / alpha, which leave two orders of magnitude over 400 steps.
TEST(Ukf, EqualsTheEkfToRoundingOnALinearModel) {
  EstimatorConfig cfg;
  cfg.model = EstimatorModel::kConstantVelocity;
  const double s2 = cfg.initial_sigma_s * cfg.initial_sigma_s;
  const double v2 = cfg.initial_sigma_sdot * cfg.initial_sigma_sdot;
  const double q2 = cfg.process_noise * cfg.process_noise;
  for (const UkfConfig& sigma_points : kSigmaPointChoices) {
    SCOPED_TRACE("alpha " + std::to_string(sigma_points.alpha));
    const double alpha = sigma_points.alpha;
    control::Ukf ukf(nominal_model(), cfg, sigma_points);
    control::Ekf ekf(nominal_model(), cfg);
    ukf.reset(1.0, -1.0, 0.5);
    ekf.reset(1.0, -1.0, 0.5);
    double worst_s = 0, worst_p = 0;
    for (int k = 1; k <= 400; ++k) {
      const double t = 1.0 + k * kDt;
      const HandInput u{0.3 + 0.01 * k, 1.0, 5.0};  // unused by the model: it must not matter
      ukf.propagate(t, u);
      ekf.propagate(t, u);
      if (k < 30) {
        const double tau = k * kDt;
        EXPECT_NEAR(ukf.estimate().covariance(0, 0), s2 + tau * tau * v2 + q2 * tau * tau * tau / 3,
                    1e-10 / alpha * s2);
      }
      if (k % 33 == 0) {  // captured 20.5 ms ago, inside a tick
        const Measurement z{t - 0.0205, t, -1.0 + 0.5 * (t - 1.0205) + 3e-4, kSigmaZ};
        const control::UpdateReport a = ukf.update(z), b = ekf.update(z);
        ASSERT_TRUE(a.applied && b.applied);
        EXPECT_NEAR(a.innovation, b.innovation, 1e-12 / (alpha * alpha));
        EXPECT_NEAR(a.innovation_sigma, b.innovation_sigma, 1e-10 / alpha * b.innovation_sigma);
      }
      const control::Estimate a = ukf.estimate(), b = ekf.estimate();
      worst_s = std::max({worst_s, std::abs(a.s_h - b.s_h), std::abs(a.sdot_h - b.sdot_h)});
      for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j)
          worst_p = std::max(worst_p, std::abs(a.covariance(i, j) - b.covariance(i, j)) /
                                          std::sqrt(b.covariance(i, i) * b.covariance(j, j)));
    }
    std::printf(
        "linear model, alpha %g beta %g kappa %g: max |UKF - EKF| state %.3g, covariance %.3g "
        "(relative to the standard deviations)\n",
        sigma_points.alpha, sigma_points.beta, sigma_points.kappa, worst_s, worst_p);
    EXPECT_LT(worst_s, 1e-12 / (alpha * alpha));
    EXPECT_LT(worst_p, 1e-10 / alpha);
  }
}

// With an (almost) certain belief the sigma points collapse onto the mean, so the UKF's mean is
// RK4 on the rolling model: the hand held still, the disk released at s_h = -0.8 oscillating
// across the palm junction, must match the simulator as closely as RK4 does (bound and reasoning
// as Estimator.OpenLoopMatchesSimulatorWithTheHandStill; the points' spread of ~2e-9 adds a
// second-order term of ~1e-17).
TEST(Ukf, CollapsedBeliefFollowsTheSimulatorLikeRk4) {
  sim::SimulationSpec spec = air_table(5.0);
  spec.motion.kind = sim::MotionSpec::Kind::kFixed;
  spec.motion.angle = 0.0;
  spec.initial.s_h = -0.8;
  spec.duration = 2.0;
  spec.run.integrator.max_step = 1e-3;
  const sim::RunResult run = sim::run_spec(spec);
  ASSERT_EQ(run.reason, sim::StopReason::kEndTime);
  EstimatorConfig cfg;
  cfg.initial_sigma_s = cfg.initial_sigma_sdot = 1e-9;
  cfg.process_noise = 1e-12;
  control::Ukf est(nominal_model(), cfg);
  est.reset(0.0, -0.8, 0.0);
  double worst = 0;
  for (int k = 0; k < 2000; ++k) {
    est.propagate((k + 1) * kDt, HandInput{});
    worst = std::max(worst, std::abs(est.estimate().s_h - run.trajectory.s_h((k + 1) * kDt)));
  }
  std::printf("UKF, hand still, collapsed belief: max |s_h error| over 2 s = %.3g (bound 1e-8)\n",
              worst);
  EXPECT_LT(worst, 1e-8);
}

TEST(Ukf, LateUpdateEqualsOnTimeUpdate) { expect_late_update_equals_on_time(make_ukf); }

// As Estimator.LatencyCompensationReducesTheError: stale measurements applied as current drag the
// estimate back by ~|sdot_h| x 33 ms; applied at their capture time, several times less.
TEST(Ukf, LatencyCompensationReducesTheError) {
  const Truth truth = simulate_truth(5.0);
  ASSERT_EQ(truth.run.reason, sim::StopReason::kEndTime);
  EstimatorConfig on, off;
  off.latency_compensation = false;
  const double rms_on = run_filter(truth, on, 7, false, 0.0, make_ukf).rms();
  const double rms_off = run_filter(truth, off, 7, false, 0.0, make_ukf).rms();
  const double rms_ekf = run_filter(truth, on, 7, false, 0.0, make_ekf).rms();
  std::printf(
      "UKF RMS s_h error over %.2f s (exact model): compensated %.3g, uncompensated %.3g; the EKF "
      "on the same data %.3g\n",
      truth.t_end(), rms_on, rms_off, rms_ekf);
  EXPECT_LT(5.0 * rms_on, rms_off);
}

// Consistency under model mismatch on the EKF's harness (Estimator.ConsistentUnderModelMismatch):
// truth at tilt 5.1 deg, the filter assuming 5 deg, 40 seeds, NEES every 0.2 s, at the library's
// process noise. The time-averaged NEES must lie in the two-sided 95 % bounds of chi2(2N) / N.
TEST(Ukf, ConsistentUnderModelMismatch) {
  const Truth truth = simulate_truth(5.1);
  ASSERT_GT(truth.t_end(), 3.0);
  const int seeds = 40;
  auto average = [&](const MakeFilter& make, long& n, double& rms) {
    double sum = 0, sum_sq = 0;
    long ticks = 0;
    n = 0;
    for (int seed = 0; seed < seeds; ++seed) {
      const RunStats s = run_filter(truth, {}, 1000 + seed, true, 0.2, make);
      for (double v : s.nees) sum += v;
      n += static_cast<long>(s.nees.size());
      sum_sq += s.sum_sq_error;
      ticks += s.ticks;
    }
    rms = std::sqrt(sum_sq / ticks);
    return sum / n;
  };
  long n = 0, n_ekf = 0;
  double rms = 0, rms_ekf = 0;
  const double nees_ukf = average(make_ukf, n, rms);
  const double nees_ekf = average(make_ekf, n_ekf, rms_ekf);
  const auto [lo, hi] = mean_chi2_bounds(static_cast<int>(n), 2);
  std::printf(
      "averaged NEES (N = %ld, q = %g): UKF %.3f in [%.3f, %.3f] (RMS s_h error %.3g); the EKF "
      "on the same data %.3f (RMS %.3g)\n",
      n, EstimatorConfig{}.process_noise, nees_ukf, lo, hi, rms, nees_ekf, rms_ekf);
  EXPECT_EQ(n, n_ekf);
  EXPECT_GT(nees_ukf, lo);
  EXPECT_LT(nees_ukf, hi);
}

TEST(Ukf, RejectsBadSigmaPointsNamingTheField) {
  auto expect_message = [&](UkfConfig sigma_points, const std::string& text) {
    try {
      control::Ukf ukf(nominal_model(), {}, sigma_points);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(text), std::string::npos) << e.what();
    }
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  expect_message({0.0, 2.0, 1.0}, "estimator.ukf.alpha: must be in [1e-04, 1], got 0");
  expect_message({1.5, 2.0, 1.0}, "estimator.ukf.alpha");
  expect_message({nan, 2.0, 1.0}, "estimator.ukf.alpha");
  expect_message({1.0, -1.0, 1.0}, "estimator.ukf.beta: must be finite and >= 0, got -1");
  expect_message({1.0, 2.0, -0.5}, "estimator.ukf.kappa: must be finite and >= 0, got -0.5");
  expect_message({1.0, 2.0, std::numeric_limits<double>::infinity()}, "estimator.ukf.kappa");
  // The shared config is checked as the EKF's is.
  EstimatorConfig bad;
  bad.process_noise = -1;
  EXPECT_THROW(control::Ukf(nominal_model(), bad), std::invalid_argument);
  auto ellipse = std::make_shared<sim::RollingProblem>(*nominal_model());
  ellipse->object = sim::make_uniform_ellipse(0.06, 0.04);
  EXPECT_THROW(control::Ukf(ellipse, {}), std::invalid_argument);
}

TEST(Ukf, RejectsTimeGoingBackFutureCapturesAndNonFiniteInput) {
  control::Ukf est(nominal_model(), {});
  est.reset(1.0, -1.0, 0.0);
  EXPECT_THROW(est.propagate(1.0, {}), std::invalid_argument);
  EXPECT_THROW(est.propagate(0.5, {}), std::invalid_argument);
  EXPECT_THROW(est.propagate(1.001, {std::nan(""), 0, 0}), std::invalid_argument);
  est.propagate(1.001, {});
  EXPECT_THROW(est.update({1.01, 1.01, -1.0, kSigmaZ}), std::invalid_argument);
  EXPECT_THROW(est.update({1.0, 1.001, -1.0, 0.0}), std::invalid_argument);
  EXPECT_EQ(est.counts().steps, 1);
  EXPECT_EQ(est.counts().updates, 0);
  // An input that makes the dynamics overflow is reported with the time and s_h.
  est.reset(0.0, -0.5, 0.0);
  try {
    est.propagate(kDt, {0.0, 0.0, 1e308});
    FAIL() << "no error";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("t = 0.001"), std::string::npos) << what;
    EXPECT_NE(what.find("s_h"), std::string::npos) << what;
  }
}

// The registry makes it by name with the choice's sigma points, and names it in the list of
// known types.
TEST(Ukf, IsABuiltInEstimatorType) {
  control::EstimatorChoice choice;
  choice.type = "ukf";
  choice.ukf.alpha = 0.5;
  const auto made = control::make_estimator(choice, nominal_model());
  ASSERT_NE(dynamic_cast<control::Ukf*>(made.get()), nullptr);
  EXPECT_EQ(made->name(), "ukf");
  EXPECT_EQ(dynamic_cast<control::Ukf&>(*made).sigma_points().alpha, 0.5);
  choice.type = "particle";
  try {
    control::make_estimator(choice, nominal_model());
    ADD_FAILURE() << "made an unknown type";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "estimator.type: unknown type 'particle' (known: ekf, ukf)");
  }
}
