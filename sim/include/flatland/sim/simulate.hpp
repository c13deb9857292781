// Running the rolling dynamics in time: integrators, events, dense output, run reports.
#pragma once

#include "flatland/sim/energy.hpp"
#include "flatland/sim/rolling.hpp"

#include <array>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace flatland::sim {

enum class Method {
  kDormandPrince54,  ///< adaptive embedded 5(4), FSAL, 4th-order dense output
  kRungeKutta4,      ///< classical fixed step, cubic Hermite dense output
  /// adaptive Dormand-Prince 8(5,3) (Hairer's DOP853): 8th order, 5th-order error estimate with
  /// a 3rd-order correction, FSAL, 7th-order dense output (3 extra stages per recorded step)
  kDormandPrince853,
};
enum class Formulation {
  kAuto,     ///< reduced when the object is a disk, general otherwise
  kGeneral,  ///< the paper's A x = b with projection
  kReduced,  ///< one coordinate, disk only
};

std::string to_string(Method m);
std::string to_string(Formulation f);

struct IntegratorSettings {
  Method method = Method::kDormandPrince54;
  double rtol = 1e-10;       ///< relative tolerance (Dormand-Prince 5(4) and 8(5,3))
  double atol = 1e-12;       ///< absolute tolerance (Dormand-Prince 5(4) and 8(5,3))
  double fixed_step = 1e-3;  ///< s (RK4)
  double max_step = std::numeric_limits<double>::infinity();  ///< s (Dormand-Prince)
  long max_steps = 5'000'000;                                 ///< runtime error beyond this
  /// The energy balance's relative tolerance (flatland/sim/energy.hpp); absent: the default
  /// energy_tolerance() derives from rtol (or 1e-6 for RK4).
  std::optional<double> energy_tolerance;
};

struct EventSettings {
  /// Rolling model: stop where the normal force reaches 0 (the hybrid model flies instead).
  bool stop_on_contact_loss = true;
  /// Rolling model: stop where |f_t| exceeds mu f_n, mu = the problem's contact.mu (the hybrid
  /// model slides instead). Off for searches, which enforce rolling and check friction after.
  bool stop_on_slip = true;
  double time_tolerance = 1e-12;  ///< s, events are located to this
  /// Stop when s_h leaves [lo, hi] (e.g. the disk rolled off around the outline); off if empty.
  std::optional<std::pair<double, double>> s_h_bounds;
};

struct RunOptions {
  double t_end = 1.0;  ///< s
  Formulation formulation = Formulation::kAuto;
  IntegratorSettings integrator;
  EventSettings events;
  ContactModel model = ContactModel::kRolling;
  /// Hybrid model: stop right after the first change of contact mode or impact. For a driver
  /// whose hand motion depends on the contact (the closed loop's joint, loaded by the disk).
  bool stop_at_transition = false;
  /// Hybrid model: the hand's inertia about its fixed pivot, kg m^2, for impacts; the hand's
  /// velocity change is reported with the impact and the run stops there (its motion is no
  /// longer the prescribed one). Absent: the motion is prescribed (an infinitely heavy hand).
  std::optional<double> hand_inertia;
  bool record =
      true;  ///< keep every step (dense output, per-step samples, extrema); off for search
  /// With `record`: keep at most about twice this many recent steps; the older ones are folded
  /// into the run's extrema and apex (RunResult::folded) and dropped, so that memory does not
  /// grow with simulated time. 0 keeps every step (a trajectory to write or to look up).
  long keep_steps = 0;
  /// With `record`: the samples at these times (within the run) are kept in RunResult::probes,
  /// whatever keep_steps drops.
  std::vector<double> probe_times;
  /// Keep the energy audit (flatland/sim/energy.hpp). Off only for a search's bracketing probes
  /// (sim/search.cpp): their s_h(T) only steers the root finder, and the answer is run again,
  /// recorded and audited, before anything is reported; the rolling model only (the hybrid
  /// model always audits).
  bool audit = true;
  /// For the energy audit's own tests only: a factor on every impact's impulse where it changes
  /// the object's velocities (the audit books the law's impulse). 1 in every real run; anything
  /// else is a deliberately wrong term that the audit must catch.
  double testing_impulse_factor = 1.0;
};

enum class StopReason {
  kEndTime,
  kContactLost,  ///< rolling model: the normal force reached 0
  kSlip,         ///< rolling model: |f_t| reached mu f_n
  kLeftBounds,
  kDropped,     ///< hybrid model: the object flew out of the hand's reach and cannot come back
  kTransition,  ///< hybrid model with stop_at_transition: the first mode change or impact
  /// The energy balance broke its bound (RunResult::audit): the numbers are wrong from there on.
  /// Never a success.
  kNumericalFailure,
};
std::string to_string(StopReason r);

