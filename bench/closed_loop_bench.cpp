// The closed loop's costs (docs/BENCHMARKS.md, "Closed loop"):
//  * BM_ControlTick: estimator + controller for one 1 kHz tick in stage 2 (propagate, plan lookup,
//    control law), with a latency-compensated update every 33rd tick as from a 30 Hz camera.
//    Target: <= 5 us. BM_ControlTickTransverse: the same tick with the transverse-linearisation
//    controller (its peer, compared as a ratio in the same run); BM_TransverseStart: its Riccati
//    solution at start(). BM_ControllerStep/0, /1: the paper's and the transverse controller's
//    step() alone.
//  * BM_SyntheticExperiment: a whole synthetic experiment of the paper's air-table run (5 deg,
//    2T = 4 s, 5.2 s simulated with the settle), every frame rendered (640 x 480, 2 DN noise) and
//    tracked. Counter realtime_factor = simulated time / wall time; target >= 30.
//  * BM_FrameNoise/0, /1: a frame's sensor noise through a float frame and on the 8-bit frame.
// Run: build/bin/flatland_closed_loop_bench
#include <benchmark/benchmark.h>

#include "flatland/control/choice.hpp"
#include "flatland/control/controller.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/drivers/experiment.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/spec.hpp"

#include <chrono>
#include <memory>
#include <string>

using namespace flatland;

