// The contact estimator (EKF on (s_h, sdot_h)) against the simulator: open-loop propagation,
// covariance behaviour, latency compensation, consistency (NEES) under model mismatch, errors.
// Expectations come from the physics (RK4 and hold error bounds, Kalman algebra, chi-square
// statistics) or from an independent computation, never from the estimator's own output.
#include "flatland/control/estimator.hpp"
#include "flatland/control/hand_input.hpp"
#include "flatland/sim/spec.hpp"

#include "control/estimator_harness.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

using namespace flatland;
using Estimator = control::Ekf;
using control::EstimatorConfig;
using control::EstimatorModel;
using control::HandInput;
using control::Measurement;

using namespace estimator_harness;

// With the hand held still the input is exact, so the only error is RK4's. A disk released at
// s_h = -0.8 oscillates in the palm well, crossing the junction at s_h = -1 where sddot_h jumps.
// RK4's global error is ~ A t w (w h)^4 / 120 with w the rate at which the solution's derivatives
// change: the well's frequency is only ~2 rad/s, but the disk crosses the outline's features
// (~0.1 in s_h) at |sdot_h| ~ 1/s, so w ~ 10-20 /s and the error is ~1e-10..1e-9 for A = 0.2,
// t = 2 s, h = 1 ms. The bound 1e-8 leaves room for that and fails on any real defect: a step
// straddling the junction costs ~1e-3 after one crossing, wrong RK4 weights or stage times
// ~1e-6.
TEST(Estimator, OpenLoopMatchesSimulatorWithTheHandStill) {
  sim::SimulationSpec spec = air_table(5.0);
  spec.motion.kind = sim::MotionSpec::Kind::kFixed;
  spec.motion.angle = 0.0;
  spec.initial.s_h = -0.8;
  spec.duration = 2.0;
  spec.run.integrator.max_step = 1e-3;  // keeps the truth's dense output error below 1e-12 too
  const sim::RunResult run = sim::run_spec(spec);
  ASSERT_EQ(run.reason, sim::StopReason::kEndTime);
  Estimator est(nominal_model(), {});
  est.reset(0.0, -0.8, 0.0);
  double worst = 0;
  for (int k = 0; k < 2000; ++k) {
    est.propagate((k + 1) * kDt, HandInput{});
    worst = std::max(worst, std::abs(est.estimate().s_h - run.trajectory.s_h((k + 1) * kDt)));
  }
  const double bound = 1e-8;
  std::printf("hand still: max |s_h error| over 2 s = %.3g (bound %.3g)\n", worst, bound);
  EXPECT_LT(worst, bound);
}