enum class EventKind {
  kJunction,     ///< s_h crossed a junction of the hand's pieces
  kContactLost,  ///< rolling model: stopped at f_n = 0
  kSlip,         ///< rolling model: stopped at |f_t| = mu f_n
  kLeftBounds,
  kApex,         ///< s_h rose through 0 (the fingertip)
  kLiftOff,      ///< f_n reached 0: flight begins
  kSlipStart,    ///< |f_t| reached mu f_n: sliding begins
  kSlipReverse,  ///< the slip stopped and resumed the other way (rolling needs more than mu)
  kStick,        ///< the slip stopped within the friction cone: rolling again
  kRest,         ///< the rolling stopped, held by the rolling-resistance couple
  kRelease,      ///< the couple reached its bound: rolling again
  kImpact,       ///< the object hit the hand (and bounced, or stayed: see `caught`)
  kDropped,      ///< the object left the hand's reach for good
  /// While sliding, the object's rotation relative to the hand reversed (the rolling-resistance
  /// couple turns with it). Changes the load only: not recorded.
  kTurn,
  kNumericalFailure,  ///< the energy balance broke its bound (RunResult::audit)
};
std::string to_string(EventKind k);

/// What the integrator did, so accuracy can be audited.
struct RunStats {
  long steps = 0;              ///< accepted steps
  long rejected = 0;           ///< rejected steps (Dormand-Prince)
  long rhs_evals = 0;          ///< right-hand-side evaluations
  long event_evals = 0;        ///< force evaluations for events and extrema
  int restarts = 0;            ///< integrator restarts (junctions s_h = +-1, motion breakpoints)
  int junction_crossings = 0;  ///< crossings of hand junctions (s_h odd integer)
  double max_drift = 0;        ///< largest constraint residual removed by a projection (general)
  double max_constraint_residual = 0;  ///< largest constraint residual after projection
  double max_redundant_residual = 0;   ///< largest |A x - b| seen at step ends (general)
  // Hybrid model.
  int mode_changes = 0;  ///< changes between rolling, rest, sliding and flight
  int impacts = 0;
  /// s spent in each mode (indexed by ContactMode).
  std::array<double, 4> mode_time{0, 0, 0, 0};
  long gap_evals = 0;  ///< distance computations in flight
};

struct RecordedEvent {
  EventKind kind = EventKind::kJunction;
  double t = 0;
  double s_h = 0;
  Vec2 position = Vec2::Zero();  ///< object centre, world, m (hybrid events)
  /// kImpact: the law's result; whether the object stayed in contact (the rebound was at most
  /// contact.capture_velocity); the hand's velocity change when it has an inertia.
  std::optional<ImpactResult> impact;
  bool caught = false;
  double hand_rate_change = 0;  ///< rad/s
  /// J: the object's mechanical energy (kinetic + potential in the table plane) after the event
  /// minus before (kImpact; with a prescribed hand, the hand may give energy when it moves).
  double energy_change = 0;
};

/// Dense output over a whole run: the state at any time, projected onto the contact manifold.
/// A hybrid run is a sequence of parts, one per segment in one mode: integrated parts keep each
/// step's interpolant, flights their closed form. At an instant where one part ends and the next
/// begins (an impact), the later part answers.
class Trajectory {
 public:
  struct Step {
    double t0, h;
    Pieces pieces;
  };
  using Sampler = std::function<Sample(double t, const double* y, const Pieces& p)>;
  /// The sample at any time of a closed-form part.
  using Closed = std::function<Sample(double t)>;

  bool empty() const;
  double t_begin() const;
  double t_end() const;
  /// Everything at time t (clamped to the run), from the dense output.
  Sample sample(double t) const;
  /// Only the hand contact parameter at t (cheap: no force solve).
  double s_h(double t) const;
  /// Samples every dt from the beginning to the end, both included.
  std::vector<Sample> resample(double dt) const;

  // Used by the integrators.
  /// Start an integrated part: `dimension` state values, `terms` coefficient vectors per step (5
  /// for the 4th-order and Hermite interpolants, 8 for DOP853's 7th-order one; both evaluate
  /// c0 + th(c1 + th1(c2 + th(c3 + th1(c4 + ...))))), s_h at `s_h_index` of the state.
  void begin_part(int dimension, Sampler sampler, int terms, int s_h_index);
  void append(double t0, double h, const Pieces& p, const double* coeffs /* terms * n values */);
  void add_closed_part(double t0, double t1, Closed f);
  /// Forget everything before t (whole steps and closed parts that end at or before it), so that
  /// a long run keeps a bounded window (RunOptions::keep_steps).
  void drop_before(double t);

 private:
  struct Part {
    int n = 0, terms = 5, s_h_index = 0;
    Sampler sampler;
    Closed closed;
    double t0 = 0, t1 = 0;
    std::vector<Step> steps;
    std::vector<double> coeffs;
    std::size_t find(double t) const;
    void interpolate(std::size_t i, double t, double* y) const;
  };
  const Part& part_at(double t) const;
  std::vector<Part> parts_;
};

