#include "flatland/sim/simulate.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/roots.hpp"

#include "integration.hpp"
#include "rolling_run.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace flatland::sim {

std::string to_string(Method m) {
  switch (m) {
    case Method::kDormandPrince54:
      return "dopri5";
    case Method::kRungeKutta4:
      return "rk4";
    case Method::kDormandPrince853:
      return "dop853";
  }
  return "?";
}
std::string to_string(Formulation f) {
  switch (f) {
    case Formulation::kAuto:
      return "auto";
    case Formulation::kGeneral:
      return "general";
    case Formulation::kReduced:
      return "reduced";
  }
  return "?";
}
std::string to_string(StopReason r) {
  switch (r) {
    case StopReason::kEndTime:
      return "end_time";
    case StopReason::kContactLost:
      return "contact_lost";
    case StopReason::kSlip:
      return "slip";
    case StopReason::kLeftBounds:
      return "left_bounds";
    case StopReason::kDropped:
      return "dropped";
    case StopReason::kTransition:
      return "transition";
    case StopReason::kNumericalFailure:
      return "numerical_failure";
  }
  return "?";
}
std::string to_string(EventKind k) {
  switch (k) {
    case EventKind::kJunction:
      return "junction";
    case EventKind::kContactLost:
      return "contact_lost";
    case EventKind::kSlip:
      return "slip";
    case EventKind::kLeftBounds:
      return "left_bounds";
    case EventKind::kApex:
      return "apex";
    case EventKind::kLiftOff:
      return "lift_off";
    case EventKind::kSlipStart:
      return "slip_start";
    case EventKind::kSlipReverse:
      return "slip_reverse";
    case EventKind::kStick:
      return "stick";
    case EventKind::kRest:
      return "rest";
    case EventKind::kRelease:
      return "release";
    case EventKind::kImpact:
      return "impact";
    case EventKind::kDropped:
      return "dropped";
    case EventKind::kTurn:
      return "turn";
    case EventKind::kNumericalFailure:
      return "numerical_failure";
  }
  return "?";
}

Formulation resolve_formulation(const RollingProblem& problem, Formulation requested) {
  if (requested == Formulation::kAuto)
    return problem.object.disk_radius ? Formulation::kReduced : Formulation::kGeneral;
  if (requested == Formulation::kReduced && !problem.object.disk_radius)
    throw std::invalid_argument(
        "integrator.formulation: 'reduced' needs a disk object; use 'general' or 'auto' for " +
        problem.object.kind);
  return requested;
}

// ---------------------------------------------------------------------------------------------
// Trajectory

bool Trajectory::empty() const {
  for (const Part& p : parts_)
    if (!p.steps.empty() || p.closed) return false;
  return true;
}

double Trajectory::t_begin() const {
  for (const Part& p : parts_)
    if (!p.steps.empty() || p.closed) return p.t0;
  throw std::logic_error("trajectory: empty (run was not recorded)");
}

double Trajectory::t_end() const {
  for (auto it = parts_.rbegin(); it != parts_.rend(); ++it)
    if (!it->steps.empty() || it->closed) return it->t1;
  throw std::logic_error("trajectory: empty (run was not recorded)");
}

void Trajectory::begin_part(int dimension, Sampler sampler, int terms, int s_h_index) {
  Part p;
  p.n = dimension;
  p.terms = terms;
  p.s_h_index = s_h_index;
  p.sampler = std::move(sampler);
  parts_.push_back(std::move(p));
}

void Trajectory::append(double t0, double h, const Pieces& pieces, const double* coeffs) {
  if (parts_.empty() || parts_.back().closed)
    throw std::logic_error("trajectory: append without an open integrated part");
  Part& p = parts_.back();
  if (p.steps.empty()) p.t0 = t0;
  p.t1 = t0 + h;
  p.steps.push_back({t0, h, pieces});
  p.coeffs.insert(p.coeffs.end(), coeffs, coeffs + p.terms * p.n);
}

void Trajectory::add_closed_part(double t0, double t1, Closed f) {
  Part p;
  p.t0 = t0;
  p.t1 = t1;
  p.closed = std::move(f);
  parts_.push_back(std::move(p));
}

