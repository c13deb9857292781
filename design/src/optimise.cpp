#include "flatland/design/design.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/sensitivity.hpp"

#include <nlopt.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

namespace flatland::design {
namespace {

using sim::format_significant;

/// |s_h(T)| a solution may keep (of s_h, whose range over the hand is [-1, 1]): NLopt's tolerance
/// on the equality constraint and the feasibility test of an iterate.
constexpr double kSolutionTolerance = 1e-7;

void check_options(const sim::SimulationSpec& spec, const DesignOptions& o) {
  auto require = [](bool ok, const std::string& line) {
    if (!ok) throw std::invalid_argument("design: " + line);
  };
  require(spec.hand.shape == sim::HandSpec::Shape::kPolynomial,
          std::string("hand.shape: the polynomial hand only (its a, b, c, d are designed); got ") +
              sim::to_string(spec.hand.shape));
  require(spec.motion.kind == sim::MotionSpec::Kind::kButterfly,
          "motion.kind: the butterfly motion only (its k is designed)");
  require(std::isfinite(o.period) && o.period > 0,
          "period: must be positive and finite (s), got " + format_significant(o.period, 6));
  require(std::isfinite(o.shape_range) && o.shape_range > 0 && o.shape_range < 1,
          "shape_range: must be in (0, 1), got " + format_significant(o.shape_range, 6));
  require(std::isfinite(o.k_min) && std::isfinite(o.k_max) && -2 < o.k_min && o.k_min < o.k_max,
          "k bounds: need -2 < k_min < k_max, finite; got [" + format_significant(o.k_min, 6) +
              ", " + format_significant(o.k_max, 6) + "]");
  require(o.objective != Objective::kRobustness || (std::isfinite(o.mu) && o.mu > 0),
          "mu: the robustness objective needs the friction coefficient, positive and finite; got " +
              format_significant(o.mu, 6));
  require(std::isfinite(o.fn_margin) && o.fn_margin >= 0,
          "fn_margin: must be >= 0 and finite, got " + format_significant(o.fn_margin, 6));
  require(o.pieces >= 1 && o.pieces <= 100,
          "pieces: must be in [1, 100], got " + std::to_string(o.pieces));
  require(o.max_evaluations >= 1 && o.max_evaluations <= 100000,
          "max_evaluations: must be in [1, 100000], got " + std::to_string(o.max_evaluations));
  require(std::isfinite(o.tolerance) && o.tolerance > 0 && o.tolerance < 1,
          "tolerance: must be in (0, 1), got " + format_significant(o.tolerance, 6));
  require(spec.initial.t0 < 0.5 * o.period, "initial.t0: the run must start before T = " +
                                                format_significant(0.5 * o.period, 6) + " s");
}

/// The butterfly's constraints at one point (with `mu`, the friction margins at that mu), with
/// their gradients in all six parameters; each force margin over each of the window's parts.
struct Evaluation {
  Iterate iterate;
  std::optional<double> mu;  ///< the friction margins' mu (the epigraph's variable)
  sim::ParameterGradient d_s_T;
  std::vector<sim::WindowMargins> windows;
};

/// The optimisation problem NLopt sees: the free parameters (a, b, c, d, k, or k alone) and one
/// more variable, the epigraph's (the friction coefficient minimised, or the contact-loss margin
/// maximised first); evaluations cached by point (NLopt asks for the objective and each
/// constraint separately).
class Design {
 public:
  Design(const sim::SimulationSpec& spec, const DesignOptions& options, const Parameters& start,
         const std::function<void(const Iterate&)>& progress)
      : spec_(sim::paper_model(spec)), options_(options), start_(start), progress_(progress) {
    if (options.shape_free)
      free_ = {0, 1, 2, 3, 4};
    else
      free_ = {4};
  }

  const std::vector<int>& free() const { return free_; }
  unsigned variables() const { return static_cast<unsigned>(free_.size()) + 1; }

