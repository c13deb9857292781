// The estimators' test harness (tests/control/test_estimator.cpp, test_ukf.cpp): the paper's
// air-table butterfly simulated as the truth, the hand input a loop would give, and a
// closed-loop-like run of any filter against that truth (1 kHz ticks, 30 Hz measurements of the
// true s_h arriving 33 ms late) with its errors and NEES samples.
#pragma once

#include "flatland/control/estimator.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <numbers>
#include <random>
#include <utility>
#include <vector>

namespace estimator_harness {

using namespace flatland;
using control::EstimatorConfig;
using control::HandInput;
using control::Measurement;

constexpr double kDt = 1e-3;           // the loop's tick
constexpr double kFrame = 1.0 / 30.0;  // camera frame interval
constexpr double kLatency = 0.033;     // capture -> arrival
constexpr double kSigmaZ = 2e-4;       // vision noise on s_h
constexpr double kDeg = std::numbers::pi / 180.0;

// The paper's air-table butterfly (section 5): tilt 5 deg, 2T = 4 s, k solving that period.
inline sim::SimulationSpec air_table(double tilt_deg) {
  sim::SimulationSpec spec;
  spec.tilt = tilt_deg * kDeg;
  spec.motion.period = 4.0;
  spec.motion.k = -1.1395840;
  spec.duration = 4.0;
  spec.run.integrator.rtol = 1e-12;
  spec.run.integrator.atol = 1e-14;
  spec.run.record = true;
  return spec;
}

struct Truth {
  sim::RunResult run;
  std::shared_ptr<const sim::RollingProblem> problem;
  double t_end() const { return run.trajectory.t_end(); }
};

inline Truth simulate_truth(double tilt_deg) {
  const sim::SimulationSpec spec = air_table(tilt_deg);
  return {sim::run_spec(spec), sim::build_problem(spec)};
}

// What the estimator models: the air table at 5 deg.
inline std::shared_ptr<const sim::RollingProblem> nominal_model() {
  static const auto model = sim::build_problem(air_table(5.0));
  return model;
}

// The hand input of the tick starting at t: the motion's exact angle and rate at t and its
// acceleration at mid-tick, so the held acceleration's error averages out over the tick (see
// Estimator.OpenLoopMatchesSimulatorOnTheAirTableButterfly).
inline HandInput exact_input(const sim::HandMotion& m, double t) {
  const sim::HandKinematics k0 = m.at(t);
  return {k0.angle, k0.angular_velocity, m.at(t + 0.5 * kDt).angular_acceleration};
}

// Two-sided 95 % bounds of the mean of n chi-square(dof) samples: chi2(n dof) / n, by the
// Wilson-Hilferty approximation (relative error < 1e-3 for n dof > 100).
inline std::pair<double, double> mean_chi2_bounds(int n, int dof) {
  const double k = static_cast<double>(n) * dof;
  const double z = 1.959963984540054;
  auto quantile = [&](double zp) {
    const double c = 2.0 / (9.0 * k);
    return k * std::pow(1.0 - c + zp * std::sqrt(c), 3);
  };
  return {quantile(-z) / n, quantile(z) / n};
}

// A filter on the nominal model with a config (the type under test).
using MakeFilter =
    std::function<std::unique_ptr<control::Estimator>(const EstimatorConfig& config)>;

inline std::unique_ptr<control::Estimator> make_ekf(const EstimatorConfig& config) {
  return std::make_unique<control::Ekf>(nominal_model(), config);
}

// A closed-loop-like run: 1 kHz ticks with the motion's exact input, measurements of the true
// s_h at 30 Hz captures arriving kLatency late. Returns per-tick errors and NEES samples.
struct RunStats {
  double sum_sq_error = 0;  // of s_h over every tick
  long ticks = 0;
  std::vector<double> nees;  // at the sampling times
  double rms() const { return std::sqrt(sum_sq_error / ticks); }
};

inline RunStats run_filter(const Truth& truth, EstimatorConfig cfg, std::uint64_t seed,
                           bool perturb_initial, double nees_every = 0.0,
                           const MakeFilter& make = make_ekf) {
  const sim::HandMotion& motion = *truth.problem->motion;
  const sim::Trajectory& tr = truth.run.trajectory;
  const std::unique_ptr<control::Estimator> filter = make(cfg);
  control::Estimator& est = *filter;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  double s0 = tr.s_h(0.0), v0 = tr.sample(0.0).sdot_h;
  if (perturb_initial) {  // an initial error drawn from the initial covariance
    s0 += cfg.initial_sigma_s * normal(rng);
    v0 += cfg.initial_sigma_sdot * normal(rng);
  }
  est.reset(0.0, s0, v0);
  RunStats out;
  const long n_ticks = static_cast<long>(std::floor(truth.t_end() / kDt + 1e-9));
  int next_frame = 1;
  Measurement pending;
  bool have_pending = false;
  const long nees_stride = nees_every > 0 ? std::lround(nees_every / kDt) : 0;
  for (long k = 0; k < n_ticks; ++k) {
    const double t = k * kDt;
    est.propagate((k + 1) * kDt, exact_input(motion, t));
    const double now = (k + 1) * kDt;
    // Capture frames as their exposure time passes; deliver them kLatency later.
    if (!have_pending && next_frame * kFrame <= now) {
      pending.t_capture = next_frame * kFrame;
      pending.t_arrival = pending.t_capture + kLatency;
      pending.s_h = tr.s_h(pending.t_capture) + kSigmaZ * normal(rng);
      pending.sigma = kSigmaZ;
      have_pending = true;
      ++next_frame;
    }
    if (have_pending && pending.t_arrival <= now + 1e-12) {
      const control::UpdateReport r = est.update(pending);
      EXPECT_TRUE(r.applied);
      have_pending = false;
    }
    const control::Estimate e = est.estimate();
    const double err = e.s_h - tr.s_h(now);
    out.sum_sq_error += err * err;
    ++out.ticks;
    if (nees_stride > 0 && (k + 1) % nees_stride == 0)
      out.nees.push_back(control::nees(e, tr.s_h(now), tr.sample(now).sdot_h));
  }
  return out;
}

// Rewinding is exact: a measurement that arrives late, corrected at its capture time and
// re-propagated, leaves the same belief as the same measurement applied on time (by a second
// estimator that stops at the capture time, updates there and goes on with the input advanced
// over the part of the tick already done, computed here).
inline void expect_late_update_equals_on_time(const MakeFilter& make) {
  const Truth truth = simulate_truth(5.0);
  const sim::HandMotion& motion = *truth.problem->motion;
  for (const double capture : {0.5, 0.5004}) {  // on a tick boundary, and inside a tick
    const std::unique_ptr<control::Estimator> late_filter = make({}), on_time_filter = make({});
    control::Estimator &late = *late_filter, &on_time = *on_time_filter;
    late.reset(0.0, -1.0, 0.0);
    on_time.reset(0.0, -1.0, 0.0);
    const Measurement z{capture, capture + kLatency, truth.run.trajectory.s_h(capture) + 3e-4,
                        kSigmaZ};
    const int n = 550;
    for (int k = 0; k < n; ++k) {
      const double t0 = k * kDt, t1 = (k + 1) * kDt;
      const HandInput u = exact_input(motion, t0);
      late.propagate(t1, u);
      if (t0 <= capture && capture < t1 && capture > t0) {
        on_time.propagate(capture, u);
        on_time.update(z);
        const double tau = capture - t0;
        on_time.propagate(t1, {u.theta + u.theta_dot * tau + 0.5 * u.theta_ddot * tau * tau,
                               u.theta_dot + u.theta_ddot * tau, u.theta_ddot});
      } else {
        on_time.propagate(t1, u);
        if (std::abs(t1 - capture) < 1e-12) on_time.update(z);
      }
    }
    const control::UpdateReport r = late.update(z);
    ASSERT_TRUE(r.applied);
    EXPECT_GE(r.repropagated_steps, 50);  // capture 50 ms before the current time
    EXPECT_LE(r.repropagated_steps, 51);
    const control::Estimate a = late.estimate(), b = on_time.estimate();
    EXPECT_NEAR(a.s_h, b.s_h, 1e-12) << capture;
    EXPECT_NEAR(a.sdot_h, b.sdot_h, 1e-11) << capture;
    EXPECT_NEAR(a.covariance(0, 0), b.covariance(0, 0), 1e-9 * b.covariance(0, 0)) << capture;
    EXPECT_NEAR(a.covariance(1, 1), b.covariance(1, 1), 1e-9 * b.covariance(1, 1)) << capture;
  }
}

}  // namespace estimator_harness