// The butterfly's first second, driven tick by tick. Besides RK4's error (as above, ~1e-12) the
// held acceleration differs from the motion's: with theta_ddot taken at mid-tick,
//   alpha_mid - alpha(tau) = j (h/2 - tau) + snap (h^2/8 - tau^2/2) + ...
// whose first term integrates to zero over the tick in velocity and to j h^3 / 12 in position
// (per tick, adding up linearly: c j t h^2 / 12), and whose second leaves a velocity error of
// -snap h^3 / 24 per tick (adding up to a position error c snap t^2 h^2 / 48). c = d sddot_h /
// d theta_ddot is the disk's response to the hand's angular acceleration (from the rolling model
// here, scanned over the s_h the disk visits). The disk stays in the palm well over this second
// (stable: errors are not amplified beyond ~1); a factor 10 covers that and the angle's own
// O(j h^3) error within a tick.
TEST(Estimator, OpenLoopMatchesSimulatorOnTheAirTableButterfly) {
  const Truth truth = simulate_truth(5.0);
  const sim::HandMotion& motion = *truth.problem->motion;
  const sim::Trajectory& tr = truth.run.trajectory;
  const double t_end = 1.0;
  Estimator est(nominal_model(), {});
  est.reset(0.0, tr.s_h(0.0), 0.0);
  double worst = 0, s_lo = 1e9, s_hi = -1e9;
  for (int k = 0; k < 1000; ++k) {
    est.propagate((k + 1) * kDt, exact_input(motion, k * kDt));
    const double s = tr.s_h((k + 1) * kDt);
    worst = std::max(worst, std::abs(est.estimate().s_h - s));
    s_lo = std::min(s_lo, s);
    s_hi = std::max(s_hi, s);
  }
  // The bound's ingredients, computed independently of the estimator.
  double jerk = 0, snap = 0;
  const double e = 1e-4;
  for (double t = e; t <= t_end; t += 1e-3) {
    auto alpha = [&](double tt) { return motion.at(tt).angular_acceleration; };
    jerk = std::max(jerk, std::abs(alpha(t + e) - alpha(t - e)) / (2 * e));
    snap = std::max(snap, std::abs(alpha(t + e) - 2 * alpha(t) + alpha(t - e)) / (e * e));
  }
  const sim::ReducedDiskRolling rolling(truth.problem);
  double c = 0;
  for (double s = s_lo; s <= s_hi; s += 0.01) {
    sim::HandKinematics h0, h1;
    h1.angular_acceleration = 1.0;
    const int piece = truth.problem->hand->piece_at(s, +1);
    c = std::max(
        c, std::abs(rolling.acceleration(h1, s, 0, piece) - rolling.acceleration(h0, s, 0, piece)));
  }
  const double bound =
      10.0 * c * (jerk * t_end * kDt * kDt / 12.0 + snap * t_end * t_end * kDt * kDt / 48.0);
  std::printf(
      "butterfly, first %.0f s: s_h in [%.3f, %.3f], max |s_h error| = %.3g; bound %.3g "
      "(c = %.3g, jerk = %.3g, snap = %.3g)\n",
      t_end, s_lo, s_hi, worst, bound, c, jerk, snap);
  EXPECT_LT(worst, bound);
}

// The same second driven as the loop drives it: the joint's readings (here exact: the motion's
// angle and rate at each tick) and the acceleration from their change over the tick before
// (HandInputFromJoint), the command (the mid-tick acceleration) only on the first tick. Tick k then
// holds the previous tick's mean acceleration abar_{k-1} instead of alpha(t_k + tau): the disk's
// rate is off by c h (abar_k - abar_{k-1}) more after each tick, and these telescope to
// c h (alpha(t) - alpha(0)), one tick's worth of the change of the hand's acceleration since the
// start (not a drift that grows tick by tick). Its integral is the position error,
//   |ds(t)| <= c h |omega(t) - omega(0) - t alpha(0)|,
// with c as above (its largest value over the s_h visited; the disk sees about half of it on
// average). The palm well is stable, so the dynamics do not amplify the error; a factor 2 covers
// the O(h^2) terms. Measured: about half the unpadded bound, and a delay of a few ticks more
// would exceed it.
TEST(Estimator, OpenLoopFromJointReadingsOnTheAirTableButterfly) {
  const Truth truth = simulate_truth(5.0);
  const sim::HandMotion& motion = *truth.problem->motion;
  const sim::Trajectory& tr = truth.run.trajectory;
  const double t_end = 1.0;
  Estimator est(nominal_model(), {});
  est.reset(0.0, tr.s_h(0.0), 0.0);
  control::HandInputFromJoint hand;
  double worst = 0, s_lo = 1e9, s_hi = -1e9;
  long from_command = 0;
  for (int k = 0; k < 1000; ++k) {
    const double t = k * kDt;
    const sim::HandKinematics now = motion.at(t);
    const control::HandInputChoice c = hand.next({t, now.angle, now.angular_velocity},
                                                 motion.at(t + 0.5 * kDt).angular_acceleration);
    from_command += c.source == control::AccelerationSource::kCommand;
    est.propagate((k + 1) * kDt, c.input);
    const double s = tr.s_h((k + 1) * kDt);
    worst = std::max(worst, std::abs(est.estimate().s_h - s));
    s_lo = std::min(s_lo, s);
    s_hi = std::max(s_hi, s);
  }
  EXPECT_EQ(from_command, 1);
  // The bound's ingredients, from the motion and the rolling model, not from the estimator.
  const sim::HandKinematics start = motion.at(0.0);
  double swing = 0;
  for (double t = 0; t <= t_end; t += 1e-3)
    swing = std::max(swing, std::abs(motion.at(t).angular_velocity - start.angular_velocity -
                                     t * start.angular_acceleration));
  const sim::ReducedDiskRolling rolling(truth.problem);
  double c = 0;
  for (double s = s_lo; s <= s_hi; s += 0.01) {
    sim::HandKinematics h0, h1;
    h1.angular_acceleration = 1.0;
    const int piece = truth.problem->hand->piece_at(s, +1);
    c = std::max(
        c, std::abs(rolling.acceleration(h1, s, 0, piece) - rolling.acceleration(h0, s, 0, piece)));
  }
  const double bound = 2.0 * c * kDt * swing;
  std::printf(
      "butterfly from readings, first %.0f s: max |s_h error| = %.3g; bound %.3g (c = %.3g, "
      "max |omega(t) - omega(0) - t alpha(0)| = %.3g rad/s)\n",
      t_end, worst, bound, c, swing);
  EXPECT_LT(worst, bound);
}

