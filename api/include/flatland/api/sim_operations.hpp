// The simulator's operations as `flatland solve|simulate|time-optimal` and the Python module's
// flatland.solve/simulate/time_optimal offer them: a request of optional overrides of the scene,
// checked one way before any work, then run. A bad value is a UsageError (exit 2 in the CLI,
// ValueError in Python) whose message names the option as the caller spells it: `--sample-dt` on
// the command line, `sample_dt` in Python; the reason is the same text.
#pragma once

#include "flatland/design/design.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_spec.hpp"

#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace flatland::api {

/// Bad input that the scene loader does not see: an option's value (exit code 2, like SceneError).
class UsageError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// How messages name an option.
enum class Spelling {
  kCommandLine,  ///< --sample-dt
  kPython,       ///< sample_dt
};
/// `name` is the Python spelling (sample_dt).
std::string option_name(std::string_view name, Spelling spelling);

/// UsageError unless v is finite (and, with require_positive, > 0). `option` is spelled already.
void require_finite(const std::string& option, double v);
void require_positive(const std::string& option, double v, const std::string& unit);
/// The most rows a trajectory resampled every --sample-dt may have: a million rows is ~0.5 GB of
/// CSV and ~0.2 GB in memory (and 1 kHz over 1000 s).
inline constexpr double kMaxSamples = 1e6;
/// UsageError (naming `option`) unless dt is positive and finite and a span of `span` s at that
/// spacing stays within kMaxSamples rows.
void require_sample_spacing(const std::string& option, double dt, double span);
/// UsageError unless from < to.
void require_increasing(const std::string& from_option, double from, const std::string& to_option,
                        double to);

/// Overrides of the scene's `simulator` section.
struct IntegratorOverrides {
  std::optional<std::string> method;       ///< dopri5, dop853 or rk4
  std::optional<double> rtol, atol, step;  ///< step: rk4's fixed step, s
  std::optional<double> energy_tolerance;  ///< the energy balance's relative tolerance
  std::optional<std::string> formulation;  ///< auto, general or reduced
};
/// Check the overrides and set them in scene.sim.run.
void apply_integrator_overrides(const IntegratorOverrides& o, Scene& scene, Spelling spelling);
/// Check the method and tolerance overrides and set them in `settings` (a spatial scene's);
/// a formulation is refused (the spatial path has one).
void apply_integrator_overrides(const IntegratorOverrides& o, sim::IntegratorSettings& settings,
                                Spelling spelling);

/// Set spec.contact.mu (UsageError for a negative value or one below the scene's
/// contact.mu_kinetic).
void apply_mu(double mu, sim::SimulationSpec& spec, Spelling spelling);
/// Set a spatial scene's contact mu (UsageError for a negative or non-finite value).
void apply_mu(double mu, sim::SpatialSpec& spec, Spelling spelling);

/// sim::build_problem, with " (set by OPTION)" added to its message when the field it names was
/// given as an option: `given` pairs a scene field ("motion.k") with its option (spelled).
std::shared_ptr<const sim::RollingProblem> build_problem_checked(
    const sim::SimulationSpec& spec, const std::vector<std::pair<std::string, std::string>>& given);

/// `solve`: the butterfly's k (or the hand's cubic coefficient d) that brings the disk to
/// s_h(T) = 0.
struct SolveRequest {
  IntegratorOverrides integrator;
  std::optional<double> period;  ///< 2T, s
  std::optional<double> k;       ///< solving for k: the start; for d: the motion's k
  std::string solve_for = "k";   ///< k or d
  double tolerance = 1e-9;
};
/// The scene with the request applied and checked (a butterfly motion).
sim::SimulationSpec prepare_solve(Scene scene, const SolveRequest& request, Spelling spelling);
sim::SolveReport solve(const sim::SimulationSpec& spec, const SolveRequest& request);

