#include "flatland/sim/search.hpp"
#include "flatland/sim/format.hpp"

#include "flatland/sim/parallel.hpp"

#include "flatland/sim/roots.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>

namespace flatland::sim {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// The validated hand and object are shared by every run of a search; only the motion changes.
std::shared_ptr<const RollingProblem> with_motion(const std::shared_ptr<const RollingProblem>& base,
                                                  double period, double k) {
  auto pb = std::make_shared<RollingProblem>(*base);
  pb->motion = std::make_shared<ButterflyMotion>(period, k);
  return pb;
}

RunOptions search_options(const SimulationSpec& spec, double t_end) {
  RunOptions o = spec.run;
  o.t_end = t_end;
  o.record = false;
  o.events.stop_on_contact_loss = false;  // rolling is enforced; forces are checked afterwards
  o.events.stop_on_slip = false;
  // Past the mirrored tips (|s_h| = 3 is the far side of the outline) the disk has rolled off
  // around the hand; stopping there keeps s_h(T) continuous (it ends at the bound) and avoids
  // integrating an enforced roll that spins ever faster.
  o.events.s_h_bounds = std::make_pair(-3.0, 3.0);
  // The bracketing probes are not audited (the audit's per-stage power costs ~20 % of this
  // hot loop): their s_h(T) only steers Brent's method, and the answer is run again, recorded
  // and audited (evaluate_on), before anything is reported. The surface, whose every point is
  // a reported number, turns the audit back on.
  o.audit = false;
  return o;
}

/// What a numerical failure (a broken energy balance) of the run at (period, k) says.
std::string numerical_failure_text(double period, double k, const EnergyAudit& a) {
  return "the run at 2T = " + format_significant(period, 8) +
         " s, k = " + format_significant(k, 8) + " failed numerically: " + breach_text(a);
}

/// s_h(T) of one unrecorded run (audited with `audit`); NaN where the run failed numerically (its
/// energy balance broke), with `failure` (if given) saying where.
double s_at_half_period(const std::shared_ptr<const RollingProblem>& base,
                        const SimulationSpec& spec, double period, double k, long* rhs_evals,
                        std::string* failure = nullptr, bool audit = false) {
  RunOptions o = search_options(spec, spec.initial.t0 + 0.5 * period);
  o.audit = audit;
  const RunResult r = simulate(with_motion(base, period, k), spec.initial, o);
  if (rhs_evals) *rhs_evals += r.stats.rhs_evals;
  if (r.reason == StopReason::kNumericalFailure) {
    if (failure) *failure = numerical_failure_text(period, k, r.audit);
    return kNaN;
  }
  return r.final.s_h;
}

/// s_at_half_period for a search: a numerical failure ends the search (NumericalFailure): a
/// root cannot be bracketed through numbers known to be wrong.
double searched_s_at_half_period(const std::shared_ptr<const RollingProblem>& base,
                                 const SimulationSpec& spec, double period, double k,
                                 long* rhs_evals, bool audit = false) {
  std::string failure;
  const double s = s_at_half_period(base, spec, period, k, rhs_evals, &failure, audit);
  if (!failure.empty()) throw NumericalFailure("solve: " + failure);
  return s;
}

void check_period(double period) {
  if (!(period > 0) || !std::isfinite(period))
    throw std::invalid_argument("period: must be positive and finite (2T in s)");
}

struct Bracket {
  double a, b, fa, fb;
};

// What to try when no motion of duration 2T has a solution. Durations scale as
// 1/sqrt(g sin(tilt)) (the rolling equations in units of sqrt(length / (g sin(tilt)))), so a 2T
// meant for a vertical plane, the paper's 1.181 s say, is the commonest miss on a tilted table.
std::string no_solution_hint(const SimulationSpec& spec, double period) {
  std::string hint = " (";
  const double vertical = 0.5 * std::numbers::pi;
  if (std::abs(spec.tilt - vertical) > 1e-9 && spec.tilt > 0) {
    hint += "durations scale as 1/sqrt(g sin(tilt)): 2T = " + format_significant(period, 6) +
            " s in a vertical plane is 2T = " +
            format_significant(period / std::sqrt(std::sin(spec.tilt)), 4) + " s at this tilt of " +
            format_significant(spec.tilt * 180 / std::numbers::pi, 4) + " deg; ";
  }
  return hint + "try the scene's own period, or a locus over a range of 2T to see which have one)";
}

// Walk from x0 in steps that double until f changes sign, first in the direction in which |f|
// decreases, then the other way. f may throw std::invalid_argument for a parameter outside its
// domain (an invalid shape): that direction then ends there.
std::optional<Bracket> find_bracket(const std::function<double(double)>& f, double x0, double fx0,
                                    double step, double lo, double hi) {
  if (fx0 == 0) return Bracket{x0, x0, 0.0, 0.0};
  auto walk = [&](double dir) -> std::optional<Bracket> {
    double a = x0, fa = fx0, h = step;
    for (int i = 0; i < 60; ++i) {
      double b = std::clamp(a + dir * h, lo, hi);
      if (b == a) return std::nullopt;
      double fb;
      try {
        fb = f(b);
      } catch (const std::invalid_argument&) {
        return std::nullopt;
      }
      if (!std::isfinite(fb)) return std::nullopt;
      if ((fa > 0) != (fb > 0) || fb == 0)
        return Bracket{std::min(a, b), std::max(a, b), a < b ? fa : fb, a < b ? fb : fa};
      a = b;
      fa = fb;
      h *= 2;
    }
    return std::nullopt;
  };
  // Probe the slope once to choose the first direction.
  double first = +1;
  try {
    const double probe = std::clamp(x0 + 0.25 * step, lo, hi);
    if (probe != x0) {
      const double fp = f(probe);
      if ((fp > 0) != (fx0 > 0))
        return Bracket{std::min(x0, probe), std::max(x0, probe), x0 < probe ? fx0 : fp,
                       x0 < probe ? fp : fx0};
      first = std::abs(fp) < std::abs(fx0) ? +1 : -1;
    }
  } catch (const std::invalid_argument&) {
    first = -1;
  }
  if (auto b = walk(first)) return b;
  return walk(-first);
}

// Brent's method converges to a sign change, and a sign change is not always a root: for slow
// motions s_h(T) is so sensitive to k (or d) that, in double precision, it jumps between "still
// on the palm" and "fallen off the tip" (|s_h(T)| ~ 3) across the final bracket. Such a point is
// no solution, so it is reported as an error instead of returned. A true root has a residual of
// about slope x bracket width; the slope is probed on either side when the residual is not
// already negligible (the probes cost two runs to T).
void check_root_is_continuous(const std::function<double(double)>& f, const RootResult& root,
                              double tolerance, double lo, double hi, const std::string& what) {
  constexpr double kNegligible = 1e-6;  // of s_h, whose range is [-1, 1] over the hand
  if (std::abs(root.fx) <= kNegligible) return;
  const double h = std::max(1e3 * tolerance, 1e-6 * std::max(1.0, std::abs(root.x)));
  // A probe outside the parameter's domain (an invalid shape) falls back to the root itself.
  auto probe = [&](double x, double& fx_out) {
    try {
      fx_out = f(x);
      return std::isfinite(fx_out);
    } catch (const std::invalid_argument&) {
      return false;
    }
  };
  double a = std::max(lo, root.x - h), b = std::min(hi, root.x + h), fa = 0, fb = 0;
  if (!probe(a, fa)) a = root.x, fa = root.fx;
  if (!probe(b, fb)) b = root.x, fb = root.fx;
  const double slope = b > a ? std::abs(fb - fa) / (b - a) : 0.0;
  if (std::abs(root.fx) <= 10 * slope * tolerance) return;
  throw std::runtime_error("solve: s_h(T) changes sign at " + what + " = " +
                           format_significant(root.x, 8) + " but jumps there (it stays at " +
                           format_significant(root.fx, 8) +
                           "), so this is no solution: the motion is too sensitive near it; try "
                           "another starting " +
                           what);
}

}  // namespace