struct RunResult {
  StopReason reason = StopReason::kEndTime;
  Formulation formulation = Formulation::kReduced;  ///< the one actually used
  Method method = Method::kDormandPrince54;
  Sample initial, final;
  std::vector<Sample> steps;  ///< one per accepted step end, and the start (when recorded)
  Trajectory trajectory;      ///< dense output (when recorded)
  std::vector<RecordedEvent> events;
  RunStats stats;
  // Extrema over the run, located on the dense output (when recorded): the smallest normal force
  // while in contact, the largest friction coefficient needed while rolling (or at rest).
  double fn_min_ratio = std::numeric_limits<double>::quiet_NaN();
  double t_fn_min = std::numeric_limits<double>::quiet_NaN();
  double mu_required =
      std::numeric_limits<double>::quiet_NaN();  ///< max |f_t|/f_n (inf if f_n <= 0)
  double t_mu_required = std::numeric_limits<double>::quiet_NaN();
  std::optional<double> t_apex;         ///< first time s_h rises through 0 (the fingertip)
  std::optional<double> fn_apex_ratio;  ///< normal force ratio there
  /// f_n < 0 somewhere (or the run stopped on it), or, in the hybrid model, the object flew.
  bool contact_lost = false;
  /// Hybrid model: where the run ended, to continue it (the closed loop steps the world so).
  std::optional<HybridState> final_state;
  /// The energy balance (flatland/sim/energy.hpp): broken only with reason kNumericalFailure.
  EnergyAudit audit;
  /// With RunOptions::keep_steps: the extrema of the steps already dropped (located there as
  /// finish_run locates the kept ones'; finish_run merges them).
  struct Folded {
    long steps = 0;  ///< steps dropped
    double fn_min_ratio = std::numeric_limits<double>::quiet_NaN();
    double t_fn_min = std::numeric_limits<double>::quiet_NaN();
    double mu_required = std::numeric_limits<double>::quiet_NaN();
    double t_mu_required = std::numeric_limits<double>::quiet_NaN();
  } folded;
  /// The samples at RunOptions::probe_times, in the order the run reached them.
  std::vector<Sample> probes;
};

struct Extrema {
  double fn_min_ratio = std::numeric_limits<double>::quiet_NaN();
  double t_fn_min = std::numeric_limits<double>::quiet_NaN();
  double mu_required = std::numeric_limits<double>::quiet_NaN();  ///< inf if f_n <= 0 somewhere
  double t_mu_required = std::numeric_limits<double>::quiet_NaN();
  /// With a friction coefficient mu: the smallest friction to spare while rolling,
  /// min (mu f_n - |f_t|) / (m g sin tilt) (< 0 where rolling needs more than mu); NaN without.
  double friction_margin = std::numeric_limits<double>::quiet_NaN();
  double t_friction_margin = std::numeric_limits<double>::quiet_NaN();
  long evaluations = 0;
};
/// Minimum normal force ratio and maximum required friction over [t_from, t_to] of a recorded
/// run, located on the dense output to `time_tolerance`; with `mu`, the friction margin too.
Extrema find_extrema(const RunResult& run, double t_from, double t_to, double time_tolerance,
                     std::optional<double> mu = std::nullopt);

/// The formulation a problem will use under `requested`; throws if kReduced is impossible.
Formulation resolve_formulation(const RollingProblem& problem, Formulation requested);

/// std::runtime_error ("WHAT: numerical failure: the energy balance broke at ...") when `run`
/// ended as a numerical failure: for callers that go on to use a recorded run (a plan, frames).
void require_no_numerical_failure(const RunResult& run, const std::string& what);

/// Settings that every model checks: integrator tolerances, step and the time span from t0; a
/// fixed step (RK4) that would take more than max_steps over the span is refused here, before
/// any work (std::invalid_argument naming integrator.step).
void validate_run_options(const RunOptions& options, double t0);

/// Why an integrator setting given as input (a scene key, a command-line option, a Python
/// argument) is refused, or "" when it is fine: `key` is the scene's name. rtol in [1e-14, 0.1]
/// (tighter than ~100 rounding units the error estimate is rounding noise; looser than 10 % is
/// no solution), atol in [1e-18, 1] (the state's values are lengths of millimetres to metres and
/// rates of them: 1e-18 is rounding of a millimetre), energy_tolerance in [1e-12, 1], step and
/// max_step positive and finite (s).
std::string integrator_setting_problem(const std::string& key, double value);
/// std::invalid_argument naming contact.drag (or drag_angular) when the drag relaxes the
/// object's velocity so fast that an explicit integrator, stable only for steps below about
/// 3 m / c, would need more than is.max_steps steps over `span` s.
void check_drag_stiffness(const RollingProblem& problem, const IntegratorSettings& is, double span);
/// std::invalid_argument naming integrator.step when a fixed step (RK4) would take more than
/// is.max_steps over `span` s (the spatial run checks the same).
void check_fixed_step_budget(const IntegratorSettings& is, double span);
/// Extrema, apex and contact_lost of a finished recorded run.
void finish_run(RunResult& run, const RunOptions& options);

/// Run the dynamics from `init` until options.t_end or a stopping event (options.model: the
/// rolling model, or the hybrid model of sim/hybrid.hpp). Throws
/// std::invalid_argument for bad settings and std::runtime_error for numerical failure (step size
/// underflow, non-finite state, step budget exhausted), naming the time and s_h.
RunResult simulate(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                   const RunOptions& options);

}  // namespace flatland::sim