void Trajectory::drop_before(double t) {
  std::size_t keep_from = 0;
  for (std::size_t i = 0; i + 1 < parts_.size(); ++i) {
    const Part& p = parts_[i];
    if ((p.closed || !p.steps.empty()) && p.t1 > t) break;
    keep_from = i + 1;  // ends at or before t (or is empty): not needed any more
  }
  parts_.erase(parts_.begin(), parts_.begin() + static_cast<std::ptrdiff_t>(keep_from));
  if (parts_.empty() || parts_.front().closed) return;
  Part& p = parts_.front();
  std::size_t n = 0;
  while (n + 1 < p.steps.size() && p.steps[n].t0 + p.steps[n].h <= t) ++n;
  if (n == 0) return;
  p.steps.erase(p.steps.begin(), p.steps.begin() + static_cast<std::ptrdiff_t>(n));
  p.coeffs.erase(p.coeffs.begin(),
                 p.coeffs.begin() + static_cast<std::ptrdiff_t>(n * p.terms * p.n));
  p.t0 = p.steps.front().t0;
}

const Trajectory::Part& Trajectory::part_at(double t) const {
  // The last non-empty part that starts at or before t: right-continuous at the instants
  // where one part ends and the next begins (an impact changes the velocities there).
  const Part* found = nullptr;
  for (const Part& p : parts_) {
    if (p.steps.empty() && !p.closed) continue;
    if (!found || p.t0 <= t) found = &p;
    if (p.t0 > t) break;
  }
  if (!found) throw std::logic_error("trajectory: empty (run was not recorded)");
  return *found;
}

std::size_t Trajectory::Part::find(double t) const {
  auto it = std::upper_bound(steps.begin(), steps.end(), t,
                             [](double v, const Step& s) { return v < s.t0; });
  return it == steps.begin() ? 0 : static_cast<std::size_t>(it - steps.begin() - 1);
}

void Trajectory::Part::interpolate(std::size_t i, double t, double* y) const {
  const Step& s = steps[i];
  const double th = std::clamp((t - s.t0) / s.h, 0.0, 1.0), th1 = 1.0 - th;
  const double* c = coeffs.data() + static_cast<std::size_t>(terms * n) * i;
  for (int k = 0; k < n; ++k) {
    // Horner from the innermost term outwards: term j multiplies the rest by th1 (odd j) or th.
    double v = c[(terms - 1) * n + k];
    for (int j = terms - 2; j >= 1; --j) v = c[j * n + k] + (j % 2 == 1 ? th1 : th) * v;
    y[k] = c[k] + th * v;
  }
}

Sample Trajectory::sample(double t) const {
  const Part& p = part_at(t);
  const double tc = std::clamp(t, t_begin(), t_end());
  if (p.closed) return p.closed(std::clamp(tc, p.t0, p.t1));
  const std::size_t i = p.find(t);
  std::array<double, 16> y{};
  p.interpolate(i, t, y.data());
  return p.sampler(std::clamp(tc, p.t0, p.t1), y.data(), p.steps[i].pieces);
}

double Trajectory::s_h(double t) const {
  const Part& p = part_at(t);
  if (p.closed) return p.closed(std::clamp(t, p.t0, p.t1)).s_h;
  std::array<double, 16> y{};
  p.interpolate(p.find(t), t, y.data());
  return y[p.s_h_index];
}

std::vector<Sample> Trajectory::resample(double dt) const {
  if (!(dt > 0)) throw std::invalid_argument("sample interval must be positive");
  std::vector<Sample> out;
  const double t0 = t_begin(), t1 = t_end();
  const long n = static_cast<long>(std::floor((t1 - t0) / dt + 1e-9));
  for (long i = 0; i <= n; ++i) out.push_back(sample(t0 + i * dt));
  if (t0 + n * dt < t1 - 1e-12) out.push_back(sample(t1));
  return out;
}

// ---------------------------------------------------------------------------------------------

void validate_run_options(const RunOptions& o, double t0) {
  const IntegratorSettings& is = o.integrator;
  const bool rk4 = is.method == Method::kRungeKutta4;
  if (rk4 && !(is.fixed_step > 0 && std::isfinite(is.fixed_step)))
    throw std::invalid_argument("integrator.step: must be positive and finite");
  if (!rk4 &&
      (!(is.rtol > 0) || !(is.atol > 0) || !std::isfinite(is.rtol) || !std::isfinite(is.atol)))
    throw std::invalid_argument("integrator.rtol/atol: must be positive and finite");
  if (is.energy_tolerance && !(*is.energy_tolerance > 0 && std::isfinite(*is.energy_tolerance)))
    throw std::invalid_argument("integrator.energy_tolerance: must be positive and finite");
  if (!std::isfinite(t0)) throw std::invalid_argument("initial: t0 must be finite");
  if (!(o.t_end > t0) || !std::isfinite(o.t_end))
    throw std::invalid_argument("duration: the end time must be finite and after the start");
  check_fixed_step_budget(is, o.t_end - t0);
}

