// Success of the vision-feedback loop against camera rate and latency, per controller. Every cell
// of the grid (controller x rate x latency) runs the same N perturbed worlds (drivers::perturb
// with the default Monte Carlo perturbations and a fixed seed, so the cells differ only in the
// camera and the controller) through its controller; unless the open loop is on the controller
// axis, it runs once, at the scene's rate and latency, as the baseline.
// Per cell: successes with their Wilson 95 % interval, why the others failed, the smallest normal
// force, the estimator's error while it steers the hand, and what the cell cost
// (docs/ACCURACY.md).
#pragma once

#include "flatland/sim/parallel.hpp"

#include "flatland/drivers/montecarlo.hpp"
#include "flatland/model/model.hpp"
#include "flatland/sim/search.hpp"

#include <cmath>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace flatland::studies {

/// The worlds' seed, as `flatland montecarlo`'s default: the same worlds.
inline constexpr std::uint64_t kClosedLoopSeed = 1;

/// One cell: the camera the loop and its worlds share, and the controller.
struct ClosedLoopCell {
  double fps = 30, latency = 0, jitter = 0;  ///< Hz, s, s
  /// A name drivers::scene_for_controller accepts: open-loop, feedback or a controller type.
  std::string controller = "feedback";
};

/// The grid of a scene: for each controller of the axis, rates 15, 30, 60, 120 Hz and latencies
/// 0-200 ms (quick: 15 Hz and an absurd 300 ms, beyond the safety monitor's lost_timeout, so that
/// one cell must fail), the scene's own rate and latency added to each; the open-loop baseline
/// last unless open-loop is on the axis.
struct ClosedLoopGrid {
  std::vector<std::string> controllers;  ///< the controller axis, in the order given
  bool open_loop_baseline = false;       ///< the last cell is the open-loop baseline
  std::vector<double> rates, latencies;
  double nominal_fps = 0, nominal_latency = 0;
  std::vector<ClosedLoopCell> cells;
  int runs_per_cell = 0;  ///< 30 (quick: 2)
};

/// What one experiment left that the study aggregates.
struct ClosedLoopRun {
  bool success = false;
  drivers::Outcome outcome = drivers::Outcome::kNotFinished;
  std::optional<control::StopCause> stop_cause;  ///< why it stopped safely (outcome kSafeStop)
  double fn_min = NAN, duration = NAN, est_rms = NAN, nees = NAN;
  long frames = 0, frames_lost = 0;
  /// s: the experiment's wall time and its thread's CPU time, on whichever thread or rank ran it.
  double wall = 0, cpu = 0;
  /// The world it ran in: perturb(nominal with the cell's camera, kClosedLoopSeed, run), the same
  /// for every controller of a camera.
  drivers::DrawnPerturbation drawn;
};
/// A short class for how a run failed: the outcome ("dropped", ...) and, for a safe stop, what
/// triggered it ("safe_stop (camera)").
std::string failure_class(const ClosedLoopRun& run);

struct ClosedLoopCellResult {
  ClosedLoopCell cell;
  std::vector<ClosedLoopRun> runs;  ///< by world
  int successes = 0;
  drivers::Interval ci;                 ///< Wilson 95 %
  std::map<std::string, int> failures;  ///< failure_class -> count (physical outcomes)
  /// Worlds whose simulation failed (drivers::Outcome::kNumericalFailure): counted apart, and
  /// left out of the success rate's denominator.
  int numerical_failures = 0;
  /// Worlds whose draw cannot exist (drivers::Outcome::kInvalidWorld, drivers::compile_world):
  /// left out of the denominator too.
  int invalid_worlds = 0;
  /// Over the successes: the smallest normal force ratio's mean and minimum, the mean duration;
  /// over every run that servoed: the estimate's RMS error and mean NEES in the servo stage.
  double fn_min_mean = NAN, fn_min_min = NAN, duration_mean = NAN, est_rms = NAN, nees = NAN;
  double frames_lost_fraction = NAN;
  /// s, the cell's runs' wall and CPU times added (each run's on the thread that ran it).
  double wall = 0, cpu = 0;
};

struct ClosedLoopStudyOptions {
  unsigned threads = 0;    ///< 0: std::thread::hardware_concurrency()
  sim::Progress progress;  ///< (experiments done, experiments)
  /// Where the experiments run instead of `threads` (an MPI job's ranks); not owned.
  const sim::SweepEngine* engine = nullptr;
};

struct ClosedLoopStudyResult {
  ClosedLoopGrid grid;
  drivers::Perturbations perturbations;  ///< the worlds' (the defaults; each cell sets the latency)
  std::vector<ClosedLoopCellResult> cells;  ///< in grid order
  unsigned threads = 0;                     ///< per process
  int processes = 1;                        ///< the MPI job's ranks (1 without MPI)
  /// Wall and CPU time of the whole study, in this process (rank 0's alone under MPI).
  double seconds = 0, cpu_seconds = 0;
};

/// The grid of a compiled scene over `controllers` (names drivers::scene_for_controller accepts,
/// each once), checked: std::invalid_argument (naming the scene and field, or `controllers` and
/// the known names) for a scene without a camera or a butterfly, one that some cell's loop cannot
/// run, no controller, or an unknown or repeated one.
ClosedLoopGrid closed_loop_grid(const model::Model& nominal, bool quick,
                                const std::vector<std::string>& controllers = {"feedback"});

/// The study over `grid` (closed_loop_grid of the same scene): each cell's scene is the nominal
/// one with the cell's camera and controller (drivers::scene_for_controller), compiled; each
/// world is the nominal scene with the cell's camera, perturbed and compiled, so every controller
/// meets the same worlds. An exception in any run stops the others and is rethrown (a failed
/// experiment is a result, not an exception).
ClosedLoopStudyResult run_closed_loop_study(const model::Model& nominal, const ClosedLoopGrid& grid,
                                            const ClosedLoopStudyOptions& options = {});
/// The same on a sweep engine: every cell's worlds in one sweep.
ClosedLoopStudyResult run_closed_loop_study(const model::Model& nominal, const ClosedLoopGrid& grid,
                                            const sim::SweepEngine& engine,
                                            const sim::Progress& progress = {});

/// closed_loop.csv: one row per cell (rate, latency, jitter, controller, runs, successes, rate
/// with its interval, failures in five columns, the force, duration, estimate and cost columns).
std::string closed_loop_study_csv(const ClosedLoopStudyResult& result);

}  // namespace flatland::studies
