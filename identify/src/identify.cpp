// identify(): the multiple-shooting least squares on Ceres, its covariance and the refusal of
// what the data do not determine (docs/IDENTIFY.md, "Method").
#include "flatland/identify/identify.hpp"

#include "covariance.hpp"
#include "shooting.hpp"

#include "flatland/sim/format.hpp"

#include <ceres/ceres.h>
#include <ceres/manifold.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <thread>

namespace flatland::identify {
namespace {

using detail::Segment;
using detail::SegmentOutput;
using detail::ShootingProblem;

/// The difference steps: relative 1e-3 of a parameter's size (or of its typical size, when
/// smaller), 1e-5 of s_h and 1e-4 1/s of sdot_h. Measured on the throw recording of
/// tests/identify at rtol 1e-10 against relative 1e-3: the drag's derivatives differ by 1.6 %
/// at 1e-4 and 21 % at 1e-5 (the integrator's error and the chattering bounces' events, which
/// shift with a parameter by whole steps, dominate the quotient below that), the states' by ~1 %
/// from 1e-4 down to 1e-6. docs/IDENTIFY.md, "Derivatives".
constexpr double kDifferenceStep = 1e-3;
constexpr double kStateStepS = 1e-5, kStateStepSdot = 1e-4;

/// The continuation of the continuity conditions (docs/IDENTIFY.md, "Convergence"): their scale
/// is first relaxed by these factors, one solve each, then the final solve holds it at 1. Held
/// at 1 from the start, the conditions make a valley 1e-3 sigma narrow whose floor curves with
/// the states: a Gauss-Newton step along it leaves it quadratically (on the closed-loop
/// experiment of tests/cli the continuity cost along the step grew as 2.3e4 t^2 while the
/// samples' chi^2 fell linearly), the trust region shrank to steps whose gain was below the
/// cost's noise (the simulator's end states jitter by ~6e-8 at rtol 1e-10, 0.26 of the scale),
/// and Ceres called it convergence with chi^2 31 above the minimum. Relaxed, the valley is wide
/// enough to travel; each tighter solve starts at the floor of the next.
constexpr std::array<double, 2> kContinuityRelaxation = {100.0, 10.0};

/// One segment's residuals: its samples' (s_h_sim - s_h_meas) / sigma and, unless it is the
/// last of its recording, the continuity of (s_h, sdot_h) with the next segment's initial state,
/// its scale multiplied by `relaxation` (1 in the final solve; larger while the continuation
/// closes the gaps, see solve()). Parameter blocks: the segment's state (2), the world (if any
/// unknown), the next state (2, if any). Derivatives by central differences (one-sided at a
/// bound), the next state's exactly; the column of an unknown that is held (`held[j]` not empty)
/// is zero and costs no simulation.
class SegmentCost final : public ceres::CostFunction {
 public:
  SegmentCost(const ShootingProblem& problem, std::size_t k, const std::vector<std::string>& held,
              const double& relaxation)
      : problem_(problem), k_(k), held_(held), relaxation_(relaxation) {
    const Segment& s = problem.segments()[k];
    samples_ = static_cast<int>(s.end - s.first);
    set_num_residuals(samples_ + (s.has_next ? 2 : 0));
    mutable_parameter_block_sizes()->push_back(2);
    worlds_ = static_cast<int>(problem.unknowns().size());
    if (worlds_ > 0) mutable_parameter_block_sizes()->push_back(worlds_);
    if (s.has_next) mutable_parameter_block_sizes()->push_back(2);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double* state = parameters[0];
    const double* world = worlds_ > 0 ? parameters[1] : nullptr;
    const double* next =
        problem_.segments()[k_].has_next ? parameters[worlds_ > 0 ? 2 : 1] : nullptr;
    const int n = num_residuals();
    std::vector<double> base(static_cast<std::size_t>(n));
    if (!residuals_at(state[0], state[1], world, next, base.data())) return false;
    if (residuals) std::copy(base.begin(), base.end(), residuals);
    if (!jacobians) return true;
    if (jacobians[0] && !state_jacobian(state, world, next, base.data(), jacobians[0]))
      return false;
    if (worlds_ > 0 && jacobians[1] &&
        !world_jacobian(state, world, next, base.data(), jacobians[1]))
      return false;
    if (next) {
      double* J = jacobians[worlds_ > 0 ? 2 : 1];
      if (J) {
        std::fill(J, J + 2 * n, 0.0);
        const std::size_t r = problem_.segments()[k_].recording;
        J[(samples_)*2 + 0] = -1.0 / scale_s(r);
        J[(samples_ + 1) * 2 + 1] = -1.0 / scale_sdot(r);
      }
    }
    return true;
  }