void require_no_numerical_failure(const RunResult& run, const std::string& what) {
  if (run.reason == StopReason::kNumericalFailure)
    throw NumericalFailure(what + ": numerical failure: " + breach_text(run.audit) +
                           " (docs/DYNAMICS.md, \"Energy audit\")");
}

void check_drag_stiffness(const RollingProblem& pb, const IntegratorSettings& is, double span) {
  // Drag relaxes the velocities at c / m (and the spin at c_w / I): an explicit Runge-Kutta step
  // is stable only below about 3 / rate (the methods' stability intervals on the negative real
  // axis: 2.8 for RK4, 3.3 for DOPRI5, 6 for DOP853), so a run needs at least rate x span / 3
  // steps, however loose its tolerance.
  const auto check = [&](const char* key, double c, double inertia, const char* unit,
                         const char* what) {
    if (!(c > 0)) return;
    const double rate = c / inertia;
    const double steps = rate * span / 3.0;
    if (steps > static_cast<double>(is.max_steps))
      throw std::invalid_argument(
          std::string("contact.") + key + ": " + format_significant(c) + " " + unit + " on " +
          format_significant(inertia) + " " + what + " relaxes in " +
          format_significant(1.0 / rate) + " s: an explicit integrator needs at least " +
          format_significant(steps, 3) + " steps over " + format_significant(span) +
          " s, beyond the step budget of " + std::to_string(is.max_steps) +
          " (an air table's film is ~0.015 N s/m per kg)");
  };
  check("drag", pb.contact.drag, pb.object.mass, "N s/m", "kg");
  check("drag_angular", pb.contact.drag_angular, pb.object.inertia, "N m s/rad", "kg m^2");
}

void check_fixed_step_budget(const IntegratorSettings& is, double span) {
  if (is.method != Method::kRungeKutta4) return;
  const double steps = std::ceil(span / is.fixed_step);
  if (steps > static_cast<double>(is.max_steps))
    throw std::invalid_argument(
        "integrator.step: " + format_significant(is.fixed_step) + " s over " +
        format_significant(span) + " s is " + format_significant(steps, 3) +
        " steps, beyond the step budget of " + std::to_string(is.max_steps) +
        " (a longer step, or a shorter duration)");
}

std::string integrator_setting_problem(const std::string& key, double v) {
  const auto range = [v](double lo, double hi, const std::string& why) -> std::string {
    if (v >= lo && v <= hi) return "";
    return "must be in [" + format_significant(lo) + ", " + format_significant(hi) + "] (" + why +
           "), got " + format_significant(v);
  };
  if (key == "rtol")
    return range(1e-14, 0.1,
                 "tighter, the error estimate is rounding noise; looser, nothing is resolved");
  if (key == "atol")
    return range(1e-18, 1.0, "absolute error of lengths in m and rates; 1e-18 is rounding");
  if (key == "energy_tolerance")
    return range(1e-12, 1.0, "relative to the energy the run moves; 1e-12 is rounding");
  if (key == "step" || key == "max_step")
    return v > 0 && std::isfinite(v)
               ? ""
               : "must be positive and finite (s), got " + format_significant(v);
  throw std::logic_error("integrator_setting_problem: unknown key " + key);
}

namespace {
bool in_contact(const Sample& s) { return s.mode != ContactMode::kFlight; }
bool needs_friction(const Sample& s) {
  return s.mode == ContactMode::kRolling || s.mode == ContactMode::kRest;
}
}  // namespace