  Parameters parameters_of(const double* x) const {
    Parameters p = start_;
    for (std::size_t i = 0; i < free_.size(); ++i) p[free_[i]] = x[i];
    return p;
  }

  /// The evaluation at the parameters of x, with the friction margins at `mu` (cached for the
  /// last point).
  const Evaluation& at(const double* x, std::optional<double> mu) {
    const Parameters p = parameters_of(x);
    if (last_ && last_->iterate.parameters == p && last_->mu == mu) return *last_;
    last_ = evaluate(p, mu);
    iterates_.push_back(last_->iterate);
    if (progress_) progress_(last_->iterate);
    return *last_;
  }

  /// A gradient in the six parameters as NLopt's row over the variables (the epigraph's last).
  void row(const sim::ParameterGradient& g, double epigraph, double* out) const {
    for (std::size_t i = 0; i < free_.size(); ++i) out[i] = g[free_[i]];
    out[free_.size()] = epigraph;
  }

  Evaluation evaluate(const Parameters& p, std::optional<double> mu) {
    const sim::SimulationSpec s = spec_with(spec_, p);
    const auto problem = sim::build_problem(s);  // std::invalid_argument for an invalid hand
    const double T = 0.5 * p[5];
    sim::RunOptions o = s.run;
    o.t_end = T;
    o.record = false;
    o.audit = false;
    o.events.stop_on_contact_loss = false;  // rolling enforced, as the searches do
    o.events.stop_on_slip = false;
    o.events.s_h_bounds = std::make_pair(-3.0, 3.0);
    const sim::ForceMarginSensitivities margins = sim::force_margin_sensitivities(
        problem, s.initial, o, s.initial.t0, T, mu, options_.pieces);
    simulations_ += margins.runs;
    Evaluation e;
    e.mu = mu;
    e.iterate.evaluation = static_cast<int>(iterates_.size()) + 1;
    e.iterate.parameters = p;
    e.iterate.mu_required = margins.mu_required.value;
    e.iterate.fn_min_ratio = margins.fn_min_ratio.value;
    e.iterate.s_T = margins.run.final.s_h;
    const bool robustness = options_.objective == Objective::kRobustness;
    e.iterate.feasible =
        std::abs(e.iterate.s_T) <= kSolutionTolerance &&
        (robustness || e.iterate.fn_min_ratio >= options_.fn_margin - kSolutionTolerance);
    if (robustness && mu)
      e.iterate.robustness = std::min(margins.friction_margin.value, margins.fn_min_ratio.value);
    e.d_s_T = margins.end.row(0);  // T is held (the period is)
    e.windows = margins.windows;
    return e;
  }

  const std::vector<Iterate>& iterates() const { return iterates_; }
  int simulations() const { return simulations_; }
  void add_simulations(int n) { simulations_ += n; }

  /// An exception thrown inside NLopt's callbacks, kept to say why the search stopped.
  std::string failure;

 private:
  sim::SimulationSpec spec_;
  DesignOptions options_;
  Parameters start_;
  std::function<void(const Iterate&)> progress_;
  std::vector<int> free_;
  std::optional<Evaluation> last_;
  std::vector<Iterate> iterates_;
  int simulations_ = 0;
};

/// NLopt's callbacks: C functions, so nothing may be thrown through them. An exception (an
/// invalid hand, a run that rolled off) stops the search and is reported.
template <class F>
auto guarded(Design& lf, nlopt_opt opt, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const std::exception& e) {
    if (lf.failure.empty()) lf.failure = e.what();
    nlopt_force_stop(opt);
    return decltype(f())(std::numeric_limits<double>::quiet_NaN());
  }
}

/// What a search's epigraph variable y (the last) is: the friction coefficient minimised (the
/// least friction), the contact-loss margin maximised until it is restored, or the robustness
/// margin maximised.
enum class Goal { kLeastFriction, kRestoreMargin, kRobustness };

struct Context {
  Design* problem;
  nlopt_opt opt;
  double fn_margin;
  double disk_radius;  ///< m
  Goal goal;
  double mu;  ///< kRobustness's friction coefficient