namespace {

const Scene& scene() {
  static const Scene s = load_scene(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml");
  return s;
}

const drivers::LoopSetup& setup() {
  static const drivers::LoopSetup s(flatland::model::compile(scene()));
  return s;
}

/// One estimator + controller tick in stage 2, the controller of `type` made as a scene's choice
/// makes it (through the Controller interface, as the loop calls it).
void control_tick(benchmark::State& state, const std::string& type) {
  const drivers::LoopSetup& su = setup();
  const control::Plan& plan = *su.plan.plan;
  const auto model = sim::build_problem(scene().sim);
  control::ControllerChoice choice = su.model->controller;
  choice.type = type;
  // Stage 2 from t = 1.5 s on the plan: the inputs the loop would see, precomputed.
  constexpr int kTicks = 1000;
  constexpr double kDt = 1e-3, kT0 = 1.5;
  std::vector<control::JointReading> joint(kTicks);
  std::vector<double> s_plan(kTicks), accel(kTicks);
  for (int i = 0; i < kTicks; ++i) {
    const double t = kT0 + i * kDt;
    const sim::HandKinematics h = plan.hand(t);
    joint[i] = {t, h.angle, h.angular_velocity};
    s_plan[i] = plan.s_h_at(t);
    accel[i] = h.angular_acceleration;
  }
  // The transverse law solves its Riccati equation in start(): made once, outside the timing.
  std::unique_ptr<control::Controller> ctl = control::make_controller(choice);
  ctl->start(su.controller_context(kT0));
  const auto fresh = [&] {
    control::Ekf e(model, su.model->estimator.config);
    e.reset(kT0, s_plan[0], (s_plan[1] - s_plan[0]) / kDt);
    ctl->start(su.controller_context(kT0));
    control::ControlInput dip;
    dip.joint = joint[0];
    dip.estimate.s_h = -0.5;  // past dip_until: the first step switches to the servo stage
    dip.estimating = true;
    (void)ctl->step(dip);
    return e;
  };
  control::Ekf est = fresh();
  int i = 0;
  for (auto _ : state) {
    if (i + 1 == kTicks) {
      state.PauseTiming();
      est = fresh();
      i = 0;
      state.ResumeTiming();
    }
    const double t = kT0 + i * kDt;
    if (i % 33 == 32) {
      const control::UpdateReport r =
          est.update({t - 0.033, t, s_plan[i - 33 > 0 ? i - 33 : 0], 2.7e-4});
      benchmark::DoNotOptimize(r);
    }
    control::ControlInput in;
    in.t = t;
    in.joint = joint[i];
    in.estimate = est.estimate();
    in.estimating = true;
    const control::ControlOutput c = ctl->step(in);
    // The joint follows the plan here (open-loop readings), so the estimator is driven with the
    // plan's acceleration: with the controller's command it would see a hand it does not move.
    est.propagate(t + kDt, {joint[i].theta, joint[i].theta_dot, accel[i]});
    benchmark::DoNotOptimize(c);
    ++i;
  }
}

void BM_ControlTick(benchmark::State& state) { control_tick(state, "paper"); }
BENCHMARK(BM_ControlTick);

/// The same tick with the transverse-linearisation controller: its peer in the same run.
void BM_ControlTickTransverse(benchmark::State& state) { control_tick(state, "transverse"); }
BENCHMARK(BM_ControlTickTransverse);

/// The controller's step alone, in stage 2 on the plan's inputs (t = 1.5 .. 2.5 s, s_h below
/// finish_after throughout, so the stage never changes): arg 0 the paper's, 1 the transverse law.
void BM_ControllerStep(benchmark::State& state) {
  const drivers::LoopSetup& su = setup();
  const control::Plan& plan = *su.plan.plan;
  control::ControllerChoice choice = su.model->controller;
  choice.type = state.range(0) == 0 ? "paper" : "transverse";
  constexpr int kTicks = 1000;
  constexpr double kDt = 1e-3, kT0 = 1.5;
  std::vector<control::ControlInput> inputs(kTicks);
  for (int i = 0; i < kTicks; ++i) {
    const double t = kT0 + i * kDt;
    const sim::HandKinematics h = plan.hand(t);
    control::ControlInput& in = inputs[static_cast<std::size_t>(i)];
    in.t = t;
    in.joint = {t, h.angle, h.angular_velocity};
    in.estimate.t = t;
    in.estimate.s_h = plan.s_h_at(t);
    in.estimate.sdot_h = plan.sdot_h_at(t);
    in.estimating = true;
  }
  std::unique_ptr<control::Controller> ctl = control::make_controller(choice);
  ctl->start(su.controller_context(kT0));
  std::size_t i = 0;
  for (auto _ : state) {
    const control::ControlOutput c = ctl->step(inputs[i]);
    benchmark::DoNotOptimize(c);
    if (++i == inputs.size()) i = 0;
  }
  state.SetLabel(choice.type);
}
BENCHMARK(BM_ControllerStep)->Arg(0)->Arg(1);

/// The transverse controller's start(): the Riccati equation solved along the plan, once a run.
void BM_TransverseStart(benchmark::State& state) {
  const drivers::LoopSetup& su = setup();
  control::ControllerChoice choice = su.model->controller;
  choice.type = "transverse";
  for (auto _ : state) {
    std::unique_ptr<control::Controller> ctl = control::make_controller(choice);
    ctl->start(su.controller_context(-0.25));
    benchmark::DoNotOptimize(ctl);
  }
}
BENCHMARK(BM_TransverseStart)->Unit(benchmark::kMillisecond);

/// The sensor noise of one 640 x 480 frame as the loop's camera adds it (2 DN read noise on an
/// 8-bit BGR render): arg 0 through a float frame (convert, apply_noise, quantize: the path before
/// 2026-11-28 and still the one for blurred or vignetted frames), arg 1 on the 8-bit frame
/// (apply_noise_8u: the same pixels, checked once here). Both start from the same render, copied
/// so that every iteration noises the clean frame.
void BM_FrameNoise(benchmark::State& state) {
  const bool eight_bit = state.range(0) == 1;
  cv::Mat render(480, 640, CV_8UC3);
  cv::RNG(1).fill(render, cv::RNG::UNIFORM, 0, 256);
  {
    render::EffectsRng a(7), b(7);
    cv::Mat floats, bytes = render.clone();
    render.convertTo(floats, CV_32F);
    render::apply_noise(floats, 2.0, 0.0, a);
    render::apply_noise_8u(bytes, 2.0, 0.0, b);
    if (cv::norm(render::quantize(floats), bytes, cv::NORM_INF) != 0)
      state.SkipWithError("the two paths give different frames");
  }
  render::EffectsRng rng(1);
  cv::Mat floats, frame;
  for (auto _ : state) {
    if (eight_bit) {
      render.copyTo(frame);
      render::apply_noise_8u(frame, 2.0, 0.0, rng);
    } else {
      render.convertTo(floats, CV_32F);
      render::apply_noise(floats, 2.0, 0.0, rng);
      frame = render::quantize(floats);
    }
    benchmark::DoNotOptimize(frame.data);
  }
  state.SetLabel(eight_bit ? "8-bit" : "float");
}
BENCHMARK(BM_FrameNoise)->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

void BM_SyntheticExperiment(benchmark::State& state) {
  const drivers::LoopSetup& su = setup();
  double simulated = 0, wall = 0;
  long frames = 0;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    const drivers::SyntheticResult r =
        drivers::run_synthetic(su, flatland::model::compile(scene()));
    wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    simulated += r.loop.log.back().t - r.loop.log.front().t;
    frames += r.loop.frames;
    if (!r.success) state.SkipWithError(("experiment failed: " + r.failure).c_str());
  }
  state.counters["realtime_factor"] = simulated / wall;
  state.counters["frames_per_run"] = static_cast<double>(frames) / state.iterations();
}
BENCHMARK(BM_SyntheticExperiment)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