 private:
  bool residuals_at(double s, double sdot, const double* world, const double* next,
                    double* out) const {
    SegmentOutput o;
    if (!problem_.simulate(k_, s, sdot, world, o)) return false;
    const Segment& seg = problem_.segments()[k_];
    const Recording& rec = problem_.recordings()[seg.recording];
    for (int i = 0; i < samples_; ++i) {
      const std::size_t j = seg.first + static_cast<std::size_t>(i);
      out[i] = problem_.s_difference(o.s_h[static_cast<std::size_t>(i)], rec.s_h[j]) / rec.sigma[j];
    }
    if (next) {
      out[samples_] = problem_.s_difference(o.s_end, next[0]) / scale_s(seg.recording);
      out[samples_ + 1] = (o.sdot_end - next[1]) / scale_sdot(seg.recording);
    }
    return true;
  }

  double scale_s(std::size_t recording) const {
    return relaxation_ * problem_.continuity_scale_s(recording);
  }
  double scale_sdot(std::size_t recording) const {
    return relaxation_ * problem_.continuity_scale_sdot(recording);
  }

  /// Column `col` of a row-major n x cols Jacobian by differences of `residuals_with(x, out)` at
  /// x = value + up and value - down (each >= 0): central, or one-sided against the base
  /// residuals where a step is 0 (at a bound) or its run fails. The integrator gives up at
  /// isolated perturbed points (seen on closed-loop experiments: a numerical failure in one
  /// difference run of one segment), and a failed Jacobian ends the whole solve, so one side is
  /// enough. False when neither side runs.
  template <class ResidualsWith>
  bool difference_column(const ResidualsWith& residuals_with, double value, double up, double down,
                         const double* base, int col, int cols, double* J) const {
    const std::size_t n = static_cast<std::size_t>(num_residuals());
    std::vector<double> plus(n), minus(n);
    const bool has_plus = up > 0 && residuals_with(value + up, plus.data());
    const bool has_minus = down > 0 && residuals_with(value - down, minus.data());
    if (!has_plus && !has_minus) return false;
    const double* hi = has_plus ? plus.data() : base;
    const double* lo = has_minus ? minus.data() : base;
    const double step = (has_plus ? up : 0.0) + (has_minus ? down : 0.0);
    for (std::size_t i = 0; i < n; ++i)
      J[i * static_cast<std::size_t>(cols) + static_cast<std::size_t>(col)] =
          (hi[i] - lo[i]) / step;
    return true;
  }

  bool state_jacobian(const double* state, const double* world, const double* next,
                      const double* base, double* J) const {
    const double steps[2] = {kStateStepS, kStateStepSdot};
    for (int c = 0; c < 2; ++c) {
      const auto with = [&](double x, double* out) {
        double xs[2] = {state[0], state[1]};
        xs[c] = x;
        return residuals_at(xs[0], xs[1], world, next, out);
      };
      if (!difference_column(with, state[c], steps[c], steps[c], base, c, 2, J)) return false;
    }
    return true;
  }