  /// The mu the friction margins are taken at, at x: the variable y, the fixed mu, or none.
  std::optional<double> margins_mu(const double* x, unsigned n) const {
    if (goal == Goal::kLeastFriction) return x[n - 1];
    if (goal == Goal::kRobustness) return mu;
    return std::nullopt;
  }
};

/// The epigraph's variable: the last.
double epigraph_objective(unsigned n, const double* x, double* grad, void* data) {
  const auto& c = *static_cast<Context*>(data);
  if (grad) {
    std::fill(grad, grad + n, 0.0);
    grad[n - 1] = c.goal == Goal::kLeastFriction ? 1.0 : -1.0;  // minimise mu, maximise a margin
  }
  return c.goal == Goal::kLeastFriction ? x[n - 1] : -x[n - 1];
}

double solution_constraint(unsigned n, const double* x, double* grad, void* data) {
  auto& c = *static_cast<Context*>(data);
  return guarded(*c.problem, c.opt, [&] {
    const Evaluation& e = c.problem->at(x, c.margins_mu(x, n));
    if (grad) c.problem->row(e.d_s_T, 0.0, grad);
    return e.iterate.s_T;
  });
}

/// Over each part of the window: f_n / (m g sin tilt) >= the margin (with the friction's
/// epigraph) or >= the epigraph's variable (restoring the margin): m results <= 0.
void normal_force_constraints(unsigned m, double* result, unsigned n, const double* x, double* grad,
                              void* data) {
  auto& c = *static_cast<Context*>(data);
  guarded(*c.problem, c.opt, [&] {
    const Evaluation& e = c.problem->at(x, c.margins_mu(x, n));
    const bool fixed = c.goal == Goal::kLeastFriction;  // else f_n >= y, the variable
    for (unsigned i = 0; i < m; ++i) {
      const sim::MarginSensitivity& fn = e.windows[i].fn_min_ratio;
      result[i] = (fixed ? c.fn_margin : x[n - 1]) - fn.value;
      if (grad) c.problem->row(-fn.gradient, fixed ? 0.0 : 1.0, grad + i * n);
    }
    return 0.0;
  });
}

/// Over each part of the window: mu f_n - |f_t| >= 0 at the variable mu (the least friction; its
/// derivative in mu is f_n at the part's extremum), or >= the variable y at the fixed mu (the
/// robustness): m results <= 0.
void friction_constraints(unsigned m, double* result, unsigned n, const double* x, double* grad,
                          void* data) {
  auto& c = *static_cast<Context*>(data);
  guarded(*c.problem, c.opt, [&] {
    const Evaluation& e = c.problem->at(x, c.margins_mu(x, n));
    const bool variable_mu = c.goal == Goal::kLeastFriction;
    for (unsigned i = 0; i < m; ++i) {
      const sim::MarginSensitivity& margin = e.windows[i].friction_margin;
      result[i] = (variable_mu ? 0.0 : x[n - 1]) - margin.value;
      if (grad)
        c.problem->row(-margin.gradient, variable_mu ? -margin.fn_ratio : 1.0, grad + i * n);
    }
    return 0.0;
  });
}

/// The outline stays a hand: x(u) = (1 - u^2)(a + (a + c) u^2) is positive on (-1, 1) (the right
/// half does not reach its mirror image) exactly when a > 0 and 2a + c > 0; the bounds keep a > 0
/// (it stays within shape_range < 1 of the start's), and this keeps 2a + c >= kMinimumWidth:
/// 2a + c - kMinimumWidth >= 0, linear in a and c.
constexpr double kMinimumWidth = 1e-3;  // m: x'(1) = -2 (2a + c), the slope at the junctions

double outline_constraint(unsigned n, const double* x, double* grad, void* data) {
  auto& c = *static_cast<Context*>(data);
  const std::vector<int>& free = c.problem->free();
  const Parameters p = c.problem->parameters_of(x);
  if (grad) {
    std::fill(grad, grad + n, 0.0);
    for (std::size_t i = 0; i < free.size(); ++i)
      grad[i] = free[i] == 0 ? -2.0 : free[i] == 2 ? -1.0 : 0.0;
  }
  return kMinimumWidth - (2 * p[0] + p[2]);  // <= 0
}

/// The wells hold the disk: at the palm's and the back's middle (u = +-1, where x = 0 and y' = 0)
/// the outline's radius of curvature is 4 (2a + c)^2 / |4b + 6d| (x' = -+2 (2a + c), y'' = -+(4b +
/// 6d)); it must exceed the disk's radius for the disk to touch the well at one point (the paper's
/// hand: 0.081 m against 0.051 m). Kept >= kWellRadiusRatio r:
/// kWellRadiusRatio r |4b + 6d| - 4 (2a + c)^2 <= 0.
constexpr double kWellRadiusRatio = 1.1;

double well_constraint(unsigned n, const double* x, double* grad, void* data) {
  auto& c = *static_cast<Context*>(data);
  const std::vector<int>& free = c.problem->free();
  const Parameters p = c.problem->parameters_of(x);
  const double w = 2 * p[0] + p[2], v = 4 * p[1] + 6 * p[3];
  const double rr = kWellRadiusRatio * c.disk_radius, sign = v < 0 ? -1.0 : 1.0;
  if (grad) std::fill(grad, grad + n, 0.0);
  if (grad)
    for (std::size_t i = 0; i < free.size(); ++i) {
      const int j = free[i];
      grad[i] = j == 0   ? -16 * w
                : j == 2 ? -8 * w
                : j == 1 ? rr * sign * 4
                : j == 3 ? rr * sign * 6
                         : 0.0;
    }
  return rr * std::abs(v) - 4 * w * w;
}

std::string nlopt_reason(nlopt_result r) {
  switch (r) {
    case NLOPT_SUCCESS:
      return "converged";
    case NLOPT_STOPVAL_REACHED:
      return "the objective reached its stop value";
    case NLOPT_FTOL_REACHED:
      return "converged: the objective changed less than its tolerance";
    case NLOPT_XTOL_REACHED:
      return "converged: the variables changed less than their tolerance";
    case NLOPT_MAXEVAL_REACHED:
      return "stopped at max_evaluations";
    case NLOPT_MAXTIME_REACHED:
      return "stopped at the time limit";
    case NLOPT_FAILURE:
      return "failed (NLopt's generic failure)";
    case NLOPT_INVALID_ARGS:
      return "failed: invalid arguments";
    case NLOPT_OUT_OF_MEMORY:
      return "failed: out of memory";
    case NLOPT_ROUNDOFF_LIMITED:
      return "stopped: limited by rounding";
    case NLOPT_FORCED_STOP:
      return "stopped";
    default:
      return "stopped (NLopt result " + std::to_string(static_cast<int>(r)) + ")";
  }
}

}  // namespace

