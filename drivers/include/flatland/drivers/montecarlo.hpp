// Monte Carlo robustness of the closed loop: many synthetic experiments in which the world differs
// from what the controller assumes (initial position, table tilt, disk size, camera noise,
// latency, dropped frames, motor friction), run with each controller on the same perturbed
// worlds, so that controllers can be compared world by world: open-loop playback against vision
// feedback (paper section 5: feedback makes the roll robust), or one feedback law against another
// (compare_controllers: each one's outcomes and margins, and paired tests).
#pragma once

#include "flatland/sim/parallel.hpp"

#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/synthetic.hpp"

#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::drivers {

/// Half-widths of the uniform perturbations of one run (a value x is drawn from
/// nominal + U(-h, +h)) and the fixed sensor settings every run gets.
struct Perturbations {
  double s_h = 0.02;              ///< initial s_h, absolute (the palm well is -1)
  double tilt_deg = 0.25;         ///< table tilt, deg
  double radius_rel = 0.02;       ///< disk radius, relative (0.02 = 2 %)
  double noise_dn = 2;            ///< camera read noise sigma, DN (set, not drawn)
  double latency = 0.033;         ///< s, camera latency (set)
  double latency_jitter = 0.005;  ///< s, half-width of its uniform spread (set)
  double drop = 0.02;             ///< probability of a dropped frame (set)
  double friction_rel = 0.2;  ///< joint viscous and Coulomb friction, relative, one factor for both
  /// The contact's friction coefficients (mu, mu_kinetic: one factor) and its losses (rolling
  /// resistance, drag: another factor), relative: the table's assumed values are not known well.
  double contact_rel = 0.2;
};

/// std::invalid_argument naming the field ("perturbations.drop: ...") for negative or non-finite
/// values, drop >= 1, radius_rel, friction_rel or contact_rel >= 1, latency_jitter > latency.
void validate(const Perturbations& p);

/// The values one run drew (the truth it was run against).
struct DrawnPerturbation {
  double s_h0 = 0;            ///< initial s_h
  double tilt_deg = 0;        ///< table tilt, deg
  double radius = 0;          ///< m
  double friction_scale = 1;  ///< factor on joint.viscous and joint.coulomb
  std::uint64_t effects_seed = 0;
  double mu_scale = 1;    ///< factor on contact.mu and contact.mu_kinetic
  double loss_scale = 1;  ///< factor on contact.rolling_resistance, drag, drag_angular
  bool operator==(const DrawnPerturbation&) const = default;
};

/// The truth scene of run `run`: uniform draws from a std::mt19937_64 seeded from (seed, run)
/// alone (std::seed_seq of their 32-bit halves, so the draws do not depend on anything else and
/// are the same on every platform), applied to the nominal scene; the sensor settings (noise,
/// latency, drops) are set; effects.seed is drawn too so that every run sees its own noise and
/// drops. The object's radius is drawn; a ring's inner radius follows it (the ring drawn larger or
/// smaller as a whole, its proportions and so its inertia's form kept), while a ball's rail gap
/// (the hand's) and a given inertia (measured apart) stay: a draw they no longer fit is a world
/// that cannot exist (compile_world). Throws std::invalid_argument for invalid perturbations or a
/// scene without a camera.
Scene perturb(const Scene& nominal, const Perturbations& p, std::uint64_t seed, int run,
              DrawnPerturbation* drawn = nullptr);

/// A two-sided confidence interval of a binomial proportion.
struct Interval {
  double lo = 0, hi = 0;
};
/// Wilson score interval for k successes in n trials (z = 1.96: 95 %); [0, 1] for n = 0.
Interval wilson_interval(long k, long n, double z = 1.959963984540054);

/// One experiment: one run (one perturbed world) under one controller.
struct RunRecord {
  int run = 0;
  std::uint64_t seed = 0;  ///< the Monte Carlo seed: (seed, run) rebuild this world (perturb)
  std::string controller;  ///< the controller's name (MonteCarloController::name)
  bool success = false;
  Outcome outcome = Outcome::kNotFinished;
  std::string failure;               ///< empty on success
  double slide_s = 0, flight_s = 0;  ///< time the disk spent sliding and flying
  int impacts = 0;
  double duration_s = 0, s_end = 0, fn_min_ratio = 0, mu_max = 0;
  bool safe_stop = false;
  long frames = 0, frames_lost = 0;
  DrawnPerturbation drawn;
  /// What triggered the safe stop (outcome kSafeStop; also a stop after the disk was lost).
  std::optional<control::StopCause> stop_cause;
  /// The world's contact.mu (after its perturbation and any WorldEdit): what mu_max is measured
  /// against. NaN for a world that failed before it was compiled.
  double mu = NAN;
};