// The Kalman algebra, checked against a hand computation: an update with H = [1 0] gives
// P00+ = P00 R / (P00 + R) (< both), and the mean moves by P00 / (P00 + R) of the innovation.
// Without updates the variance of s_h grows: right after an update it is ~R while sdot_h's is
// much larger, so over the next frame it grows by ~P11 t^2 at least.
TEST(Estimator, UpdateShrinksAndPropagationGrowsTheVariance) {
  Estimator est(nominal_model(), {});
  est.reset(0.0, -1.0, 0.0);
  for (int k = 0; k < 50; ++k) est.propagate((k + 1) * kDt, HandInput{});
  const control::Estimate before = est.estimate();
  Measurement z{before.t, before.t, before.s_h + 1e-3, kSigmaZ};
  const control::UpdateReport r = est.update(z);
  ASSERT_TRUE(r.applied);
  const control::Estimate after = est.estimate();
  const double P00 = before.covariance(0, 0), R = kSigmaZ * kSigmaZ;
  EXPECT_NEAR(after.covariance(0, 0), P00 * R / (P00 + R), 1e-12 * P00);
  EXPECT_LT(after.covariance(0, 0), R);
  EXPECT_NEAR(after.s_h - before.s_h, P00 / (P00 + R) * 1e-3, 1e-12);
  EXPECT_NEAR(r.innovation, 1e-3, 1e-15);
  EXPECT_NEAR(r.innovation_sigma, std::sqrt(P00 + R), 1e-15);
  EXPECT_NEAR(r.nis, 1e-6 / (P00 + R), 1e-9 / (P00 + R));
  double previous = after.covariance(0, 0);
  for (int k = 50; k < 83; ++k) {
    est.propagate((k + 1) * kDt, HandInput{});
    const double v = est.estimate().covariance(0, 0);
    EXPECT_GT(v, previous) << "tick " << k;
    previous = v;
  }
  EXPECT_GT(previous, after.covariance(0, 0) + 0.5 * after.covariance(1, 1) * 0.033 * 0.033);
}

// The constant-velocity model is linear: its covariance has a closed form,
// P00(t) = P00 + 2 t P01 + t^2 P11 + q^2 t^3 / 3, growing from the start.
TEST(Estimator, ConstantVelocityCovarianceHasItsClosedForm) {
  EstimatorConfig cfg;
  cfg.model = EstimatorModel::kConstantVelocity;
  Estimator est(nominal_model(), cfg);
  est.reset(1.0, -1.0, 0.5);
  const double s2 = cfg.initial_sigma_s * cfg.initial_sigma_s;
  const double v2 = cfg.initial_sigma_sdot * cfg.initial_sigma_sdot;
  const double q2 = cfg.process_noise * cfg.process_noise;
  double previous = s2;
  for (int k = 1; k <= 200; ++k) {
    est.propagate(1.0 + k * kDt, HandInput{0.3, 1.0, 5.0});
    const double t = k * kDt;
    const control::Estimate e = est.estimate();
    EXPECT_NEAR(e.covariance(0, 0), s2 + t * t * v2 + q2 * t * t * t / 3, 1e-12 * s2);
    EXPECT_NEAR(e.s_h, -1.0 + 0.5 * t, 1e-12);
    EXPECT_GT(e.covariance(0, 0), previous);
    previous = e.covariance(0, 0);
  }
}