/// `simulate`: one run of the scene.
struct SimulateRequest {
  IntegratorOverrides integrator;
  std::optional<double> period;  ///< 2T, s; also the duration unless `duration` is given
  std::optional<double> k;
  std::optional<double> duration;  ///< s
  std::optional<double> mu;
  std::optional<std::string> model;  ///< rolling or hybrid
  bool stop_on_contact_loss = true;  ///< rolling model only
  /// Keep every step (a trajectory to write or return). false: the run keeps a bounded window
  /// of recent steps (its extrema, apex and s_h(T) are folded as it goes), so that memory does
  /// not grow with simulated time.
  bool keep_trajectory = true;
};
struct PreparedSimulation {
  sim::SimulationSpec spec;
  std::shared_ptr<const sim::RollingProblem> problem;
  bool keep_trajectory = true;
};
PreparedSimulation prepare_simulate(Scene scene, const SimulateRequest& request, Spelling spelling);
/// A spatial scene (space: 3d) with the request's overrides, checked as the planar ones are
/// (UsageError naming the option): the rolling model only, period and k for a butterfly motion
/// only, duration, mu, stop_on_contact_loss and the integrator's method and tolerances.
/// keep_trajectory is the caller's (sim::SpatialRunOptions::record).
sim::SpatialSpec prepare_spatial_simulate(const Scene& scene, const SimulateRequest& request,
                                          Spelling spelling);
/// The run, recorded (dense output and per-step samples: every step, or with keep_trajectory
/// false a bounded window of them and s_h at the butterfly's half period as a probe).
sim::RunResult simulate(const PreparedSimulation& prepared);

/// `time-optimal`: the fastest butterfly in [from, to] that keeps contact (and friction, with mu).
struct TimeOptimalRequest {
  IntegratorOverrides integrator;
  std::optional<double> mu;
  double from = 0.9, to = 1.5;  ///< 2T bracket, s
  double period_tolerance = 1e-7, tolerance = 1e-9;
};
sim::SimulationSpec prepare_time_optimal(Scene scene, const TimeOptimalRequest& request,
                                         Spelling spelling);
sim::TimeOptimalReport time_optimal(const sim::SimulationSpec& spec,
                                    const TimeOptimalRequest& request);

/// `design`: the hand's shape and the butterfly's motion designed together (docs/DESIGN.md).
/// Objectives 1, least-friction, and 3, robustness (at `mu`, or the scene's contact.mu), are
/// built; shortest-period is refused, saying so.
struct DesignRequest {
  IntegratorOverrides integrator;
  std::string objective = "least-friction";
  std::optional<double> period;  ///< 2T, s; default: the scene's motion.period
  std::optional<double> mu;      ///< robustness: the friction coefficient; default contact.mu
  bool motion_only = false;      ///< the scene's hand held, k alone free
  double shape_range = 0.25;
  double fn_margin = 0.05;
  int max_evaluations = 100;
  double tolerance = 1e-7;
};
/// The scene with the request checked (a polynomial hand and the butterfly motion, options in
/// range; UsageError naming the option).
sim::SimulationSpec prepare_design(Scene scene, const DesignRequest& request, Spelling spelling);
design::DesignResult design(const sim::SimulationSpec& spec, const DesignRequest& request,
                            const std::function<void(const design::Iterate&)>& progress = {});

/// `locus`: the butterfly solutions k(2T) at n periods evenly spaced over [from, to] (Fig. 7).
struct LocusRequest {
  IntegratorOverrides integrator;
  std::optional<double> mu;
  double from = 1.1, to = 3.0;  ///< 2T, s
  int n = 20;                   ///< 1 to 10000
  double tolerance = 1e-9;
};
sim::SimulationSpec prepare_locus(Scene scene, const LocusRequest& request, Spelling spelling);
std::vector<sim::SolveReport> locus(const sim::SimulationSpec& spec, const LocusRequest& request,
                                    const sim::Progress& progress = {});

/// `surface`: s_h(T) on a k x 2T grid (Fig. 6).
struct SurfaceRequest {
  IntegratorOverrides integrator;
  double k_from = -1.6, k_to = -0.8;
  double period_from = 0.8, period_to = 2.0;  ///< 2T, s
  int nk = 50, np = 50;                       ///< 2 to 10000 each, at most 1e6 points
  int threads = 0;                            ///< 0: all cores
};
sim::SimulationSpec prepare_surface(Scene scene, const SurfaceRequest& request, Spelling spelling);
/// On `engine` if given (an MPI job's ranks), else on request.threads of this process.
sim::SurfaceResult surface(const sim::SimulationSpec& spec, const SurfaceRequest& request,
                           const sim::Progress& progress = {},
                           const sim::SweepEngine* engine = nullptr);

}  // namespace flatland::api
