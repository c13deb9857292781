// The closed-loop study (closed_loop_study.hpp).
#include "flatland/studies/closed_loop_study.hpp"

#include "flatland/drivers/experiment.hpp"
#include "flatland/sim/parallel.hpp"
#include "flatland/sim/trajectory_csv.hpp"
#include "flatland/studies/timing.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <functional>
#include <memory>
#include <stdexcept>
#include <thread>

namespace flatland::studies {

namespace {

using sim::format_number;
using RunSummary = ClosedLoopRun;
using Cell = ClosedLoopCell;
using CellResult = ClosedLoopCellResult;
constexpr std::uint64_t kSeed = kClosedLoopSeed;
// Worlds per cell. The full grid is 24 feedback cells and the baseline, 750 experiments of
// 0.25 (15 Hz) to 2 s (120 Hz) CPU each: about 8 minutes on two cores (docs/ACCURACY.md). The
// Wilson interval of 30/30 is 88.6-100 %; more worlds would not fit the budget.
constexpr int kRunsFull = 30;
constexpr int kRunsQuick = 2;
// --quick's second latency: beyond the safety monitor's default lost_timeout (0.25 s), so no
// frame arrives before the monitor gives up and every run must end in a safe stop. It makes the
// quick grid a test that can fail (a cell that must fail next to one that should not).
constexpr double kAbsurdLatency = 0.3;

/// The CSV's failure columns: classes folded into five.
int failure_column(const std::string& cls) {
  if (cls == "dropped") return 0;
  if (cls == "slid_off") return 1;
  if (cls == "wrong_well" || cls == "not_settled") return 2;
  if (cls.rfind("safe_stop", 0) == 0) return 3;
  return 4;
}
const char* const kFailureColumns[] = {"fail_dropped", "fail_slid_off", "fail_wrong_well",
                                       "fail_safe_stop", "fail_other"};

/// The nominal scene with the cell's camera. The truth worlds are perturbed from it, so the loop
/// and the world agree on the camera's rate and latency, and the worlds do not depend on the
/// controller. The estimator's latency compensation rewinds to each frame's capture time stamp
/// (the synthetic camera's stamps are exact), so it compensates the latency a frame really had;
/// the scene's camera.latency only sizes the estimator's history (drivers::LoopSetup), which must
/// reach back that far.
Scene camera_scene(const Scene& nominal, const Cell& c) {
  Scene s = nominal;
  s.camera->fps = c.fps;
  // scene validation: exposure <= 1/fps. A faster camera cannot expose longer than its frame.
  s.camera->exposure = std::min(s.camera->exposure, 1.0 / c.fps);
  s.camera->latency = c.latency;
  s.camera->latency_jitter = c.jitter;
  return s;
}

/// The scene the loop assumes in a cell: the cell's camera and controller.
Scene cell_scene(const Scene& nominal, const Cell& c) {
  return drivers::scene_for_controller(camera_scene(nominal, c), c.controller, "controllers");
}

/// The estimate while it steers the hand (the servo stage, before any failure stops the world):
/// the RMS of its error in s_h over every tick, and its mean NEES at the ticks that folded in a
/// measurement (about 2 for a consistent filter). NaN if the run never servoed. Both are taken
/// over the same window in every run, so a run that failed does not add the estimate's drift
/// against a world that has stopped.
struct ServoStats {
  double err_rms = NAN, nees = NAN;
};
ServoStats servo_stats(const drivers::LoopResult& loop) {
  double sum = 0, nees = 0;
  long n = 0, m = 0;
  for (const drivers::TickLog& row : loop.log) {
    if (row.mode != "servo" || !row.estimating || !std::isfinite(row.s_true)) continue;
    const double e = row.s_est - row.s_true;
    sum += e * e;
    ++n;
    if (row.measured && std::isfinite(row.nees)) {
      nees += row.nees;
      ++m;
    }
  }
  ServoStats s;
  if (n) s.err_rms = std::sqrt(sum / static_cast<double>(n));
  if (m) s.nees = nees / static_cast<double>(m);
  return s;
}

double mean_finite(const std::vector<RunSummary>& runs, double RunSummary::*field,
                   bool successes_only = false) {
  double sum = 0;
  long n = 0;
  for (const RunSummary& r : runs)
    if (std::isfinite(r.*field) && (!successes_only || r.success)) {
      sum += r.*field;
      ++n;
    }
  return n ? sum / static_cast<double>(n) : NAN;
}

/// Sorted, with `extra` added unless it is already there (to 1e-9).
std::vector<double> with_value(std::vector<double> v, double extra) {
  if (std::none_of(v.begin(), v.end(), [&](double x) { return std::abs(x - extra) < 1e-9; }))
    v.push_back(extra);
  std::sort(v.begin(), v.end());
  return v;
}

/// Thread CPU time (s) of the calling thread: what one experiment cost, whichever thread or
/// rank ran it.
double thread_cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// What a cell's worlds share: the scene its worlds are perturbed from, the loop it runs.
struct CellPlan {
  Scene camera;
  drivers::Perturbations perturbations;
  std::unique_ptr<const drivers::LoopSetup> setup;
};

CellPlan plan_cell(const Scene& nominal, const Cell& cell) {
  CellPlan plan;
  plan.camera = camera_scene(nominal, cell);
  plan.perturbations.latency = cell.latency;
  plan.perturbations.latency_jitter = cell.jitter;
  plan.setup =
      std::make_unique<const drivers::LoopSetup>(model::compile(cell_scene(nominal, cell)));
  return plan;
}

/// Run `run` of a cell: its world is perturb(camera, p, kSeed, run) in every cell. A failed
/// experiment is a result, not an exception.
RunSummary run_world(const CellPlan& plan, int run) {
  RunSummary s;
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = thread_cpu_now();
  const auto finish = [&] {
    s.cpu = thread_cpu_now() - cpu0;
    s.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  };
  drivers::SyntheticResult r;
  try {
    r = drivers::run_synthetic(
        *plan.setup, drivers::compile_world(plan.camera, plan.perturbations, kSeed, run, &s.drawn));
  } catch (const drivers::InvalidWorld&) {
    // A draw that cannot exist is no world: recorded, not counted, and the study goes on.
    s.outcome = drivers::Outcome::kInvalidWorld;
    finish();
    return s;
  } catch (const std::runtime_error&) {
    // A world whose simulation fails is recorded and the study goes on (counted apart).
    s.outcome = drivers::Outcome::kNumericalFailure;
    finish();
    return s;
  }
  s.success = r.success;
  s.outcome = r.outcome;
  if (r.loop.stop_reason) s.stop_cause = r.loop.stop_reason->cause;
  s.fn_min = r.fn_min_ratio;
  s.duration = r.success ? r.loop.duration_s : NAN;
  const ServoStats servo = servo_stats(r.loop);
  s.est_rms = servo.err_rms;
  s.nees = servo.nees;
  s.frames = r.loop.frames;
  s.frames_lost = r.loop.frames_lost;
  finish();
  return s;
}

/// Each run of `cells` (cell i's run j is item i * n + j) as bytes and back, exactly.
sim::ItemCodec runs_codec(std::vector<CellResult>& cells, int n) {
  const auto slot = [&cells, n](long item) -> RunSummary& {
    return cells[static_cast<std::size_t>(item / n)].runs[static_cast<std::size_t>(item % n)];
  };
  sim::ItemCodec codec;
  codec.pack = [slot](long item, sim::ByteWriter& w) {
    const RunSummary& r = slot(item);
    w.put(r.success);
    w.put(r.outcome);
    w.put(r.stop_cause);
    for (double v : {r.fn_min, r.duration, r.est_rms, r.nees, r.wall, r.cpu}) w.put(v);
    w.put(r.frames);
    w.put(r.frames_lost);
    w.put(r.drawn);
  };
  codec.unpack = [slot](long item, sim::ByteReader& in) {
    RunSummary& r = slot(item);
    in.get(r.success);
    in.get(r.outcome);
    in.get(r.stop_cause);
    for (double* v : {&r.fn_min, &r.duration, &r.est_rms, &r.nees, &r.wall, &r.cpu}) in.get(*v);
    in.get(r.frames);
    in.get(r.frames_lost);
    in.get(r.drawn);
  };
  return codec;
}

/// A cell's tallies from its runs.
void summarize_cell(CellResult& out) {
  const int n = static_cast<int>(out.runs.size());
  long frames = 0, lost = 0;
  for (const RunSummary& r : out.runs) {
    if (r.success)
      ++out.successes;
    else if (r.outcome == drivers::Outcome::kNumericalFailure)
      ++out.numerical_failures;
    else if (r.outcome == drivers::Outcome::kInvalidWorld)
      ++out.invalid_worlds;
    else
      ++out.failures[failure_class(r)];
    frames += r.frames;
    lost += r.frames_lost;
    out.wall += r.wall;
    out.cpu += r.cpu;
    if (r.success && std::isfinite(r.fn_min))
      out.fn_min_min = std::isnan(out.fn_min_min) ? r.fn_min : std::min(out.fn_min_min, r.fn_min);
  }
  // A world that failed numerically has no physical outcome: the rate is over the others.
  out.ci = drivers::wilson_interval(out.successes, n - out.numerical_failures - out.invalid_worlds);
  out.fn_min_mean = mean_finite(out.runs, &RunSummary::fn_min, true);
  out.duration_mean = mean_finite(out.runs, &RunSummary::duration, true);
  out.est_rms = mean_finite(out.runs, &RunSummary::est_rms);
  out.nees = mean_finite(out.runs, &RunSummary::nees);
  out.frames_lost_fraction = frames ? static_cast<double>(lost) / static_cast<double>(frames) : NAN;
}

std::string csv_header() {
  std::string h =
      "rate[Hz],latency[s],latency_jitter[s],controller,runs,successes,success_rate,ci95_lo,"
      "ci95_hi";
  for (const char* c : kFailureColumns) h += std::string(",") + c;
  return h +
         ",fn_min_ratio_mean,fn_min_ratio_min,duration_mean[s],est_err_rms,nees_mean,"
         "frames_lost_fraction,wall[s],cpu[s],numerical_failures,invalid_worlds\n";
}

std::string csv_row(const CellResult& c, int n) {
  int fails[5] = {};
  for (const auto& [cls, count] : c.failures) fails[failure_column(cls)] += count;
  std::string s = format_number(c.cell.fps);
  for (double v : {c.cell.latency, c.cell.jitter}) {
    s += ',';
    s += format_number(v);
  }
  s += "," + c.cell.controller + "," + std::to_string(n) + "," + std::to_string(c.successes);
  const int counted = n - c.numerical_failures - c.invalid_worlds;
  for (double v :
       {counted > 0 ? static_cast<double>(c.successes) / counted : NAN, c.ci.lo, c.ci.hi}) {
    s += ',';
    s += format_number(v);
  }
  for (int f : fails) {
    s += ',';  // piecewise: GCC 12's -Wrestrict false positive on "," + std::string&&
    s += std::to_string(f);
  }
  for (double v : {c.fn_min_mean, c.fn_min_min, c.duration_mean, c.est_rms, c.nees,
                   c.frames_lost_fraction, c.wall, c.cpu}) {
    s += ',';
    s += format_number(v);
  }
  s += ',';
  s += std::to_string(c.numerical_failures);
  s += ',';
  s += std::to_string(c.invalid_worlds);
  return s + "\n";
}

}  // namespace

std::string failure_class(const ClosedLoopRun& r) {
  if (r.outcome != drivers::Outcome::kSafeStop) return drivers::to_string(r.outcome);
  if (!r.stop_cause) return "safe_stop (other)";
  return std::string("safe_stop (") + control::to_string(*r.stop_cause) + ")";
}

ClosedLoopGrid closed_loop_grid(const model::Model& nominal, bool quick,
                                const std::vector<std::string>& controllers) {
  const Scene& scene = nominal.spec;
  if (!scene.camera)
    throw std::invalid_argument(
        scene.origin + ": camera: the scene has no camera section (needed by the closed loop)");
  if (scene.sim.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw std::invalid_argument(
        scene.origin + ": motion: study closed-loop needs the butterfly (motion.type: butterfly)");
  const drivers::Perturbations defaults;
  drivers::perturb(scene, defaults, kSeed, 0);  // std::invalid_argument for what it refuses
  if (controllers.empty()) throw std::invalid_argument("controllers: no controller given");
  for (std::size_t i = 0; i < controllers.size(); ++i) {
    drivers::scene_for_controller(scene, controllers[i], "controllers");  // known names
    for (std::size_t j = 0; j < i; ++j)
      if (controllers[j] == controllers[i])
        throw std::invalid_argument("controllers: '" + controllers[i] + "' given twice");
  }

  // The scene's own rate and latency are always in the grid (the nominal cell).
  ClosedLoopGrid grid;
  grid.controllers = controllers;
  grid.nominal_fps = scene.camera->fps;
  grid.nominal_latency = scene.camera->latency;
  const double fps0 = grid.nominal_fps, latency0 = grid.nominal_latency;
  grid.rates =
      with_value(quick ? std::vector<double>{15} : std::vector<double>{15, 30, 60, 120}, fps0);
  grid.latencies = with_value(quick ? std::vector<double>{kAbsurdLatency}
                                    : std::vector<double>{0, 0.033, 0.067, 0.1, 0.15, 0.2},
                              latency0);
  // Each cell keeps the Monte Carlo study's latency spread where it can (it must not exceed the
  // latency: a frame cannot arrive before it is taken).
  const auto jitter = [&](double latency) { return std::min(defaults.latency_jitter, latency); };
  for (const std::string& c : controllers)
    for (double r : grid.rates)
      for (double l : grid.latencies) grid.cells.push_back({r, l, jitter(l), c});
  // The open loop does not use the camera to steer, so one baseline (at the scene's camera) says
  // what feedback adds, unless the axis has it already.
  grid.open_loop_baseline =
      std::find(controllers.begin(), controllers.end(), "open-loop") == controllers.end();
  if (grid.open_loop_baseline)
    grid.cells.push_back({fps0, latency0, jitter(latency0), "open-loop"});
  // Every cell's loop set-up is built now, so that a scene the loop cannot run is bad input
  // rather than a failure half-way through.
  for (const Cell& c : grid.cells) drivers::LoopSetup check(model::compile(cell_scene(scene, c)));
  grid.runs_per_cell = quick ? kRunsQuick : kRunsFull;
  return grid;
}

ClosedLoopStudyResult run_closed_loop_study(const model::Model& nominal, const ClosedLoopGrid& grid,
                                            const ClosedLoopStudyOptions& options) {
  const sim::ThreadSweep threads(options.threads);
  return run_closed_loop_study(nominal, grid, options.engine ? *options.engine : threads,
                               options.progress);
}

ClosedLoopStudyResult run_closed_loop_study(const model::Model& nominal, const ClosedLoopGrid& grid,
                                            const sim::SweepEngine& engine,
                                            const sim::Progress& progress) {
  ClosedLoopStudyResult out;
  out.grid = grid;
  out.threads = engine.threads();
  out.processes = engine.processes();
  const int n = out.grid.runs_per_cell;
  const long total = static_cast<long>(out.grid.cells.size()) * n;
  std::vector<CellPlan> plans;
  for (const Cell& c : out.grid.cells) {
    plans.push_back(plan_cell(nominal.spec, c));
    CellResult cell;
    cell.cell = c;
    cell.runs.resize(static_cast<std::size_t>(n));
    out.cells.push_back(std::move(cell));
  }
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = cpu_now();
  // One sweep over every cell's worlds (item i * n + j is cell i's run j), so that the threads
  // and ranks stay busy across cells instead of waiting for each cell's slowest world.
  engine.run(
      total,
      [&](long item) {
        const auto cell = static_cast<std::size_t>(item / n);
        out.cells[cell].runs[static_cast<std::size_t>(item % n)] =
            run_world(plans[cell], static_cast<int>(item % n));
      },
      runs_codec(out.cells, n),
      [&](long finished) {
        if (progress) progress(finished, total);
      });
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  out.cpu_seconds = cpu_now() - cpu0;
  for (CellResult& c : out.cells) summarize_cell(c);
  return out;
}

std::string closed_loop_study_csv(const ClosedLoopStudyResult& result) {
  std::string csv = csv_header();
  for (const CellResult& c : result.cells) csv += csv_row(c, result.grid.runs_per_cell);
  return csv;
}

}  // namespace flatland::studies