/// A controller Monte Carlo runs on every world: by name, or the caller's own.
struct MonteCarloController {
  // Implicit from a name, so that {"open-loop", "feedback"} lists controllers by name.
  MonteCarloController(std::string name_, ControllerFactory make_ = {},
                       EstimatorFactory estimator_ = {})
      : name(std::move(name_)), make(std::move(make_)), estimator(std::move(estimator_)) {}
  MonteCarloController(const char* name_) : MonteCarloController(std::string(name_)) {}
  /// "open-loop" (the paper's plan played back), "feedback" (the scene's controller.type in
  /// feedback mode), a built-in controller type ("paper", ...), or, with `make`, the caller's
  /// label for their own.
  std::string name;
  ControllerFactory make;      ///< empty: made from `name` and the scene
  EstimatorFactory estimator;  ///< empty: the scene's estimator.type
};

/// One controller's tally over the worlds.
struct ControllerSummary {
  std::string name;
  int successes = 0;
  /// Worlds whose simulation failed (Outcome::kNumericalFailure): they have no physical outcome
  /// and are left out of the rate's denominator.
  int numerical_failures = 0;
  Interval ci;  ///< Wilson 95 %, over the runs that did not fail and could exist
  /// Worlds that cannot exist (Outcome::kInvalidWorld): left out of the denominator too.
  int invalid_worlds = 0;
};

struct MonteCarloResult {
  int runs = 0;
  /// Per controller, in the order given.
  std::vector<ControllerSummary> summaries;
  /// -1 when that controller was not run.
  int success_open_loop = -1, success_feedback = -1;
  /// Worlds whose simulation failed (Outcome::kNumericalFailure), per controller: they have no
  /// physical outcome and are left out of the rates' denominators.
  int numerical_failures_open_loop = 0, numerical_failures_feedback = 0;
  Interval ci_open_loop, ci_feedback;  ///< Wilson 95 %, over the runs that did not fail
  /// Ordered by run, then by the order of `controllers`: independent of the thread count.
  std::vector<RunRecord> records;
  double seconds = 0;  ///< wall clock
};

/// Called after each experiment with (experiments done, experiments in all); from the worker
/// threads, one call at a time.
using MonteCarloProgress = std::function<void(long done, long total)>;
/// Edits world `run`'s scene after its perturbation and before it is compiled (a study of one
/// more parameter, or a fault to inject); called from the worker threads.
using WorldEdit = std::function<void(Scene& world, int run)>;

/// A perturbed world that cannot exist: its drawn values break a rule of the scene (a ball that
/// falls between its rails, an inertia its drawn radius cannot hold, a disk too large for a well).
/// Recorded as Outcome::kInvalidWorld, with the (seed, run) that draws it, and the study goes on.
struct InvalidWorld : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// World `run`: perturb(nominal, p, seed, run, drawn), then `edit`, compiled. InvalidWorld
/// ("world (seed S, run R) cannot exist: <the rule, naming its field>") when the compile refuses
/// it; the nominal scene compiled, so a refusal is the draw's doing.
std::shared_ptr<const model::Model> compile_world(const Scene& nominal, const Perturbations& p,
                                                  std::uint64_t seed, int run,
                                                  DrawnPerturbation* drawn = nullptr,
                                                  const WorldEdit& edit = {});

/// `n` runs of each of `controllers` (names at most once each) on `threads` std::threads (0:
/// std::thread::hardware_concurrency()). Run i's world obeys perturb(nominal.spec, p, seed, i),
/// compiled; the loop assumes `nominal` with the controller's type and mode (or the caller's
/// factories), so every controller meets the very same worlds. Experiments are handed out by index,
/// and each result is stored at its index, so the records do not depend on the thread count. A run
/// that fails — contact lost, safe stop — is a result; so is a world whose simulation fails (a
/// std::runtime_error in it: Outcome::kNumericalFailure with its message, and the study goes
/// on), and a world that cannot exist (compile_world's InvalidWorld: Outcome::kInvalidWorld). Any
/// other exception stops the others and is rethrown. std::invalid_argument for n < 1, an unknown or
/// repeated controller, invalid perturbations.
MonteCarloResult run_montecarlo(const model::Model& nominal_model, const Perturbations& p, int n,
                                std::uint64_t seed,
                                const std::vector<MonteCarloController>& controllers,
                                unsigned threads = 0, const MonteCarloProgress& progress = {},
                                const WorldEdit& edit = {});
