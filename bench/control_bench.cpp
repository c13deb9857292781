// Cost of the contact estimator per 1 kHz tick (docs/ESTIMATOR.md): one propagation step, one
// latency-compensated update (rewind 33 ms, correct, re-propagate), and the average tick of a
// loop with a 30 Hz camera, with the hand input as the loop makes it (the joint's readings, the
// acceleration from their change: control/hand_input.hpp) against the commanded acceleration
// given directly (the loop before issue 24). The budget for estimator + controller is 5 us per
// tick. The unscented filter against the extended one on the same inputs (BM_FilterPropagate,
// BM_FilterTick: arg 0 the EKF, arg 1 the UKF; their ratio in one run is the UKF's cost).
// Run: build/bin/flatland_control_bench
#include <benchmark/benchmark.h>

#include "flatland/control/estimator.hpp"
#include "flatland/control/hand_input.hpp"
#include "flatland/control/ukf.hpp"
#include "flatland/sim/spec.hpp"

#include <numbers>

using namespace flatland;

namespace {

constexpr double kDt = 1e-3;

// The air-table butterfly (5 deg, 2T = 4 s): the model and, from its motion, realistic inputs.
sim::SimulationSpec spec() {
  sim::SimulationSpec spec;
  spec.tilt = 5.0 * std::numbers::pi / 180.0;
  spec.motion.period = 4.0;
  spec.motion.k = -1.1395840;
  return spec;
}

std::shared_ptr<const sim::RollingProblem> model() {
  static const auto pb = sim::build_problem(spec());
  return pb;
}

// Mid-roll (from t = 1.5 s, the disk moving toward the fingertip): the true trajectory and the
// inputs for a window of ticks, precomputed so the benchmark measures the estimator only.
struct Window {
  static constexpr int kCount = 1000;
  double t0 = 1.5;
  control::HandInput u[kCount];
  control::JointReading readings[kCount];  ///< the motion's angle and rate at each tick
  double s_true[kCount + 1], sdot0 = 0;
  Window() {
    const sim::RunResult run = sim::run_spec(spec());
    const sim::HandMotion& m = *model()->motion;
    for (int i = 0; i < kCount; ++i) {
      const sim::HandKinematics k = m.at(t0 + i * kDt);
      u[i] = {k.angle, k.angular_velocity, m.at(t0 + (i + 0.5) * kDt).angular_acceleration};
      readings[i] = {t0 + i * kDt, k.angle, k.angular_velocity};
    }
    for (int i = 0; i <= kCount; ++i) s_true[i] = run.trajectory.s_h(t0 + i * kDt);
    sdot0 = run.trajectory.sample(t0).sdot_h;
  }
};
const Window& inputs() {
  static const Window in;
  return in;
}
using Inputs = Window;

// Starts the estimator at t0 on the true state with 400 ms of history behind it.
control::Ekf warmed_up(control::EstimatorConfig cfg = {}) {
  const Window& w = inputs();
  control::Ekf est(model(), cfg);
  est.reset(w.t0, w.s_true[0], w.sdot0);
  for (int i = 0; i < 400; ++i) est.propagate(w.t0 + (i + 1) * kDt, w.u[i]);
  return est;
}

void BM_EstimatorPropagate(benchmark::State& state) {
  control::EstimatorConfig cfg;
  cfg.model = static_cast<control::EstimatorModel>(state.range(0));
  control::Ekf est = warmed_up(cfg);
  const Inputs& in = inputs();
  long i = 400;
  for (auto _ : state) {
    if (i == Inputs::kCount) {  // stay inside the window: restart (outside the timing)
      state.PauseTiming();
      est = warmed_up(cfg);
      i = 400;
      state.ResumeTiming();
    }
    est.propagate(in.t0 + (i + 1) * kDt, in.u[i]);
    ++i;
    benchmark::DoNotOptimize(est);
  }
  state.SetLabel(control::to_string(cfg.model));
}
BENCHMARK(BM_EstimatorPropagate)->Arg(0)->Arg(1);

// One update captured 33 ms ago (mid-tick): rewinds through 33 stored steps.
void BM_EstimatorUpdateWithLatency(benchmark::State& state) {
  const control::Ekf base = warmed_up();
  const double now = base.estimate().t;
  const control::Measurement z{now - 0.0325, now, inputs().s_true[367] + 1e-4, 2e-4};
  control::Ekf est = base;
  int repropagated = 0;
  for (auto _ : state) {
    state.PauseTiming();
    est = base;  // the same history every time
    state.ResumeTiming();
    const control::UpdateReport r = est.update(z);
    repropagated = r.repropagated_steps;
    benchmark::DoNotOptimize(r);
  }
  state.counters["repropagated"] = repropagated;
}
BENCHMARK(BM_EstimatorUpdateWithLatency);

// The loop's average tick: propagate every 1 ms, an update (33 ms old) every 33 ticks. Arg 0:
// the hand input with the commanded acceleration, as the loop propagated before issue 24; arg 1:
// the hand input from the joint's readings (HandInputFromJoint, as the loop does now), the command
// passed only as its fallback. Both in the same run, so their ratio is the cost of the change.
void BM_EstimatorTick(benchmark::State& state) {
  const bool from_readings = state.range(0) == 1;
  control::Ekf est = warmed_up();
  control::HandInputFromJoint hand;
  const Inputs& in = inputs();
  long i = 400, tick = 0;
  hand.next(in.readings[i - 1], in.u[i - 1].theta_ddot);
  for (auto _ : state) {
    if (i == Inputs::kCount) {
      state.PauseTiming();
      est = warmed_up();
      i = 400;
      hand.reset();
      hand.next(in.readings[i - 1], in.u[i - 1].theta_ddot);
      state.ResumeTiming();
    }
    const double t1 = in.t0 + (i + 1) * kDt;
    if (from_readings)
      est.propagate(t1, hand.next(in.readings[i], in.u[i].theta_ddot).input);
    else
      est.propagate(t1, in.u[i]);
    if (++tick % 33 == 0) {
      // Captured 32.5 ms ago (mid-tick): the truth there, near enough for timing.
      const control::UpdateReport r = est.update({t1 - 0.0325, t1, in.s_true[i - 32], 2e-4});
      benchmark::DoNotOptimize(r);
    }
    ++i;
    benchmark::DoNotOptimize(est);
  }
  state.SetLabel(from_readings ? "hand input from readings" : "commanded acceleration");
}
BENCHMARK(BM_EstimatorTick)->Arg(0)->Arg(1);

// Either filter type, warmed up as above (the same 400 ms of history behind it).
template <class Filter>
Filter warmed_up_filter() {
  const Window& w = inputs();
  Filter est(model(), {});
  est.reset(w.t0, w.s_true[0], w.sdot0);
  for (int i = 0; i < 400; ++i) est.propagate(w.t0 + (i + 1) * kDt, w.u[i]);
  return est;
}

// One 1 ms propagation on the rolling model: the EKF's 8 evaluations of the disk equation (4 RK4
// stages, 4 for the Jacobian) against the UKF's 20 (4 RK4 stages for each of 5 sigma points).
template <class Filter>
void filter_propagate(benchmark::State& state) {
  Filter est = warmed_up_filter<Filter>();
  const Inputs& in = inputs();
  long i = 400;
  for (auto _ : state) {
    if (i == Inputs::kCount) {
      state.PauseTiming();
      est = warmed_up_filter<Filter>();
      i = 400;
      state.ResumeTiming();
    }
    est.propagate(in.t0 + (i + 1) * kDt, in.u[i]);
    ++i;
    benchmark::DoNotOptimize(est);
  }
  state.SetLabel(est.name());
}

// The loop's average tick as BM_EstimatorTick/1 (the hand input from the readings, an update 33
// ms old every 33 ticks), per filter type.
template <class Filter>
void filter_tick(benchmark::State& state) {
  Filter est = warmed_up_filter<Filter>();
  control::HandInputFromJoint hand;
  const Inputs& in = inputs();
  long i = 400, tick = 0;
  hand.next(in.readings[i - 1], in.u[i - 1].theta_ddot);
  for (auto _ : state) {
    if (i == Inputs::kCount) {
      state.PauseTiming();
      est = warmed_up_filter<Filter>();
      i = 400;
      hand.reset();
      hand.next(in.readings[i - 1], in.u[i - 1].theta_ddot);
      state.ResumeTiming();
    }
    const double t1 = in.t0 + (i + 1) * kDt;
    est.propagate(t1, hand.next(in.readings[i], in.u[i].theta_ddot).input);
    if (++tick % 33 == 0) {
      const control::UpdateReport r = est.update({t1 - 0.0325, t1, in.s_true[i - 32], 2e-4});
      benchmark::DoNotOptimize(r);
    }
    ++i;
    benchmark::DoNotOptimize(est);
  }
  state.SetLabel(est.name());
}

void BM_FilterPropagate(benchmark::State& state) {
  if (state.range(0) == 0)
    filter_propagate<control::Ekf>(state);
  else
    filter_propagate<control::Ukf>(state);
}
BENCHMARK(BM_FilterPropagate)->Arg(0)->Arg(1);

void BM_FilterTick(benchmark::State& state) {
  if (state.range(0) == 0)
    filter_tick<control::Ekf>(state);
  else
    filter_tick<control::Ukf>(state);
}
BENCHMARK(BM_FilterTick)->Arg(0)->Arg(1);

}  // namespace

BENCHMARK_MAIN();
