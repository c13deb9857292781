// Speed (and cost-versus-accuracy) of the simulator and the design search, on the paper's
// butterfly: sim::SimulationSpec's defaults (2T = 1.181 s, k = -1.1393, disk r = 5.1 cm, g = 9.8).
// Results and how to rerun: docs/BENCHMARKS.md.
#include "flatland/design/design.hpp"
#include "flatland/sim/format.hpp"
#include "flatland/sim/hand_shapes.hpp"
#include "flatland/sim/rolling.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/sensitivity.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_run.hpp"
#include "flatland/sim/spec.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

namespace sim = flatland::sim;
namespace design = flatland::design;

namespace {

constexpr double kPeriod = 1.181;  // 2T, s: the paper's solution

sim::SimulationSpec with_tolerance(double rtol, double atol) {
  sim::SimulationSpec spec;
  spec.run.integrator.rtol = rtol;
  spec.run.integrator.atol = atol;
  return spec;
}

// DoNotOptimize is applied to whole result structs, never to a lone double: with GCC 12 and
// libbenchmark 1.7.1 (whose GCC variant uses a "+m,r" asm constraint), DoNotOptimize on a double
// member was seen to corrupt it (compare google/benchmark#903).

// Reference values from tight tolerances, computed once (outside any timed region).
double reference_s_end() {
  static const double s = [] {
    sim::SimulationSpec spec = with_tolerance(1e-13, 1e-15);
    spec.run.formulation = sim::Formulation::kReduced;
    spec.run.record = false;
    return sim::run_spec(spec).final.s_h;
  }();
  return s;
}
double reference_k() {
  static const double k = [] {
    const sim::SimulationSpec spec = with_tolerance(1e-12, 1e-14);
    sim::SearchSettings settings;
    settings.tolerance = 1e-12;
    return sim::solve_k(spec, kPeriod, settings).k;
  }();
  return k;
}

// One full 2T run of the butterfly.
void ButterflyRun(benchmark::State& state, sim::Formulation formulation, double rtol, bool record) {
  sim::SimulationSpec spec = with_tolerance(rtol, rtol * 1e-2);
  spec.run.formulation = formulation;
  spec.run.record = record;
  const auto problem = sim::build_problem(spec);
  const sim::RunOptions options = sim::run_options(spec);
  sim::RunResult result;
  for (auto _ : state) {
    result = sim::simulate(problem, spec.initial, options);
    benchmark::DoNotOptimize(result);
  }
  state.counters["steps"] = benchmark::Counter(static_cast<double>(result.stats.steps));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(result.stats.rhs_evals));
  // Distance of the final s_h from a reduced run at rtol 1e-13: the accuracy bought.
  state.counters["s_end_err"] = benchmark::Counter(std::abs(result.final.s_h - reference_s_end()));
}

// One 2T run of the butterfly (reduced, not recorded) with or without the sensitivities of its end
// to the six parameters (a, b, c, d, k, period): the cost ratio of the two, same tolerance;
// and with the sensitivities in the step-size control too (SensitivityOptions::control_error).
void SensitivityRun(benchmark::State& state, bool sensitivities, bool control_error) {
  sim::SimulationSpec spec = with_tolerance(1e-10, 1e-12);
  spec.run.formulation = sim::Formulation::kReduced;
  spec.run.record = false;
  const auto problem = sim::build_problem(spec);
  const sim::RunOptions options = sim::run_options(spec);
  sim::RunResult result;
  for (auto _ : state) {
    if (sensitivities) {
      sim::RunSensitivities s =
          sim::simulate_with_sensitivities(problem, spec.initial, options, {control_error});
      benchmark::DoNotOptimize(s);
      result = s.run;
    } else {
      result = sim::simulate(problem, spec.initial, options);
      benchmark::DoNotOptimize(result);
    }
  }
  state.counters["steps"] = benchmark::Counter(static_cast<double>(result.stats.steps));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(result.stats.rhs_evals));
}