/// The same on a sweep engine: this process's threads, or the ranks of an MPI job
/// (cluster::MpiSweep), whose records come back to rank 0 bit for bit (records_codec).
MonteCarloResult run_montecarlo(const model::Model& nominal_model, const Perturbations& p, int n,
                                std::uint64_t seed,
                                const std::vector<MonteCarloController>& controllers,
                                const sim::SweepEngine& engine,
                                const MonteCarloProgress& progress = {},
                                const WorldEdit& edit = {});
/// Each record of `records` as bytes and back, exactly (sim::ItemCodec).
sim::ItemCodec records_codec(std::vector<RunRecord>& records);
/// Controllers by name only.
std::vector<MonteCarloController> controllers_by_name(const std::vector<std::string>& names);

/// The scene a named controller assumes: "open-loop" -> the paper's controller in open-loop mode;
/// "feedback" -> the scene's own type in feedback mode; a built-in type -> that type in feedback
/// mode. std::invalid_argument naming `field` and the known names otherwise.
Scene scene_for_controller(const Scene& nominal, const std::string& name,
                           const std::string& field = "controller");

/// The q-quantile (0 <= q <= 1) of `values` by linear interpolation between the order statistics
/// (Hyndman and Fan's type 7, numpy's and R's default): x_(h) with h = (n - 1) q, 0-based, read
/// between its neighbours. NaN for no values; std::invalid_argument for q outside [0, 1] or a
/// non-finite value.
double quantile(std::vector<double> values, double q);

/// How one quantity spread over a set of runs: its extremes, 5th and 95th percentiles and median
/// (quantile()). All NaN when n = 0.
struct Spread {
  int n = 0;
  double min = NAN, p05 = NAN, median = NAN, p95 = NAN, max = NAN;
};
Spread spread(const std::vector<double>& values);

/// The exact two-sided McNemar test of paired successes: `only_a` worlds where A succeeded and B
/// failed, `only_b` the reverse. Under "the controllers are equally good" each discordant world is
/// a fair coin, so p = min(1, 2 P[X <= min(only_a, only_b)]) for X ~ Binomial(only_a + only_b,
/// 1/2); 1 without discordant worlds. std::invalid_argument for negative counts.
double mcnemar_exact_p(long only_a, long only_b);

/// One controller over the worlds of a Monte Carlo result.
struct ControllerReport {
  std::string name;
  int runs = 0;                ///< worlds
  int numerical_failures = 0;  ///< worlds whose simulation failed (left out of the rate)
  int invalid_worlds = 0;      ///< worlds that cannot exist (left out of the rate)
  int successes = 0;
  Interval ci;  ///< Wilson 95 % over runs - numerical_failures - invalid_worlds
  /// How the runs ended: to_string(Outcome) -> count, every outcome listed (zeros included).
  std::map<std::string, int> outcomes;
  /// The safe stops by what triggered them: control::to_string(StopCause) -> count (the causes
  /// that occurred; "other" for a safe stop without a recorded cause).
  std::map<std::string, int> safe_stops;
  /// Over the successes only (a failed run's margins describe how it failed, not how close a
  /// success came to failing): the motion's duration (s), the smallest normal force over
  /// m g sin(tilt) (worst: min), and the friction used, mu_max over the world's mu (worst: max;
  /// 1 is the slip limit).
  Spread duration_s, fn_min_ratio, friction_use;
};

/// Two controllers on the same worlds (the worlds where both had a physical outcome).
struct PairedComparison {
  std::string a, b;
  int worlds = 0;  ///< worlds both ran without a numerical failure
  int both = 0, only_a = 0, only_b = 0, neither = 0;
  double p_value = 1;  ///< mcnemar_exact_p(only_a, only_b)
};

struct ControllerComparison {
  std::vector<ControllerReport> controllers;  ///< in the result's order
  std::vector<PairedComparison> pairs;        ///< every pair (i < j) in that order
};

/// The per-controller reports and the paired comparisons of a Monte Carlo result (the
/// controllers in the order of result.summaries). std::invalid_argument if the records do not
/// hold one record per world and controller.
ControllerComparison compare_controllers(const MonteCarloResult& result);

/// runs.csv: one row per experiment (run, controller, outcome, what it drew, ...; the columns
/// are documented in docs/CLOSED_LOOP.md), in the records' order.
std::string runs_csv(const MonteCarloResult& result);

}  // namespace flatland::drivers