namespace {

/// The contact-loss margin is restored with this much to spare (of the weight), so that the
/// friction's search starts strictly inside it.
constexpr double kRestoreSpare = 0.02;

/// One SLSQP search from x (the free parameters and the epigraph's variable, last) for `goal`;
/// restoring the margin stops at fn_margin + kRestoreSpare.
nlopt_result search(Design& problem, const DesignOptions& options, double disk_radius, Goal goal,
                    std::vector<double>& x, const std::vector<double>& lower,
                    const std::vector<double>& upper) {
  const unsigned n = problem.variables();
  std::unique_ptr<std::remove_pointer_t<nlopt_opt>, decltype(&nlopt_destroy)> opt(
      nlopt_create(NLOPT_LD_SLSQP, n), &nlopt_destroy);
  if (!opt) throw std::runtime_error("design: NLopt could not create its SLSQP optimiser");
  Context context{&problem, opt.get(), options.fn_margin, disk_radius, goal, options.mu};
  nlopt_set_lower_bounds(opt.get(), lower.data());
  nlopt_set_upper_bounds(opt.get(), upper.data());
  nlopt_set_min_objective(opt.get(), epigraph_objective, &context);
  nlopt_add_equality_constraint(opt.get(), solution_constraint, &context, kSolutionTolerance);
  const std::vector<double> tolerances(options.pieces, kSolutionTolerance);
  nlopt_add_inequality_mconstraint(opt.get(), options.pieces, normal_force_constraints, &context,
                                   tolerances.data());
  if (goal == Goal::kRestoreMargin)
    nlopt_set_stopval(opt.get(), -(options.fn_margin + kRestoreSpare));
  else
    nlopt_add_inequality_mconstraint(opt.get(), options.pieces, friction_constraints, &context,
                                     tolerances.data());
  if (options.shape_free) {
    nlopt_add_inequality_constraint(opt.get(), outline_constraint, &context, 0.0);
    nlopt_add_inequality_constraint(opt.get(), well_constraint, &context, 0.0);
  }
  nlopt_set_xtol_rel(opt.get(), options.tolerance);
  nlopt_set_maxeval(opt.get(), options.max_evaluations);
  double value = 0;
  return nlopt_optimize(opt.get(), x.data(), &value);
}

/// The constraints and bounds that hold with equality at p (to 1e-6 of their scale).
std::vector<std::string> active_at(const Parameters& p, const Iterate& at,
                                   const DesignOptions& options, const Parameters& start,
                                   double disk_radius) {
  std::vector<std::string> active;
  for (int j = 0; j < 5; ++j) {
    if (!options.shape_free && j < 4) continue;
    const double lo = j == 4 ? options.k_min : start[j] - options.shape_range * std::abs(start[j]);
    const double hi = j == 4 ? options.k_max : start[j] + options.shape_range * std::abs(start[j]);
    const double tol = 1e-6 * std::max(1.0, std::abs(start[j]));
    const std::string name(sim::kButterflyParameters[j]);
    if (p[j] - lo <= tol) active.push_back(name + " at its lower bound");
    if (hi - p[j] <= tol) active.push_back(name + " at its upper bound");
  }
  if (options.objective == Objective::kLeastFriction && at.fn_min_ratio - options.fn_margin <= 1e-6)
    active.push_back("the contact-loss margin");
  if (options.shape_free) {
    const double w = 2 * p[0] + p[2], v = 4 * p[1] + 6 * p[3];
    if (w - kMinimumWidth <= 1e-6) active.push_back("the outline's width (2a + c)");
    if (4 * w * w - kWellRadiusRatio * disk_radius * std::abs(v) <= 1e-6 * disk_radius)
      active.push_back("the wells' radius of curvature");
  }
  return active;
}

/// The most friction a design may be asked to need, and the contact-loss margin's range while it
/// is restored: the epigraph variables' bounds.
constexpr double kMaxMu = 1e3, kMarginRange = 1e3;

}  // namespace