// One right-hand-side evaluation at a mid-roll state.
template <class Model>
void Rhs(benchmark::State& state) {
  const sim::SimulationSpec spec;
  const Model model(sim::build_problem(spec));
  const double t = 0.3;
  sim::InitialContact init;
  init.t0 = t;
  init.s_h = -0.5;
  init.sdot_h = 1.0;
  typename Model::State y = model.initial_state(init);
  sim::Pieces pieces = model.pieces_for(y, +1);
  pieces.motion = 1;  // the quintic (0 < t < 2T)
  typename Model::State dy;
  for (auto _ : state) {
    model.derivative(t, y, pieces, dy);
    benchmark::DoNotOptimize(dy);
    benchmark::ClobberMemory();
  }
}

// The hands compared (issue 26): the paper's polynomial, and the same hand given as 200 points
// of its right half (the points hand: a periodic quintic spline, sim/hand_shapes.hpp).
enum class HandKind { kPolynomial, kPoints };

sim::CurvePtr bench_hand(HandKind kind) {
  const sim::HandSpec h;
  const sim::PolynomialHand poly(h.a, h.b, h.c, h.d);
  if (kind == HandKind::kPolynomial) return std::make_shared<sim::PolynomialHand>(poly);
  sim::PointsHandSpec spec;
  for (int i = 0; i < 200; ++i) spec.points.push_back(poly.jet(-1.0 + 2.0 * i / 199, 0).c);
  return sim::make_points_hand(spec);
}

// The hand's geometry (the jet and everything derived from it) at random s over the outline.
void HandGeometry(benchmark::State& state, HandKind kind) {
  const sim::CurvePtr hand = bench_hand(kind);
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> uniform(-1.0, 3.0);
  std::vector<double> s(1024);
  for (double& v : s) v = uniform(rng);
  std::size_t i = 0;
  for (auto _ : state) {
    const double at = s[i++ & 1023];
    sim::CurveGeometry g = hand->geometry(at, hand->piece_at(at, +1));
    benchmark::DoNotOptimize(g);
  }
}

// The reduced formulation's right-hand side at a mid-roll state (as BM_Rhs) on either hand.
void HandRhs(benchmark::State& state, HandKind kind) {
  const sim::SimulationSpec spec;
  auto problem = std::make_shared<sim::RollingProblem>(*sim::build_problem(spec));
  problem->hand = bench_hand(kind);
  const sim::ReducedDiskRolling model(problem);
  sim::InitialContact init;
  init.t0 = 0.3;
  init.s_h = -0.5;
  init.sdot_h = 1.0;
  sim::ReducedDiskRolling::State y = model.initial_state(init), dy;
  sim::Pieces pieces = model.pieces_for(y, +1);
  pieces.motion = 1;
  for (auto _ : state) {
    model.derivative(init.t0, y, pieces, dy);
    benchmark::DoNotOptimize(dy);
    benchmark::ClobberMemory();
  }
}

// One full 2T butterfly run (reduced, rtol 1e-10, unrecorded) on either hand.
void HandButterflyRun(benchmark::State& state, HandKind kind) {
  sim::SimulationSpec spec = with_tolerance(1e-10, 1e-12);
  spec.run.formulation = sim::Formulation::kReduced;
  spec.run.record = false;
  auto problem = std::make_shared<sim::RollingProblem>(*sim::build_problem(spec));
  problem->hand = bench_hand(kind);
  const sim::RunOptions options = sim::run_options(spec);
  sim::RunResult result;
  for (auto _ : state) {
    result = sim::simulate(problem, spec.initial, options);
    benchmark::DoNotOptimize(result);
  }
  state.counters["steps"] = benchmark::Counter(static_cast<double>(result.stats.steps));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(result.stats.rhs_evals));
  state.counters["restarts"] = benchmark::Counter(result.stats.restarts);
}