double half_period_s_h(const SimulationSpec& spec, double period, double k, long* rhs_evals) {
  check_period(period);
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  s.motion.period = period;
  s.motion.k = k;
  return searched_s_at_half_period(build_problem(s), s, period, k, rhs_evals, true);
}

namespace {
/// evaluate() on an already built problem of the same spec (the motion is replaced).
SolveReport evaluate_on(const std::shared_ptr<const RollingProblem>& base,
                        const SimulationSpec& spec, double period, double k) {
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  s.motion.period = period;
  s.motion.k = k;
  RunOptions o = search_options(s, s.initial.t0 + period);
  o.record = true;
  o.audit = true;  // the answer is audited (the probes were not)
  SolveReport rep;
  rep.period = period;
  rep.k = k;
  rep.d = s.hand.d;
  rep.run = simulate(with_motion(base, period, k), s.initial, o);
  const RunResult& r = rep.run;
  if (r.reason == StopReason::kNumericalFailure)
    throw NumericalFailure("solve: " + numerical_failure_text(period, k, r.audit));
  const double T = s.initial.t0 + 0.5 * period;
  rep.s_T = r.trajectory.s_h(T);
  rep.s_end = r.final.s_h;
  rep.sdot_end = r.final.sdot_h;
  // A solution (s_h(T) = 0) is symmetric about T: reflecting the world and reversing time maps
  // it onto itself, so its second half repeats the first. Forces are therefore taken over
  // [0, T], where they are well conditioned; integrating a slow, nearly balanced roll on to 2T
  // amplifies rounding exponentially (s_end shows it).
  const Extrema x =
      find_extrema(r, s.initial.t0, std::min(T, r.final.t), o.events.time_tolerance, s.contact.mu);
  rep.fn_apex_ratio = r.final.t >= T ? r.trajectory.sample(T).fn_ratio : kNaN;
  rep.fn_min_ratio = x.fn_min_ratio;
  rep.mu_required = x.mu_required;
  rep.friction_margin = x.friction_margin;
  rep.simulations += 1;
  rep.rhs_evals += r.stats.rhs_evals;
  return rep;
}
}  // namespace

