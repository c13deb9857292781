// Running the rolling dynamics in time: integrators, events, dense output, run reports.
#pragma once

#include "flatland/sim/rolling.hpp"

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
};

struct EventSettings {
  bool stop_on_contact_loss = true;  ///< stop where the normal force reaches 0
  std::optional<double> mu;          ///< stop where |f_t| exceeds mu f_n (rolling -> slipping)
  double time_tolerance = 1e-12;     ///< s, events are located to this
  /// Stop when s_h leaves [lo, hi] (e.g. the disk rolled off around the outline); off if empty.
  std::optional<std::pair<double, double>> s_h_bounds;
};

struct RunOptions {
  double t_end = 1.0;  ///< s
  Formulation formulation = Formulation::kAuto;
  IntegratorSettings integrator;
  EventSettings events;
  bool record =
      true;  ///< keep every step (dense output, per-step samples, extrema); off for search
};

enum class StopReason { kEndTime, kContactLost, kSlip, kLeftBounds };
std::string to_string(StopReason r);

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
};

struct RecordedEvent {
  std::string kind;  ///< "junction", "contact_lost", "slip", "left_bounds", "apex"
  double t = 0;
  double s_h = 0;
};

/// Dense output over a whole run: the state at any time, projected onto the contact manifold.
class Trajectory {
 public:
  struct Step {
    double t0, h;
    Pieces pieces;
  };
  using Sampler = std::function<Sample(double t, const double* y, const Pieces& p)>;
  Trajectory() = default;
  /// `terms` coefficient vectors per step: 5 for the 4th-order (and Hermite) interpolants, 8 for
  /// DOP853's 7th-order one; both evaluate c0 + th(c1 + th1(c2 + th(c3 + th1(c4 + ...)))).
  Trajectory(int dimension, Sampler sampler, int terms = 5)
      : n_(dimension), terms_(terms), sampler_(std::move(sampler)) {}

  bool empty() const { return steps_.empty(); }
  double t_begin() const { return steps_.front().t0; }
  double t_end() const { return steps_.back().t0 + steps_.back().h; }
  std::size_t size() const { return steps_.size(); }
  const Step& step(std::size_t i) const { return steps_[i]; }
  /// Everything at time t (clamped to the run), from the dense output.
  Sample sample(double t) const;
  /// Only the hand contact parameter at t (cheap: no force solve).
  double s_h(double t) const;
  /// Samples every dt from the beginning to the end, both included.
  std::vector<Sample> resample(double dt) const;

  // Used by the integrator.
  void append(double t0, double h, const Pieces& p, const double* coeffs /* terms * n values */);
  void set_s_h_index(int i) { s_h_index_ = i; }

 private:
  std::size_t find(double t) const;
  void interpolate(std::size_t i, double t, double* y) const;
  int n_ = 0;
  int terms_ = 5;
  int s_h_index_ = 0;
  Sampler sampler_;
  std::vector<Step> steps_;
  std::vector<double> coeffs_;
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
  // Extrema over the run, located on the dense output (when recorded).
  double fn_min_ratio = std::numeric_limits<double>::quiet_NaN();
  double t_fn_min = std::numeric_limits<double>::quiet_NaN();
  double mu_required =
      std::numeric_limits<double>::quiet_NaN();  ///< max |f_t|/f_n (inf if f_n <= 0)
  double t_mu_required = std::numeric_limits<double>::quiet_NaN();
  std::optional<double> t_apex;         ///< first time s_h rises through 0 (the fingertip)
  std::optional<double> fn_apex_ratio;  ///< normal force ratio there
  bool contact_lost = false;            ///< f_n < 0 somewhere (or the run stopped on it)
};

struct Extrema {
  double fn_min_ratio = std::numeric_limits<double>::quiet_NaN();
  double t_fn_min = std::numeric_limits<double>::quiet_NaN();
  double mu_required = std::numeric_limits<double>::quiet_NaN();  ///< inf if f_n <= 0 somewhere
  double t_mu_required = std::numeric_limits<double>::quiet_NaN();
  long evaluations = 0;
};
/// Minimum normal force ratio and maximum required friction over [t_from, t_to] of a recorded
/// run, located on the dense output to `time_tolerance`.
Extrema find_extrema(const RunResult& run, double t_from, double t_to, double time_tolerance);

/// The formulation a problem will use under `requested`; throws if kReduced is impossible.
Formulation resolve_formulation(const RollingProblem& problem, Formulation requested);

/// Run the dynamics from `init` until options.t_end or a stopping event. Throws
/// std::invalid_argument for bad settings and std::runtime_error for numerical failure (step size
/// underflow, non-finite state, step budget exhausted), naming the time and s_h.
RunResult simulate(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                   const RunOptions& options);

}  // namespace flatland::sim