// Solve k for 2T = 1.181 s to a bracket of 1e-6 (the acceptance target: <= 2 ms).
void Solve(benchmark::State& state, double rtol, double atol) {
  const sim::SimulationSpec spec = with_tolerance(rtol, atol);
  sim::SearchSettings settings;
  settings.tolerance = 1e-6;
  sim::SolveReport report;
  for (auto _ : state) {
    report = sim::solve_k(spec, kPeriod, settings);
    benchmark::DoNotOptimize(report);
  }
  state.counters["simulations"] = benchmark::Counter(report.simulations);
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(report.rhs_evals));
  state.counters["k_err"] = benchmark::Counter(std::abs(report.k - reference_k()));
}

// `design` from the bundled scene's defaults: objective 1 (the least friction at 2T), the
// motion-only design (k alone, the paper's search) beside shape and motion, and objective 3 (the
// robustness margin at mu, with robustness_mu > 0), with their evaluations and runs
// (docs/DESIGN.md).
void Design(benchmark::State& state, double period, bool shape_free, double robustness_mu) {
  design::DesignOptions o;
  o.period = period;
  if (robustness_mu > 0) {
    o.objective = design::Objective::kRobustness;
    o.mu = robustness_mu;
  }
  o.shape_free = shape_free;
  design::DesignResult r;
  for (auto _ : state) {
    r = design::optimise(sim::SimulationSpec{}, o);
    benchmark::DoNotOptimize(r);
  }
  state.counters["evaluations"] = benchmark::Counter(static_cast<double>(r.iterates.size()));
  state.counters["runs"] = benchmark::Counter(r.simulations);
  state.counters["mu"] = benchmark::Counter(r.best.mu_required);
  if (o.objective == design::Objective::kRobustness)
    state.counters["robustness"] = benchmark::Counter(r.best.robustness);
}

// s_h(T) on a 100 x 100 grid of (k, 2T) (paper Fig. 6) on all cores (target: <= 5 s wall).
void Surface100(benchmark::State& state) {
  const sim::SimulationSpec spec = with_tolerance(1e-7, 1e-9);
  sim::SurfaceResult result;
  for (auto _ : state) {
    result = sim::surface(spec, -1.6, -0.8, 100, 0.8, 2.0, 100, /*threads=*/0);
    benchmark::DoNotOptimize(result);
  }
  state.counters["points"] = benchmark::Counter(static_cast<double>(result.s_T.size()));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(result.rhs_evals));
}

// The throw and the catch (assets/scenes/throw-catch.yaml): the air table at 5 deg, a butterfly
// faster than the fastest that keeps contact (2T = 3.556 s = kappa x 1.05 s); the disk slips,
// flies over the tip, lands on the back, bounces and is caught. Its contact law and losses are
// the air-table scenes'.
sim::SimulationSpec throw_catch_spec(sim::ContactModel model) {
  sim::SimulationSpec spec;
  spec.tilt = 5.0 * M_PI / 180.0;
  spec.motion.period = 3.556;
  spec.motion.k = -1.155794;
  spec.duration = 5.0;
  spec.run.model = model;
  if (model == sim::ContactModel::kHybrid) {
    spec.contact.mu = 0.8;
    spec.contact.mu_kinetic = 0.6;
    spec.contact.restitution = 0.4;
    spec.contact.drag = 0.015;
    spec.contact.drag_angular = 2e-5;
    spec.contact.rolling_resistance = 5e-5;
  } else {
    spec.run.events.stop_on_contact_loss = false;  // the reference: rolling enforced throughout
  }
  return spec;
}