Extrema find_extrema(const RunResult& run, double t_from, double t_to, double time_tolerance,
                     std::optional<double> mu) {
  const auto& S = run.steps;
  const Trajectory& tr = run.trajectory;
  if (S.empty() || tr.empty()) throw std::logic_error("find_extrema: the run was not recorded");
  Extrema x;
  // Step ends inside the window, plus the window's ends themselves.
  std::vector<Sample> pts;
  pts.push_back(tr.sample(t_from));
  for (const Sample& s : S)
    if (s.t > t_from && s.t < t_to) pts.push_back(s);
  pts.push_back(tr.sample(t_to));
  x.evaluations += 2;
  const std::size_t n = pts.size();
  // Extrema of the contact force over the contact modes: the normal force while in contact, the
  // friction needed while not slipping (sliding uses mu_k by definition; flight has no force).
  constexpr double kOutside = 1e300;
  auto refine = [&](std::size_t i, const std::function<double(const Sample&)>& key) {
    const double a = pts[i == 0 ? 0 : i - 1].t, b = pts[std::min(i + 1, n - 1)].t;
    const MinResult m = brent_minimize(
        [&](double tau) {
          ++x.evaluations;
          return key(tr.sample(tau));
        },
        a, b, time_tolerance * 10);
    return m.fx <= key(pts[i]) ? std::make_pair(m.x, m.fx) : std::make_pair(pts[i].t, key(pts[i]));
  };
  const auto fn_key = [](const Sample& s) { return in_contact(s) ? s.fn_ratio : kOutside; };
  const auto mu_key = [](const Sample& s) {
    return needs_friction(s) && s.force_normal > 0 ? -s.mu_required : kOutside;
  };
  std::optional<std::size_t> imin, imu;
  bool nonpositive = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (in_contact(pts[i]) && (!imin || pts[i].fn_ratio < pts[*imin].fn_ratio)) imin = i;
    if (!needs_friction(pts[i])) continue;
    if (pts[i].force_normal <= 0)
      nonpositive = true;
    else if (!imu || pts[i].mu_required > pts[*imu].mu_required)
      imu = i;
  }
  if (imin) {
    const auto fn = refine(*imin, fn_key);
    x.t_fn_min = fn.first;
    x.fn_min_ratio = fn.second;
  }
  // Rolling where the normal force is not positive needs unlimited friction.
  const bool fn_lost_while_rolling =
      imin && x.fn_min_ratio <= 0 && needs_friction(tr.sample(x.t_fn_min));
  if (nonpositive || fn_lost_while_rolling) {
    x.mu_required = std::numeric_limits<double>::infinity();
    x.t_mu_required = x.t_fn_min;
  } else if (imu) {
    const auto worst = refine(*imu, mu_key);
    x.t_mu_required = worst.first;
    x.mu_required = -worst.second;
  }
  if (mu && std::isfinite(*mu)) {
    const double m = *mu;
    const auto margin_key = [m](const Sample& s) {
      return needs_friction(s) ? m * s.fn_ratio - std::abs(s.ft_ratio) : kOutside;
    };
    std::optional<std::size_t> imargin;
    for (std::size_t i = 0; i < n; ++i)
      if (needs_friction(pts[i]) && (!imargin || margin_key(pts[i]) < margin_key(pts[*imargin])))
        imargin = i;
    if (imargin) {
      const auto margin = refine(*imargin, margin_key);
      x.t_friction_margin = margin.first;
      x.friction_margin = margin.second;
    }
  }
  return x;
}