SolveReport evaluate(const SimulationSpec& spec, double period, double k) {
  check_period(period);
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  s.motion.period = period;
  s.motion.k = k;
  return evaluate_on(build_problem(s), s, period, k);
}

namespace {
SolveReport solve_k_from(const SimulationSpec& spec,
                         const std::shared_ptr<const RollingProblem>& base, double period,
                         double k0, const SearchSettings& set) {
  int sims = 0;
  long rhs = 0;
  auto f = [&](double k) {
    ++sims;
    return searched_s_at_half_period(base, spec, period, k, &rhs);
  };
  // k = -2 is singular (P(1) = 0); beyond k = 2 the hand no longer dips at all.
  const double lo = -2.0 + 1e-6, hi = 2.0;
  k0 = std::clamp(k0, lo, hi);
  const auto br = find_bracket(f, k0, f(k0), 0.02, lo, hi);
  if (!br)
    throw std::runtime_error("solve: no k in (-2, 2] brings the disk to s_h(T) = 0 for 2T = " +
                             format_significant(period, 8) + " s" + no_solution_hint(spec, period));
  const RootResult root = br->a == br->b ? RootResult{br->a, 0.0, 0, true}
                                         : brent_root(f, br->a, br->b, br->fa, br->fb,
                                                      set.tolerance, set.max_evaluations);
  if (!root.converged)
    throw std::runtime_error(
        "solve: root finder did not converge for 2T = " + format_significant(period, 8) + " s");
  check_root_is_continuous(f, root, set.tolerance, lo, hi, "k");
  SolveReport rep = evaluate_on(base, spec, period, root.x);
  rep.simulations += sims;
  rep.rhs_evals += rhs;
  return rep;
}
}  // namespace

namespace {
// The problem a search runs on: every search starts the disk in the palm and asks for the back.
std::shared_ptr<const RollingProblem> searched_problem(const SimulationSpec& s,
                                                       const std::string& search) {
  auto problem = build_problem(s);
  require_palm_and_back(s.hand, *problem->hand, search);
  return problem;
}
}  // namespace

SolveReport solve_k(const SimulationSpec& spec, double period, const SearchSettings& set) {
  check_period(period);
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  s.motion.period = period;
  return solve_k_from(s, searched_problem(s, "the search for k (solve)"), period, spec.motion.k,
                      set);
}