std::string to_string(Objective o) {
  return o == Objective::kRobustness ? "robustness" : "least-friction";
}

sim::SimulationSpec spec_with(sim::SimulationSpec spec, const Parameters& p) {
  spec.hand.a = p[0];
  spec.hand.b = p[1];
  spec.hand.c = p[2];
  spec.hand.d = p[3];
  spec.motion.k = p[4];
  spec.motion.period = p[5];
  return spec;
}

DesignResult optimise(const sim::SimulationSpec& spec, const DesignOptions& options,
                      const std::function<void(const Iterate&)>& progress) {
  check_options(spec, options);
  const double disk_radius = *sim::build_problem(spec)->object.disk_radius;
  DesignResult out;
  // The start: the spec's hand, and the k that brings the disk to s_h(T) = 0 (the paper's
  // motion-only search).
  const sim::SolveReport solved = sim::solve_k(spec, options.period);
  out.start = {spec.hand.a, spec.hand.b, spec.hand.c, spec.hand.d, solved.k, options.period};
  if (out.start[4] < options.k_min || out.start[4] > options.k_max)
    throw std::invalid_argument(
        "design: k bounds: the start's k = " + format_significant(out.start[4], 8) +
        " is outside [" + format_significant(options.k_min, 6) + ", " +
        format_significant(options.k_max, 6) + "]");

  out.objective = options.objective;
  out.mu = options.mu;
  Design problem(spec, options, out.start, progress);
  problem.add_simulations(solved.simulations);
  const std::vector<int>& free = problem.free();
  const std::size_t n = problem.variables();
  std::vector<double> x(n), lower(n), upper(n);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const int j = free[i];
    x[i] = out.start[j];
    if (j == 4) {
      lower[i] = options.k_min;
      upper[i] = options.k_max;
    } else {
      const double half = options.shape_range * std::abs(out.start[j]);
      lower[i] = out.start[j] - half;
      upper[i] = out.start[j] + half;
    }
  }
  const bool robustness = options.objective == Objective::kRobustness;
  const std::optional<double> mu = robustness ? std::optional<double>(options.mu) : std::nullopt;
  out.start_point = problem.at(x.data(), mu).iterate;

  // One search for `goal` from x, its variable y starting at y0 within [lo, hi]; why it stopped.
  auto run_search = [&](Goal goal, double y0, double lo, double hi) {
    problem.failure.clear();
    x[n - 1] = y0;
    lower[n - 1] = lo;
    upper[n - 1] = hi;
    std::string stop = nlopt_reason(search(problem, options, disk_radius, goal, x, lower, upper));
    return problem.failure.empty() ? stop : stop + ": " + problem.failure;
  };
  if (robustness) {
    // Maximise y with mu f_n - |f_t| >= y and f_n >= y over every part; the start is a solution.
    out.stop =
        run_search(Goal::kRobustness, out.start_point.robustness, -kMarginRange, kMarginRange);
  } else {
    Iterate from = out.start_point;
    if (out.start_point.fn_min_ratio < options.fn_margin) {
      // The motion-only solution comes too near contact loss (or loses contact): restore the
      // margin first, if the free variables can: maximise y with f_n >= y over every part.
      out.restore_stop = run_search(Goal::kRestoreMargin, out.start_point.fn_min_ratio,
                                    -kMarginRange, kMarginRange);
      from = problem.at(x.data(), std::nullopt).iterate;
      out.restored = from.feasible;
    }
    if (from.feasible)  // mu_required is finite: f_n > 0 throughout
      out.stop = run_search(Goal::kLeastFriction, from.mu_required, 0.0,
                            std::max(kMaxMu, from.mu_required));
    else
      out.stop = "no feasible start: the contact-loss margin could not be restored (" +
                 out.restore_stop + ")";
  }

  out.iterates = problem.iterates();
  out.simulations = problem.simulations();
  // The best feasible iterate; a robustness iterate counts only with its margins at the fixed mu
  // (those of the restoring search have none).
  auto better = [&](const Iterate& a, const Iterate& b) {
    return robustness ? a.robustness > b.robustness : a.mu_required < b.mu_required;
  };
  out.best = out.start_point;
  for (const Iterate& it : out.iterates)
    if (it.feasible && (!robustness || !std::isnan(it.robustness)) &&
        (!out.best.feasible || better(it, out.best)))
      out.best = it;
  if (out.best.feasible)
    out.active = active_at(out.best.parameters, out.best, options, out.start, disk_radius);
  return out;
}

}  // namespace flatland::design