// One run of the throw and the catch in the hybrid model, against the same motion with rolling
// enforced (no events) in the same process: the cost of the modes, the flight and the impacts.
void ThrowCatch(benchmark::State& state, sim::ContactModel model, bool record) {
  sim::SimulationSpec spec = throw_catch_spec(model);
  spec.run.record = record;
  const auto problem = sim::build_problem(spec);
  const sim::RunOptions options = sim::run_options(spec);
  sim::RunResult result;
  for (auto _ : state) {
    result = sim::simulate(problem, spec.initial, options);
    benchmark::DoNotOptimize(result);
  }
  const sim::RunStats& st = result.stats;
  state.counters["steps"] = benchmark::Counter(static_cast<double>(st.steps));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(st.rhs_evals));
  state.counters["event_evals"] = benchmark::Counter(static_cast<double>(st.event_evals));
  state.counters["gap_evals"] = benchmark::Counter(static_cast<double>(st.gap_evals));
  state.counters["impacts"] = benchmark::Counter(st.impacts);
  state.counters["mode_changes"] = benchmark::Counter(st.mode_changes);
  state.counters["flight_s"] = benchmark::Counter(st.mode_time[3]);
}

std::string tolerance_name(double rtol) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "rtol:%.0e", rtol);
  return buf;
}

// Spatial rolling (issue 16): a uniform ball (r 2 cm) on a turntable spinning at 10 rad/s about
// the vertical, rolling at 5.8 cm/s 12.6 cm from the axis (Weltner's problem).
/// Weltner's turntable as assets/scenes/ball-on-turntable.yaml places it: the ball at (0.12,
/// -0.04) on the plate moving at (0.05, 0.03) m/s, spinning at 1.5 rad/s about the vertical, its
/// chart's u direction turned by `twist` from the plate's (the scene: 0; the benchmark until
/// 2026-11-28: 90 degrees, the chart's (0, 0) at the bottom with its path along the equator).
struct Turntable {
  sim::SpatialRollingProblem problem;
  sim::SpinningHand3 table{sim::Vec3::UnitZ(), 10.0};
  sim::SpatialState state;
  explicit Turntable(double twist = 0.5 * M_PI) {
    problem.hand = std::make_shared<sim::PlaneSurface>(sim::Vec3::Zero(), sim::Vec3::UnitX(),
                                                       sim::Vec3::UnitY());
    problem.object = sim::uniform_ball(0.02, 0.2);
    sim::ContactPlacement at;
    at.s_h = sim::SurfaceParam(0.12, -0.04);
    at.twist = twist;
    at.velocity = sim::Vec3(0.05, 0.03, 0);
    at.spin = 1.5;
    state = sim::place_in_contact(problem, table.at(0), at);
  }
};

// One evaluation of the spatial equations: the surfaces' geometry, A x = b (11 x 10) assembled
// and solved by column-pivoting QR.
void SpatialRhs(benchmark::State& state) {
  const Turntable t;
  const sim::HandPose3 hand = t.table.at(0);
  for (auto _ : state) {
    sim::SpatialSolution s = sim::solve_spatial_rolling(t.problem, hand, t.state);
    benchmark::DoNotOptimize(s.x);
  }
}

// 10 s of Weltner's turntable (2.9 of the ball's circles), steps not kept: method 0 DOPRI5 and 1
// DOP853 at rtol 1e-10, 2 RK4 at a 1 ms step.
void SpatialWeltner10s(benchmark::State& state) {
  const Turntable t(state.range(1) * M_PI / 180.0);
  sim::SpatialRunOptions o;
  o.t_end = 10.0;
  o.integrator.rtol = 1e-10;
  o.integrator.atol = 1e-12;
  o.integrator.method = state.range(0) == 1   ? sim::Method::kDormandPrince853
                        : state.range(0) == 2 ? sim::Method::kRungeKutta4
                                              : sim::Method::kDormandPrince54;
  o.integrator.fixed_step = 1e-3;
  o.record = false;
  sim::SpatialRunResult run;
  for (auto _ : state) {
    run = sim::simulate_spatial(t.problem, t.table, t.state, 0.0, o);
    benchmark::DoNotOptimize(run.final);
  }
  state.counters["steps"] = benchmark::Counter(static_cast<double>(run.stats.steps));
  state.counters["rhs_evals"] = benchmark::Counter(static_cast<double>(run.stats.rhs_evals));
  state.counters["charts"] = benchmark::Counter(run.stats.chart_changes);
  // The centre's error against Weltner's circle, about p0 + z x v0 / k at k = (2/7) Omega.
  const double k = 2.0 / 7.0 * 10.0;
  const sim::Vec3 p0 = t.state.position, c = p0 + sim::Vec3::UnitZ().cross(t.state.velocity) / k;
  const sim::Vec3 expected = c + Eigen::AngleAxisd(k * o.t_end, sim::Vec3::UnitZ()) * (p0 - c);
  state.counters["centre_err_m"] = benchmark::Counter((run.final.state.position - expected).norm());
}