SolveReport solve_d(const SimulationSpec& spec, double period, double k,
                    const SearchSettings& set) {
  check_period(period);
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  s.motion.period = period;
  s.motion.k = k;
  if (s.hand.shape != HandSpec::Shape::kPolynomial)
    throw std::invalid_argument(std::string("hand.shape: ") + to_string(s.hand.shape) +
                                ": the search for d varies the polynomial hand's d (hand.shape: "
                                "polynomial)");
  searched_problem(s, "the search for d (solve)");  // the starting shape must be valid
  int sims = 0;
  long rhs = 0;
  auto f = [&](double d) {
    SimulationSpec sd = s;
    sd.hand.d = d;
    ++sims;
    return searched_s_at_half_period(build_problem(sd), sd, period, k, &rhs);  // validates
  };
  const double scale = std::max(std::abs(s.hand.a), std::abs(s.hand.b));
  const auto br = find_bracket(f, s.hand.d, f(s.hand.d), 0.01 * scale, s.hand.d - 10 * scale,
                               s.hand.d + 10 * scale);
  if (!br)
    throw std::runtime_error(
        "solve: no valid hand shape d brings the disk to s_h(T) = 0 for 2T = " +
        format_significant(period, 8) + " s, k = " + format_significant(k, 8) +
        no_solution_hint(s, period));
  const RootResult root = br->a == br->b ? RootResult{br->a, 0.0, 0, true}
                                         : brent_root(f, br->a, br->b, br->fa, br->fb,
                                                      set.tolerance * scale, set.max_evaluations);
  if (!root.converged) throw std::runtime_error("solve: root finder did not converge for d");
  check_root_is_continuous(f, root, set.tolerance * scale, s.hand.d - 10 * scale,
                           s.hand.d + 10 * scale, "d");
  s.hand.d = root.x;
  SolveReport rep = evaluate(s, period, k);
  rep.simulations += sims;
  rep.rhs_evals += rhs;
  return rep;
}

std::vector<SolveReport> locus(const SimulationSpec& spec, double from, double to, int n,
                               const SearchSettings& set, const Progress& progress) {
  check_period(from);
  check_period(to);
  if (n < 1) throw std::invalid_argument("n: must be at least 1");
  if (n > 1 && !(to > from)) throw std::invalid_argument("to: must be larger than from");
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  const auto base = searched_problem(s, "locus");
  std::vector<SolveReport> out;
  double k0 = spec.motion.k;
  for (int i = 0; i < n; ++i) {
    const double period = n == 1 ? from : from + (to - from) * i / (n - 1);
    try {
      out.push_back(solve_k_from(s, base, period, k0, set));
      out.back().run = RunResult{};  // keep the locus light: the reports, not every trajectory
      k0 = out.back().k;             // warm start: the locus is smooth
    } catch (const NumericalFailure& e) {
      // A period whose runs fail numerically is recorded (no k) and the locus goes on.
      SolveReport failed;
      failed.period = period;
      failed.k = failed.s_T = failed.s_end = failed.sdot_end = kNaN;
      failed.fn_apex_ratio = failed.fn_min_ratio = failed.mu_required = kNaN;
      failed.failure = e.what();
      out.push_back(std::move(failed));
    }
    if (progress) progress(i + 1, n);
  }
  return out;
}

SurfaceResult surface(const SimulationSpec& spec, double k_lo, double k_hi, int nk, double p_lo,
                      double p_hi, int np, int threads, const Progress& progress) {
  if (threads < 0) throw std::invalid_argument("surface: threads must be >= 0");
  return surface(spec, k_lo, k_hi, nk, p_lo, p_hi, np, ThreadSweep(static_cast<unsigned>(threads)),
                 progress);
}