  bool world_jacobian(const double* state, const double* world, const double* next,
                      const double* base, double* J) const {
    std::vector<double> w(world, world + worlds_);
    for (int c = 0; c < worlds_; ++c) {
      const auto cc = static_cast<std::size_t>(c);
      if (!held_[cc].empty()) {
        for (int i = 0; i < num_residuals(); ++i) J[i * worlds_ + c] = 0.0;
        continue;
      }
      const detail::Unknown& u = problem_.unknowns()[cc];
      const double h = kDifferenceStep * std::max(std::abs(world[c]), u.typical);
      // Central inside the bounds, one-sided where a side would leave them (a negative drag or
      // a restitution above 1 is no world the simulator accepts).
      const double up = std::min(world[c] + h, u.bounds.upper) - world[c];
      const double down = world[c] - std::max(world[c] - h, u.bounds.lower);
      const auto with = [&](double x, double* out) {
        w[cc] = x;
        const bool ok = residuals_at(state[0], state[1], w.data(), next, out);
        w[cc] = world[c];
        return ok;
      };
      if (!difference_column(with, world[c], up, down, base, c, worlds_, J)) return false;
    }
    return true;
  }

  const ShootingProblem& problem_;
  std::size_t k_;
  const std::vector<std::string>& held_;
  const double& relaxation_;
  int samples_ = 0, worlds_ = 0;
};

/// Reports each iteration to the caller's progress function.
class ProgressCallback final : public ceres::IterationCallback {
 public:
  ProgressCallback(const IdentifyOptions& options, const ShootingProblem& problem,
                   std::chrono::steady_clock::time_point start)
      : options_(options), problem_(problem), start_(start) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    Progress p;
    p.iteration = summary.iteration;
    p.cost = summary.cost;
    p.simulations = problem_.simulations();
    p.wall_time = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    options_.progress(p);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const IdentifyOptions& options_;
  const ShootingProblem& problem_;
  std::chrono::steady_clock::time_point start_;
};

/// The world spec with the fitted values in place.
sim::SimulationSpec fitted_world(const sim::SimulationSpec& world, const detail::WorldValues& v) {
  sim::SimulationSpec out = world;
  out.contact = v.law;
  out.tilt = v.tilt;
  return out;
}

int hardware_threads() {
  return std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

ceres::Solver::Options solver_options(const IdentifyOptions& options,
                                      ceres::IterationCallback* callback) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = options.max_iterations;
  so.num_threads = options.threads > 0 ? options.threads : hardware_threads();
  // A relative change of the cost below 1e-6 moves chi^2 by far less than the 1 that a one-sigma
  // change of a parameter makes; the events make the last digits of the cost ragged anyway.
  so.function_tolerance = 1e-6;
  so.gradient_tolerance = 1e-12;
  so.parameter_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  if (callback) so.callbacks.push_back(callback);
  return so;
}

/// Holds the unknowns whose `held` entry is not empty at their current values: the world block
/// constant when all are, a subset manifold over it otherwise (kept in `manifolds`, which the
/// problem does not own).
void hold(ceres::Problem& cp, std::vector<double>& w, const std::vector<std::string>& held,
          std::vector<std::unique_ptr<ceres::Manifold>>& manifolds) {
  std::vector<int> constant;
  for (std::size_t j = 0; j < held.size(); ++j)
    if (!held[j].empty()) constant.push_back(static_cast<int>(j));
  if (constant.size() == w.size()) {
    cp.SetParameterBlockConstant(w.data());
    return;
  }
  manifolds.push_back(
      std::make_unique<ceres::SubsetManifold>(static_cast<int>(w.size()), constant));
  cp.SetManifold(w.data(), manifolds.back().get());
}

/// The warnings of a solved fit: a solver that did not converge, chi^2 beyond its quantile.
void fit_warnings(const ceres::Solver::Summary& summary, const IdentifyOptions& options,
                  IdentifyResult& result) {
  if (summary.termination_type == ceres::NO_CONVERGENCE)
    result.warnings.push_back(
        "the fit did not converge: the solver stopped after max_iterations = " +
        std::to_string(options.max_iterations) + " iterations (" + summary.message +
        "); the values are where it stopped, not a minimum of chi^2: raise max_iterations");
  else if (summary.termination_type != ceres::CONVERGENCE)
    result.warnings.push_back("the fit did not converge: Ceres ended with " +
                              result.termination_type + " (" + summary.message +
                              "); the values are where it stopped, not a minimum of chi^2");
  else if (!result.converged)
    result.warnings.push_back(
        "the fit did not reach a minimum of chi^2: Ceres stopped on its tolerance (" +
        summary.message + "), but the linear model there still moves a parameter by " +
        sim::format_significant(result.step_in_sigma, 2) + " sigma and lowers chi^2 by " +
        sim::format_significant(result.chi2_decrease_expected, 2) +
        "; the values are where it stopped: start from other values, or use shorter segments");
  if (result.sigma_scale > 1)
    result.warnings.push_back(
        "chi^2 " + sim::format_significant(result.chi2, 4) + " for " +
        std::to_string(result.degrees_of_freedom) + " degrees of freedom exceeds its " +
        sim::format_number(100 * detail::kConsistentChi2Quantile) + " % quantile " +
        sim::format_significant(result.chi2_limit, 4) +
        ": every sigma is scaled by sqrt(chi^2/dof) = " +
        sim::format_significant(result.sigma_scale, 3) +
        " (the unscaled beside it); the measurements' sigma is too small or the model misses "
        "something (structure in the residuals over time says the model)");
}

}  // namespace

namespace detail {

IdentifyResult solve(const ShootingProblem& problem, const sim::SimulationSpec& world,
                     const IdentifyOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const std::size_t K = problem.unknowns().size();
  std::vector<double> w(K);
  for (std::size_t j = 0; j < K; ++j) w[j] = problem.unknowns()[j].initial;
  std::vector<std::array<double, 2>> states(problem.segments().size());
  for (std::size_t k = 0; k < states.size(); ++k)
    states[k] = {problem.segments()[k].guess_s, problem.segments()[k].guess_sdot};
  // The starting point must simulate: its failure is the user's world or data, said once.
  for (std::size_t k = 0; k < states.size(); ++k) {
    SegmentOutput o;
    std::string why;
    if (!problem.simulate(k, states[k][0], states[k][1], w.data(), o, &why))
      throw std::runtime_error("identify: at the starting values, " + why);
  }

  // held[j]: why unknown j is held at its starting value (empty: fitted).
  std::vector<std::string> held(K);
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::TAKE_OWNERSHIP;
  problem_options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  std::vector<std::unique_ptr<ceres::Manifold>> manifolds;
  ceres::Problem cp(problem_options);
  // The continuity conditions' scale factor, which every segment's cost reads (1: as defined).
  double relaxation = 1;
  bool joined = false;  // any continuity condition at all
  for (std::size_t k = 0; k < states.size(); ++k) {
    std::vector<double*> blocks{states[k].data()};
    if (K > 0) blocks.push_back(w.data());
    if (problem.segments()[k].has_next) blocks.push_back(states[k + 1].data());
    joined = joined || problem.segments()[k].has_next;
    cp.AddResidualBlock(new SegmentCost(problem, k, held, relaxation), nullptr, blocks);
  }
  for (std::size_t j = 0; j < K; ++j) {
    cp.SetParameterLowerBound(w.data(), static_cast<int>(j), problem.unknowns()[j].bounds.lower);
    cp.SetParameterUpperBound(w.data(), static_cast<int>(j), problem.unknowns()[j].bounds.upper);
  }
  std::unique_ptr<ProgressCallback> callback;
  if (options.progress) callback = std::make_unique<ProgressCallback>(options, problem, start);
  const ceres::Solver::Options so = solver_options(options, callback.get());
  // First the segments' states with the world held at its starting values: the guesses from the
  // data leave large gaps at the boundaries, and closing them while the world moves too sent the
  // world far off (into another minimum) in trials; then everything together, the continuity
  // conditions relaxed and tightened step by step (kContinuityRelaxation) before the last solve.
  ceres::Solver::Summary summary;
  int iterations = 0;
  if (joined) relaxation = kContinuityRelaxation.front();
  if (K > 0) {
    cp.SetParameterBlockConstant(w.data());
    ceres::Solve(so, &cp, &summary);
    iterations += static_cast<int>(summary.iterations.size()) - 1;
    cp.SetParameterBlockVariable(w.data());
  }
  if (joined) {
    for (const double factor : kContinuityRelaxation) {
      relaxation = factor;
      ceres::Solve(so, &cp, &summary);
      iterations += static_cast<int>(summary.iterations.size()) - 1;
    }
    relaxation = 1;
  }
  // A parameter the data do not determine would wander where its noisy derivatives take it and
  // drag the others along (adding an unconstrained mu_kinetic to a closed-loop experiment moved
  // its rolling resistance by 3 sigma): it is held at its starting value, the value the fitted
  // scene keeps, and the rest fitted again, until every free parameter is determined.
  IdentifyResult result;
  for (;;) {
    ceres::Solve(so, &cp, &summary);
    iterations += static_cast<int>(summary.iterations.size()) - 1;
    // The report's Jacobian has a column per unknown (a held one's zero): no manifold, which
    // would drop the held columns, and not constant.
    if (K > 0) {
      cp.SetManifold(w.data(), nullptr);
      cp.SetParameterBlockVariable(w.data());
    }
    detail::report_fit(problem, cp, w, states, options, held, result);
    bool newly_held = false;
    for (std::size_t j = 0; j < K; ++j) {
      if (!held[j].empty() || result.parameters[j].sigma) continue;
      const Unknown& u = problem.unknowns()[j];
      held[j] = result.parameters[j].not_determined + "; held at its starting value " +
                sim::format_number(u.initial) + ", the others fitted with it there";
      w[j] = u.initial;
      newly_held = true;
    }
    if (!newly_held) break;
    hold(cp, w, held, manifolds);
  }

  result.iterations = iterations;
  // Ceres' convergence means its steps stopped gaining, not that the minimum is reached: the
  // Gauss-Newton step at the solution says how far it still lies.
  result.converged = summary.termination_type == ceres::CONVERGENCE &&
                     result.step_in_sigma <= detail::kConvergedStepInSigma;
  result.termination_type = ceres::TerminationTypeToString(summary.termination_type);
  result.termination = summary.message;
  fit_warnings(summary, options, result);
  for (std::size_t k = 0; k < states.size(); ++k) {
    const Segment& seg = problem.segments()[k];
    SegmentOutput o;
    if (!seg.has_next || !problem.simulate(k, states[k][0], states[k][1], w.data(), o)) continue;
    if (o.end_mode == sim::ContactMode::kFlight || o.end_mode == sim::ContactMode::kSliding)
      result.warnings.push_back(problem.recordings()[seg.recording].name +
                                ": at t = " + sim::format_number(seg.t_end) +
                                " s the fitted run is in " + sim::to_string(o.end_mode) +
                                " where a segment starts rolling: choose another segment_duration");
  }
  const detail::WorldValues v = problem.values(w.data());
  result.world = fitted_world(world, v);
  result.angle_offset = v.angle_offset;
  result.time_offset = v.time_offset;
  result.simulations = problem.simulations();
  result.simulation_time = problem.simulation_time();
  result.wall_time =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace detail

IdentifyResult identify(const sim::SimulationSpec& world, const std::vector<Recording>& recordings,
                        const IdentifyOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const ShootingProblem problem(world, recordings, options);
  IdentifyResult result = detail::solve(problem, world, options);
  result.wall_time =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace flatland::identify