namespace {

/// The apex in [from, to] of a recorded run (s_h rising through 0, the fingertip), if it is
/// there and none was found before: t_apex, the normal force there and its event.
void find_apex(RunResult& res, double from, double to, double time_tolerance) {
  if (res.t_apex) return;
  const auto& S = res.steps;
  const Trajectory& tr = res.trajectory;
  for (std::size_t i = 1; i < S.size() && S[i].t <= to; ++i) {
    if (S[i - 1].t < from) continue;
    if (S[i - 1].s_h < 0 && S[i].s_h >= 0 && S[i].t > S[i - 1].t) {
      const RootResult r = brent_root([&](double tau) { return tr.s_h(tau); }, S[i - 1].t, S[i].t,
                                      S[i - 1].s_h, S[i].s_h, time_tolerance);
      res.t_apex = r.x;
      res.fn_apex_ratio = tr.sample(r.x).fn_ratio;
      RecordedEvent apex;
      apex.kind = EventKind::kApex;
      apex.t = r.x;
      res.events.push_back(apex);
      return;
    }
  }
}

/// The samples at the probe times in [from, to) (to] at the run's end) not taken yet.
void take_probes(RunResult& res, const RunOptions& opt, double from, double to, bool last) {
  for (double t : opt.probe_times) {
    const bool in = t >= from && (t < to || (last && t <= to));
    const bool taken = std::any_of(res.probes.begin(), res.probes.end(),
                                   [t](const Sample& s) { return s.t == t; });
    if (in && !taken) res.probes.push_back(res.trajectory.sample(t));
  }
}

/// Fold an Extrema found over one window into the run's running ones (the smaller normal force,
/// the larger friction needed; an infinite one stays).
void fold_extrema(RunResult::Folded& f, const Extrema& x) {
  if (std::isnan(f.fn_min_ratio) || x.fn_min_ratio < f.fn_min_ratio) {
    if (!std::isnan(x.fn_min_ratio)) f.fn_min_ratio = x.fn_min_ratio, f.t_fn_min = x.t_fn_min;
  }
  if (std::isnan(f.mu_required) || x.mu_required > f.mu_required) {
    if (!std::isnan(x.mu_required))
      f.mu_required = x.mu_required, f.t_mu_required = x.t_mu_required;
  }
}

}  // namespace

namespace detail {
void fold_old_steps(RunResult& res, const RunOptions& opt) {
  if (!opt.record || opt.keep_steps <= 0) return;
  auto& S = res.steps;
  const std::size_t keep = static_cast<std::size_t>(opt.keep_steps);
  if (S.size() < 2 * keep + 2) return;
  // The oldest `keep` steps: their extrema, apex and probes, located as finish_run would, then
  // dropped (steps and dense output up to the window's end, which stays as the new front).
  const double from = S.front().t, cut = S[keep].t;
  if (cut > from) {
    const Extrema x = find_extrema(res, from, cut, opt.events.time_tolerance);
    res.stats.event_evals += x.evaluations;
    fold_extrema(res.folded, x);
    find_apex(res, from, cut, opt.events.time_tolerance);
    take_probes(res, opt, from, cut, false);
  }
  res.folded.steps += static_cast<long>(keep);
  S.erase(S.begin(), S.begin() + static_cast<std::ptrdiff_t>(keep));
  res.trajectory.drop_before(cut);
}
}  // namespace detail

void finish_run(RunResult& res, const RunOptions& opt) {
  bool flew = false;
  for (const RecordedEvent& e : res.events) flew = flew || e.kind == EventKind::kLiftOff;
  if (!opt.record || res.steps.size() < 2) {
    // A run that stopped where it started: the forces of its one state.
    const Sample& s = res.final;
    if (opt.record && res.steps.size() == 1 && s.mode != ContactMode::kFlight) {
      res.fn_min_ratio = s.fn_ratio;
      res.t_fn_min = s.t;
      res.mu_required = s.mu_required;
      res.t_mu_required = s.t;
    }
    res.contact_lost = res.reason == StopReason::kContactLost || flew;
    return;
  }
  const auto& S = res.steps;
  const Extrema x = find_extrema(res, S.front().t, S.back().t, opt.events.time_tolerance);
  res.stats.event_evals += x.evaluations;
  RunResult::Folded all = res.folded;  // the dropped steps' extrema, if any, and the kept ones'
  fold_extrema(all, x);
  res.fn_min_ratio = all.fn_min_ratio;
  res.t_fn_min = all.t_fn_min;
  res.mu_required = all.mu_required;
  res.t_mu_required = all.t_mu_required;
  find_apex(res, S.front().t, S.back().t, opt.events.time_tolerance);
  take_probes(res, opt, S.front().t, S.back().t, true);
  res.contact_lost = res.reason == StopReason::kContactLost || res.fn_min_ratio < 0 || flew;
}

RunResult simulate(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                   const RunOptions& options) {
  if (!problem) throw std::invalid_argument("simulate: no problem");
  problem->contact.validate();
  const Formulation f = resolve_formulation(*problem, options.formulation);
  if (options.model == ContactModel::kHybrid) return simulate_hybrid(problem, init, options);
  detail::require_finite(init);
  RunResult r = f == Formulation::kReduced
                    ? detail::run_rolling(ReducedDiskRolling(problem), init, options)
                    : detail::run_rolling(GeneralRolling(problem), init, options);
  r.formulation = f;
  return r;
}

}  // namespace flatland::sim