SurfaceResult surface(const SimulationSpec& spec, double k_lo, double k_hi, int nk, double p_lo,
                      double p_hi, int np, const SweepEngine& engine, const Progress& progress) {
  if (nk < 2 || np < 2) throw std::invalid_argument("surface: nk and np must be at least 2");
  if (!(k_hi > k_lo) || !std::isfinite(k_lo) || !std::isfinite(k_hi))
    throw std::invalid_argument("k-to: must be larger than k-from");
  if (k_lo <= -2 && k_hi >= -2)
    throw std::invalid_argument("k-from/k-to: the range must not contain k = -2");
  check_period(p_lo);
  check_period(p_hi);
  if (!(p_hi > p_lo)) throw std::invalid_argument("period-to: must be larger than period-from");
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  const auto base = searched_problem(s, "surface");
  SurfaceResult res;
  for (int i = 0; i < nk; ++i) res.k.push_back(k_lo + (k_hi - k_lo) * i / (nk - 1));
  for (int j = 0; j < np; ++j) res.period.push_back(p_lo + (p_hi - p_lo) * j / (np - 1));
  res.s_T.assign(static_cast<std::size_t>(nk) * np, kNaN);
  const long total = static_cast<long>(nk) * np;
  std::vector<long> evals(static_cast<std::size_t>(total), 0);
  std::vector<std::string> failures(static_cast<std::size_t>(total));
  sim::ItemCodec codec;
  codec.pack = [&](long idx, ByteWriter& w) {
    const auto u = static_cast<std::size_t>(idx);
    w.put(res.s_T[u]);
    w.put(evals[u]);
    w.put(failures[u]);
  };
  codec.unpack = [&](long idx, ByteReader& in) {
    const auto u = static_cast<std::size_t>(idx);
    in.get(res.s_T[u]);
    in.get(evals[u]);
    in.get(failures[u]);
  };
  try {
    engine.run(
        total,
        [&](long idx) {
          const int i = static_cast<int>(idx / np), j = static_cast<int>(idx % np);
          const auto u = static_cast<std::size_t>(idx);
          // A point whose run fails numerically stays NaN and is reported; the grid goes on.
          res.s_T[u] =
              s_at_half_period(base, s, res.period[j], res.k[i], &evals[u], &failures[u], true);
        },
        codec,
        [&](long finished) {
          if (progress) progress(finished, total);
        });
  } catch (const std::exception& e) {
    throw std::runtime_error(std::string("surface: ") + e.what());
  }
  for (long e : evals) res.rhs_evals += e;
  for (long idx = 0; idx < total; ++idx)
    if (!failures[static_cast<std::size_t>(idx)].empty())
      res.numerical_failures.push_back({static_cast<int>(idx / np), static_cast<int>(idx % np),
                                        failures[static_cast<std::size_t>(idx)]});
  return res;
}

std::string to_string(SpeedLimit l) {
  return l == SpeedLimit::kFriction ? "friction" : "normal_force";
}

TimeOptimalReport time_optimal(const SimulationSpec& spec, double lo, double hi,
                               double period_tolerance, const SearchSettings& set) {
  check_period(lo);
  check_period(hi);
  if (!(hi > lo)) throw std::invalid_argument("to: must be larger than from");
  SimulationSpec s = paper_model(spec);
  s.motion.kind = MotionSpec::Kind::kButterfly;
  const auto base = searched_problem(s, "time-optimal");
  const bool friction = s.contact.mu.has_value();
  TimeOptimalReport rep;
  double k0 = spec.motion.k;
  // The binding constraint: the normal force and, with mu, the friction to spare (both in
  // units of the weight), each rising with 2T.
  const auto limit = [&](const SolveReport& r) {
    return friction ? std::min(r.fn_min_ratio, r.friction_margin) : r.fn_min_ratio;
  };
  auto g = [&](double period) {
    ++rep.solves;
    SolveReport r = solve_k_from(s, base, period, k0, set);
    k0 = r.k;
    return limit(r);
  };
  const double glo = g(lo), ghi = g(hi);
  const std::string what = friction ? "minimum of the normal force ratio and the friction margin"
                                    : "minimum normal force ratio";
  if (!(glo < 0 && ghi > 0))
    throw std::runtime_error("time-optimal: [" + format_significant(lo, 8) + ", " +
                             format_significant(hi, 8) +
                             "] s does not bracket the fastest admissible solution (" + what + " " +
                             format_significant(glo, 8) + " at 2T = " + format_significant(lo, 8) +
                             " s, " + format_significant(ghi, 8) + " at " +
                             format_significant(hi, 8) + " s; it must go from < 0 to > 0)");
  const RootResult root = brent_root(g, lo, hi, glo, ghi, period_tolerance, set.max_evaluations);
  rep.solution = solve_k_from(s, base, root.x, k0, set);
  rep.period = root.x;
  rep.k = rep.solution.k;
  rep.fn_min_ratio = rep.solution.fn_min_ratio;
  rep.friction_margin = rep.solution.friction_margin;
  rep.limit = friction && rep.friction_margin < rep.fn_min_ratio ? SpeedLimit::kFriction
                                                                 : SpeedLimit::kNormalForce;
  return rep;
}

}  // namespace flatland::sim