// Rewinding is exact: a late measurement leaves the same belief as the same measurement applied
// on time (estimator_harness.hpp).
TEST(Estimator, LateUpdateEqualsOnTimeUpdate) { expect_late_update_equals_on_time(make_ekf); }

// 30 Hz measurements arriving 33 ms late. Applied as if current, each one drags the estimate
// back by ~|sdot_h| x 33 ms (sdot_h reaches ~1/s mid-roll, i.e. ~3e-2 against a noise of 2e-4);
// applied at its capture time the only errors left are the noise's and the prediction's over
// the latency (the filter's sdot_h uncertainty times 33-66 ms): several times smaller.
TEST(Estimator, LatencyCompensationReducesTheError) {
  const Truth truth = simulate_truth(5.0);
  ASSERT_EQ(truth.run.reason, sim::StopReason::kEndTime);
  EstimatorConfig on, off;
  off.latency_compensation = false;
  const double rms_on = run_filter(truth, on, 7, false).rms();
  const double rms_off = run_filter(truth, off, 7, false).rms();
  EstimatorConfig cv = on;
  cv.model = EstimatorModel::kConstantVelocity;
  const double rms_cv = run_filter(truth, cv, 7, false).rms();
  std::printf("RMS s_h error over %.2f s: compensated %.3g, uncompensated %.3g, CV %.3g\n",
              truth.t_end(), rms_on, rms_off, rms_cv);
  EXPECT_LT(5.0 * rms_on, rms_off);
}

// Consistency under model mismatch: the truth at tilt 5.1 deg (2 % more gravity in the plane),
// the filter assuming 5 deg. NEES sampled every 0.2 s (longer than the error's correlation time
// of a few frames, so the samples are close to independent), over many seeds (noise and initial
// error drawn from the initial covariance): the average must lie in the two-sided 95 % bounds of
// chi2(2N) / N.
TEST(Estimator, ConsistentUnderModelMismatch) {
  const Truth truth = simulate_truth(5.1);
  std::printf("truth at 5.1 deg: %s at t = %.3f, s_h = %.3f\n",
              sim::to_string(truth.run.reason).c_str(), truth.t_end(), truth.run.final.s_h);
  ASSERT_GT(truth.t_end(), 3.0);
  const int seeds = 40;
  auto average = [&](EstimatorConfig cfg, long& n) {
    double sum = 0;
    n = 0;
    for (int seed = 0; seed < seeds; ++seed) {
      const RunStats s = run_filter(truth, cfg, 1000 + seed, true, 0.2);
      for (double v : s.nees) sum += v;
      n += static_cast<long>(s.nees.size());
    }
    return sum / n;
  };
  long n = 0, n_off = 0, n_cv = 0;
  EstimatorConfig on, off, cv;
  off.latency_compensation = false;
  cv.model = EstimatorModel::kConstantVelocity;
  const double nees_on = average(on, n);
  const double nees_off = average(off, n_off);
  const double nees_cv = average(cv, n_cv);
  const auto [lo, hi] = mean_chi2_bounds(static_cast<int>(n), 2);
  std::printf(
      "averaged NEES (N = %ld, q = %g): compensated %.3f in [%.3f, %.3f]; uncompensated %.3g; "
      "constant-velocity %.3g\n",
      n, on.process_noise, nees_on, lo, hi, nees_off, nees_cv);
  EXPECT_GT(nees_on, lo);
  EXPECT_LT(nees_on, hi);
  // Stale measurements applied as current bias the estimate by ~sdot x latency, far outside
  // the covariance.
  EXPECT_GT(nees_off, hi);
  EXPECT_GT(nees_off, nees_on);
}

