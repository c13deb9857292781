// Cost of identify (docs/IDENTIFY.md, docs/BENCHMARKS.md): five parameters (rolling resistance,
// drag, tilt, the hand's angle offset, the camera-to-joint time offset) fitted to a 20 s recording
// at 30 Hz (601 samples, the tracker's noise): the air-table butterfly (2T = 4 s at 5 degrees),
// then the disk rocking in the back well until it settles. The fit's wall time, iterations and
// simulator runs, and the cost of one simulator run inside it, against the peer measured in the
// same process: one run of the whole 20 s recording (BM_SimulateRecording).
// Run: build/bin/flatland_identify_bench
#include <benchmark/benchmark.h>

#include "identify/identify_support.hpp"

#include <random>

using namespace flatland;

namespace {

constexpr double kDuration = 20.0, kRate = 30.0;

sim::SimulationSpec world() {
  // assets/scenes/airtable-5deg.yaml's contact: friction, restitution and its losses.
  return flatland_test::air_table_world(0.8, 0.6, 0.4, 5e-5, 0.015);
}

const identify::Recording& recording() {
  static const identify::Recording r = [] {
    std::mt19937_64 rng(1);
    return flatland_test::record("butterfly-20s", world(),
                                 flatland_test::butterfly_hand(4.0, -1.1395840, kDuration), -1, 0,
                                 kDuration, kRate, flatland_test::kTrackerSigmaSh, &rng);
  }();
  return r;
}

void BM_Identify(benchmark::State& state) {
  identify::IdentifyOptions o;
  o.unknowns = {"rolling_resistance", "drag", "tilt", "angle_offset", "time_offset"};
  o.initial = {{"rolling_resistance", 4e-5}, {"drag", 0.012}, {"tilt", 0.09}};
  o.segment_duration = 2.0;
  o.threads = static_cast<int>(state.range(0));
  identify::IdentifyResult r;
  for (auto _ : state) r = identify::identify(world(), {recording()}, o);
  state.counters["iterations"] = r.iterations;
  state.counters["simulations"] = static_cast<double>(r.simulations);
  state.counters["sim_ms_each"] = 1e3 * r.simulation_time / static_cast<double>(r.simulations);
  state.counters["chi2_per_dof"] = r.chi2 / r.degrees_of_freedom;
  state.counters["chi2"] = r.chi2;
  state.counters["converged"] = r.converged;
  state.counters["step_in_sigma"] = r.step_in_sigma;
  int determined = 0;
  for (const auto& p : r.parameters) determined += p.sigma.has_value();
  state.counters["determined"] = determined;
}
BENCHMARK(BM_Identify)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();

// The peer: the whole recording simulated once, as the fit's segments are (hybrid model, the
// joint log's spline, rtol 1e-10).
void BM_SimulateRecording(benchmark::State& state) {
  const identify::Recording& r = recording();
  auto pb = std::make_shared<sim::RollingProblem>(*sim::build_problem(world()));
  pb->motion = std::make_shared<identify::JointLogMotion>(r.joint_t, r.joint_theta);
  sim::RunOptions opt = sim::run_options(world());
  opt.model = sim::ContactModel::kHybrid;
  opt.t_end = kDuration;
  opt.integrator.rtol = 1e-10;
  opt.integrator.atol = 1e-12;
  sim::InitialContact init;
  init.s_h = -1;
  for (auto _ : state) benchmark::DoNotOptimize(sim::simulate(pb, init, opt));
}
BENCHMARK(BM_SimulateRecording)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