void register_all() {
  for (const auto formulation : {sim::Formulation::kGeneral, sim::Formulation::kReduced}) {
    for (const double rtol : {1e-6, 1e-9, 1e-12}) {
      for (const bool record : {false, true}) {
        const std::string name = "BM_ButterflyRun/" + sim::to_string(formulation) + "/" +
                                 tolerance_name(rtol) + "/record:" + (record ? "1" : "0");
        benchmark::RegisterBenchmark(name.c_str(), ButterflyRun, formulation, rtol, record)
            ->Unit(benchmark::kMillisecond);
      }
    }
  }
  for (const bool record : {false, true}) {
    const std::string suffix = std::string("/record:") + (record ? "1" : "0");
    benchmark::RegisterBenchmark(("BM_ThrowCatch/hybrid" + suffix).c_str(), ThrowCatch,
                                 sim::ContactModel::kHybrid, record)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("BM_ThrowCatch/rolling_enforced" + suffix).c_str(), ThrowCatch,
                                 sim::ContactModel::kRolling, record)
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("BM_SensitivityRun/without", SensitivityRun, false, false)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_SensitivityRun/with", SensitivityRun, true, false)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_SensitivityRun/with_error_control", SensitivityRun, true, true)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_Rhs/general", Rhs<sim::GeneralRolling>);
  benchmark::RegisterBenchmark("BM_Rhs/reduced", Rhs<sim::ReducedDiskRolling>);
  for (const auto& [kind, name] :
       {std::pair{HandKind::kPolynomial, "polynomial"}, {HandKind::kPoints, "points"}}) {
    benchmark::RegisterBenchmark((std::string("BM_HandGeometry/") + name).c_str(), HandGeometry,
                                 kind);
    benchmark::RegisterBenchmark((std::string("BM_HandRhs/") + name).c_str(), HandRhs, kind);
    benchmark::RegisterBenchmark((std::string("BM_HandButterflyRun/") + name).c_str(),
                                 HandButterflyRun, kind)
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("BM_Solve/rtol:1e-07", Solve, 1e-7, 1e-9)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_Solve/rtol:1e-10", Solve, 1e-10, 1e-12)
      ->Unit(benchmark::kMillisecond);
  for (const double period : {0.9, 1.181}) {
    const std::string p = sim::format_number(period);
    benchmark::RegisterBenchmark(("BM_Design/least_friction/motion_only/period:" + p).c_str(),
                                 Design, period, false, 0.0)
        ->Unit(benchmark::kMillisecond);
    benchmark::RegisterBenchmark(("BM_Design/least_friction/shape_and_motion/period:" + p).c_str(),
                                 Design, period, true, 0.0)
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark("BM_Design/robustness:mu=0.306/shape_and_motion/period:1.181",
                               Design, 1.181, true, 0.306)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_SpatialRhs", SpatialRhs)->Unit(benchmark::kMicrosecond);
  benchmark::RegisterBenchmark("BM_SpatialWeltner10s", SpatialWeltner10s)
      ->ArgNames({"method", "twist_deg"})
      ->ArgsProduct({{0, 1, 2}, {0, 90}})
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("BM_Surface100", Surface100)
      ->Iterations(1)
      ->UseRealTime()
      ->MeasureProcessCPUTime()
      ->Unit(benchmark::kSecond);
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  register_all();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