TEST(Estimator, RejectsBadConfigNamingTheField) {
  const auto model = nominal_model();
  auto expect_message = [&](EstimatorConfig cfg, const std::string& text) {
    try {
      Estimator e(model, cfg);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const std::invalid_argument& ex) {
      EXPECT_NE(std::string(ex.what()).find(text), std::string::npos) << ex.what();
    }
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EstimatorConfig c;
  c.process_noise = -1;
  expect_message(c, "estimator.process_noise: must be positive, got -1");
  c = {};
  c.process_noise = nan;
  expect_message(c, "estimator.process_noise");
  c = {};
  c.history = 0;
  expect_message(c, "estimator.history: must be positive, got 0");
  c = {};
  c.initial_sigma_s = -0.5;
  expect_message(c, "estimator.initial_sigma_s");
  c = {};
  c.initial_sigma_sdot = nan;
  expect_message(c, "estimator.initial_sigma_sdot");
  c = {};
  c.history = std::numeric_limits<double>::infinity();
  expect_message(c, "estimator.history");

  auto ellipse = std::make_shared<sim::RollingProblem>(*model);
  ellipse->object = sim::make_uniform_ellipse(0.06, 0.04);
  EXPECT_THROW(Estimator(ellipse, {}), std::invalid_argument);
  EXPECT_EQ(control::parse_estimator_model("constant-velocity"), EstimatorModel::kConstantVelocity);
  EXPECT_EQ(control::to_string(control::parse_estimator_model("rolling")), "rolling");
  EXPECT_THROW(control::parse_estimator_model("kalman"), std::invalid_argument);
}

TEST(Estimator, RejectsTimeGoingBackAndFutureCaptures) {
  Estimator est(nominal_model(), {});
  est.reset(1.0, -1.0, 0.0);
  EXPECT_THROW(est.propagate(1.0, {}), std::invalid_argument);
  EXPECT_THROW(est.propagate(0.5, {}), std::invalid_argument);
  est.propagate(1.001, {});
  EXPECT_THROW(est.update({1.01, 1.01, -1.0, kSigmaZ}), std::invalid_argument);
  EXPECT_THROW(est.update({1.0, 1.001, -1.0, 0.0}), std::invalid_argument);
  EXPECT_EQ(est.counts().steps, 1);
}

// A capture older than the stored history cannot be applied (the loop logs and drops it); one
// inside it can, and then re-propagates every step since.
TEST(Estimator, CaptureOlderThanHistoryIsNotApplied) {
  EstimatorConfig cfg;
  cfg.history = 0.05;
  Estimator est(nominal_model(), cfg);
  est.reset(0.0, -1.0, 0.0);
  for (int k = 0; k < 200; ++k) est.propagate((k + 1) * kDt, {});
  const control::Estimate before = est.estimate();
  const control::UpdateReport old = est.update({0.1, 0.2, -1.0, kSigmaZ});
  EXPECT_FALSE(old.applied);
  EXPECT_EQ(est.counts().updates, 0);
  EXPECT_EQ(est.estimate().s_h, before.s_h);
  EXPECT_TRUE(est.estimate().covariance == before.covariance);
  // Inside the step [0.170, 0.171): that step and the 29 after it are redone.
  const control::UpdateReport recent = est.update({0.1705, 0.2, -1.0, kSigmaZ});
  EXPECT_TRUE(recent.applied);
  EXPECT_EQ(recent.repropagated_steps, 30);
  EXPECT_EQ(est.counts().repropagated, 30);
  EXPECT_LT(est.estimate().covariance(0, 0), before.covariance(0, 0));
}

// An input that makes the dynamics overflow is reported with the time and s_h, not carried on.
TEST(Estimator, NonFiniteStateIsARuntimeError) {
  Estimator est(nominal_model(), {});
  est.reset(0.0, -0.5, 0.0);
  try {
    est.propagate(kDt, {0.0, 0.0, 1e308});
    FAIL() << "no error";
  } catch (const std::runtime_error& ex) {
    const std::string what = ex.what();
    EXPECT_NE(what.find("t = 0.001"), std::string::npos) << what;
    EXPECT_NE(what.find("s_h"), std::string::npos) << what;
  }
}
