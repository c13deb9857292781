#include "flatland/sim/simulate.hpp"

#include "flatland/sim/roots.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace flatland::sim {

std::string to_string(Method m) { return m == Method::kDormandPrince54 ? "dopri5" : "rk4"; }
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

void Trajectory::append(double t0, double h, const Pieces& p, const double* coeffs) {
  steps_.push_back({t0, h, p});
  coeffs_.insert(coeffs_.end(), coeffs, coeffs + 5 * n_);
}

std::size_t Trajectory::find(double t) const {
  if (steps_.empty()) throw std::logic_error("trajectory: empty (run was not recorded)");
  auto it = std::upper_bound(steps_.begin(), steps_.end(), t,
                             [](double v, const Step& s) { return v < s.t0; });
  return it == steps_.begin() ? 0 : static_cast<std::size_t>(it - steps_.begin() - 1);
}

void Trajectory::interpolate(std::size_t i, double t, double* y) const {
  const Step& s = steps_[i];
  const double th = std::clamp((t - s.t0) / s.h, 0.0, 1.0), th1 = 1.0 - th;
  const double* c = coeffs_.data() + 5 * n_ * i;
  for (int k = 0; k < n_; ++k)
    y[k] = c[k] +
           th * (c[n_ + k] + th1 * (c[2 * n_ + k] + th * (c[3 * n_ + k] + th1 * c[4 * n_ + k])));
}

Sample Trajectory::sample(double t) const {
  const std::size_t i = find(t);
  std::array<double, 16> y{};
  interpolate(i, t, y.data());
  return sampler_(std::clamp(t, t_begin(), t_end()), y.data(), steps_[i].pieces);
}

double Trajectory::s_h(double t) const {
  std::array<double, 16> y{};
  interpolate(find(t), t, y.data());
  return y[s_h_index_];
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
namespace {

// Dormand-Prince 5(4) tableau (Hairer, Norsett, Wanner: DOPRI5).
constexpr double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
constexpr double a21 = 1.0 / 5;
constexpr double a31 = 3.0 / 40, a32 = 9.0 / 40;
constexpr double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
constexpr double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                 a54 = -212.0 / 729;
constexpr double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247, a64 = 49.0 / 176,
                 a65 = -5103.0 / 18656;
constexpr double a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192, a75 = -2187.0 / 6784,
                 a76 = 11.0 / 84;
constexpr double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920, e5 = -17253.0 / 339200,
                 e6 = 22.0 / 525, e7 = -1.0 / 40;
constexpr double d1 = -12715105075.0 / 11282082432, d3 = 87487479700.0 / 32700410799,
                 d4 = -10690763975.0 / 1880347072, d5 = 701980252875.0 / 199316789632,
                 d6 = -1453857185.0 / 822651844, d7 = 69997945.0 / 29380423;

std::string at_text(double t, double s_h) {
  std::ostringstream os;
  os.precision(10);
  os << "at t=" << t << " s (s_h=" << s_h << ")";
  return os.str();
}

template <class Model>
class Integration {
 public:
  using State = typename Model::State;
  static constexpr int N = Model::N;
  using Dense = std::array<State, 5>;

  Integration(const Model& model, const RunOptions& opt, RunResult& res)
      : model_(model), opt_(opt), res_(res), st_(res.stats) {}

  void run(const InitialContact& init);

 private:
  void rhs(double t, const State& y, State& dy) {
    model_.derivative(t, y, pieces_, dy);
    ++st_.rhs_evals;
  }
  double attempt(double t, const State& y, const State& k1, double h, State& y1, State& k7,
                 Dense& rc);
  double initial_step(double t, const State& y, const State& f0, double t_stop);
  Sample sample(double t, const State& y) {
    ++st_.event_evals;
    return model_.sample(t, y, pieces_);
  }
  void record(double t, const State& y, const Sample* s);
  void finish();

  const Model& model_;
  const RunOptions& opt_;
  RunResult& res_;
  RunStats& st_;
  Pieces pieces_;
};

template <class Model>
double Integration<Model>::attempt(double t, const State& y, const State& k1, double h, State& y1,
                                   State& k7, Dense& rc) {
  if (opt_.integrator.method == Method::kRungeKutta4) {
    State k2, k3, k4;
    rhs(t + 0.5 * h, y + 0.5 * h * k1, k2);
    rhs(t + 0.5 * h, y + 0.5 * h * k2, k3);
    rhs(t + h, y + h * k3, k4);
    y1 = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    rhs(t + h, y1, k7);  // reused as the next step's k1; gives the Hermite dense output
    rc[0] = y;
    rc[1] = y1 - y;
    rc[2] = h * k1 - rc[1];
    rc[3] = rc[1] - h * k7 - rc[2];
    rc[4].setZero();
    return 0.0;
  }
  State k2, k3, k4, k5, k6;
  rhs(t + c2 * h, y + h * (a21 * k1), k2);
  rhs(t + c3 * h, y + h * (a31 * k1 + a32 * k2), k3);
  rhs(t + c4 * h, y + h * (a41 * k1 + a42 * k2 + a43 * k3), k4);
  rhs(t + c5 * h, y + h * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4), k5);
  rhs(t + h, y + h * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5), k6);
  y1 = y + h * (a71 * k1 + a73 * k3 + a74 * k4 + a75 * k5 + a76 * k6);
  rhs(t + h, y1, k7);
  const State err = h * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  double sum = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::max(std::abs(y[i]), std::abs(y1[i]));
    sum += (err[i] / sk) * (err[i] / sk);
  }
  rc[0] = y;
  rc[1] = y1 - y;
  rc[2] = h * k1 - rc[1];
  rc[3] = rc[1] - h * k7 - rc[2];
  rc[4] = h * (d1 * k1 + d3 * k3 + d4 * k4 + d5 * k5 + d6 * k6 + d7 * k7);
  const double e = std::sqrt(sum / N);
  return std::isfinite(e) && y1.allFinite() ? e : std::numeric_limits<double>::infinity();
}

// Hairer's starting step size heuristic.
template <class Model>
double Integration<Model>::initial_step(double t, const State& y, const State& f0, double t_stop) {
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  double dnf = 0, dny = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    dnf += (f0[i] / sk) * (f0[i] / sk);
    dny += (y[i] / sk) * (y[i] / sk);
  }
  double h = (dnf <= 1e-10 || dny <= 1e-10) ? 1e-6 : std::sqrt(dny / dnf) * 0.01;
  h = std::min({h, opt_.integrator.max_step, t_stop - t});
  State f1;
  rhs(t + h, y + h * f0, f1);
  double der2 = 0;
  for (int i = 0; i < N; ++i) {
    const double sk = atol + rtol * std::abs(y[i]);
    der2 += ((f1[i] - f0[i]) / sk) * ((f1[i] - f0[i]) / sk);
  }
  der2 = std::sqrt(der2) / h;
  const double der12 = std::max(std::abs(der2), std::sqrt(dnf));
  const double h1 = der12 <= 1e-15 ? std::max(1e-6, h * 1e-3) : std::pow(0.01 / der12, 0.2);
  return std::min({100 * h, h1, opt_.integrator.max_step});
}

template <class Model>
void Integration<Model>::record(double t, const State& y, const Sample* s) {
  if (!opt_.record) return;
  res_.steps.push_back(s ? *s : sample(t, y));
}

template <class Model>
void Integration<Model>::run(const InitialContact& init) {
  const IntegratorSettings& is = opt_.integrator;
  const EventSettings& ev = opt_.events;
  const bool rk4 = is.method == Method::kRungeKutta4;
  if (rk4 && !(is.fixed_step > 0 && std::isfinite(is.fixed_step)))
    throw std::invalid_argument("integrator.step: must be positive and finite");
  if (!rk4 &&
      (!(is.rtol > 0) || !(is.atol > 0) || !std::isfinite(is.rtol) || !std::isfinite(is.atol)))
    throw std::invalid_argument("integrator.rtol/atol: must be positive and finite");
  if (!std::isfinite(init.s_h) || !std::isfinite(init.sdot_h) || !std::isfinite(init.t0))
    throw std::invalid_argument("initial: s_h, sdot_h and t0 must be finite");
  if (!(opt_.t_end > init.t0) || !std::isfinite(opt_.t_end))
    throw std::invalid_argument("duration: the end time must be finite and after the start");
  if (ev.mu && !(*ev.mu >= 0)) throw std::invalid_argument("contact.mu: must be >= 0");

  double t = init.t0;
  State y = model_.initial_state(init);
  // Direction of travel decides which piece is active when starting on a junction; at rest the
  // initial acceleration decides.
  int dir = model_.sdot_h(y) < 0 ? -1 : +1;
  const int motion_segment = model_.problem().motion->segment_at(t);
  if (model_.sdot_h(y) == 0) {
    pieces_ = model_.pieces_for(y, +1);
    pieces_.motion = motion_segment;
    State dy;
    rhs(t, y, dy);
    const double sdd = model_.sdot_h(dy);  // the rate slot of the derivative holds sddot_h
    dir = sdd < 0 ? -1 : +1;
  }
  pieces_ = model_.pieces_for(y, dir);
  pieces_.motion = motion_segment;
  model_.project(t, y, pieces_);

  if (opt_.record) {
    res_.trajectory = Trajectory(N, [m = model_](double tt, const double* yy, const Pieces& p) {
      State s = Eigen::Map<const State>(yy);
      m.project(tt, s, p);
      return m.sample(tt, s, p);
    });
    res_.trajectory.set_s_h_index(N == 3 ? 0 : 4);
  }
  res_.initial = sample(t, y);
  record(t, y, &res_.initial);
  if (ev.stop_on_contact_loss && res_.initial.force_normal < 0) {
    res_.reason = StopReason::kContactLost;
    res_.events.push_back({"contact_lost", t, model_.s_h(y)});
    res_.final = res_.initial;
    finish();
    return;
  }

  std::vector<double> stops;
  for (double b : model_.problem().motion->breakpoints())
    if (b > t && b < opt_.t_end) stops.push_back(b);
  std::sort(stops.begin(), stops.end());
  stops.push_back(opt_.t_end);

  State k1, y1, k7;
  Dense rc;
  bool need_k1 = true;
  double h = rk4 ? is.fixed_step : 0.0;
  double facold = 1e-4;  // PI step-size controller memory
  bool stopped = false;
  int zero_progress = 0;
  const bool need_force = ev.stop_on_contact_loss || ev.mu.has_value();

  for (double t_stop : stops) {
    while (t < t_stop && !stopped) {
      if (need_k1) {
        rhs(t, y, k1);
        need_k1 = false;
        if (!rk4 && h == 0.0) h = initial_step(t, y, k1, t_stop);
      }
      double h_try = rk4 ? is.fixed_step : std::min(h, is.max_step);
      if (t + 1.01 * h_try >= t_stop) h_try = t_stop - t;  // land exactly on the stop
      if (st_.steps + st_.rejected >= is.max_steps)
        throw std::runtime_error("integrator: step budget (" + std::to_string(is.max_steps) +
                                 ") exhausted " + at_text(t, model_.s_h(y)));
      const double err = attempt(t, y, k1, h_try, y1, k7, rc);
      if (!rk4 && err > 1.0) {
        ++st_.rejected;
        h = h_try * (std::isfinite(err) ? std::max(0.2, 0.9 * std::pow(err, -0.2)) : 0.1);
        if (h < 1e-14 * std::max(1.0, std::abs(t)))
          throw std::runtime_error("integrator: step size underflow " + at_text(t, model_.s_h(y)) +
                                   " (singular or non-finite dynamics)");
        continue;
      }
      if (!y1.allFinite())
        throw std::runtime_error("integrator: non-finite state " + at_text(t, model_.s_h(y)) +
                                 " (reduce integrator.step)");
      double t1 = (h_try == t_stop - t) ? t_stop : t + h_try;
      State y1p = y1;
      double drift = model_.project(t1, y1p, pieces_);

      // ---- events on (t, t1] ----
      const PieceInterval iv = model_.problem().hand->piece_interval(pieces_.hand);
      const double s1 = model_.s_h(y1p);
      enum Kind { kNone, kJunction, kContact, kSlip, kBounds } kind = kNone;
      double t_event = t1, junction = 0;
      // Events are located on the integrator's own step map, h -> step(y, h), rather than on the
      // dense output: the step that then ends on the event lands on it by construction (a coarse
      // fixed step's Hermite interpolant can be far off), and g(h_try) is exactly g1.
      const double h_full = h_try;
      auto step_state = [&](double hh) {
        State out, k7_unused;
        Dense rc_unused;
        attempt(t, y, k1, hh, out, k7_unused, rc_unused);
        model_.project(t + hh, out, pieces_);
        return out;
      };
      auto locate = [&](const std::function<double(const State&, double)>& g, double g0,
                        double g1) {
        return t + brent_root([&](double hh) { return g(step_state(hh), t + hh); }, 0.0, h_full, g0,
                              g1, ev.time_tolerance)
                       .x;
      };
      if (s1 > iv.hi || s1 < iv.lo) {
        junction = s1 > iv.hi ? iv.hi : iv.lo;
        const double g0 = model_.s_h(y) - junction, g1 = s1 - junction;
        // A previous crossing may have landed a rounding error short of its junction; if the
        // disk turns back right there, it is already across at the start of this step.
        const double tj =
            (g0 > 0) == (g1 > 0) || g0 == 0
                ? t
                : locate([&](const State& s, double) { return model_.s_h(s) - junction; }, g0, g1);
        if (tj < t_event || kind == kNone) t_event = tj, kind = kJunction;
      }
      if (ev.s_h_bounds && (s1 < ev.s_h_bounds->first || s1 > ev.s_h_bounds->second)) {
        const double bound =
            s1 < ev.s_h_bounds->first ? ev.s_h_bounds->first : ev.s_h_bounds->second;
        const double g0 = model_.s_h(y) - bound, g1 = s1 - bound;
        const double tb =
            (g0 > 0) == (g1 > 0) || g0 == 0
                ? t
                : locate([&](const State& s, double) { return model_.s_h(s) - bound; }, g0, g1);
        if (tb < t_event || kind == kNone) t_event = tb, kind = kBounds;
      }
      Sample s_end;
      bool have_end = false;
      if (need_force) {
        s_end = sample(t1, y1p);
        have_end = true;
        const Sample s0 = res_.steps.empty() || !opt_.record ? sample(t, y) : res_.steps.back();
        if (ev.stop_on_contact_loss && s_end.force_normal < 0 && s0.force_normal >= 0) {
          const double tc =
              locate([&](const State& s, double tau) { return sample(tau, s).force_normal; },
                     s0.force_normal, s_end.force_normal);
          if (tc < t_event || kind == kNone) t_event = tc, kind = kContact;
        }
        if (ev.mu) {
          auto slip_margin = [&](const Sample& s) {
            return *ev.mu * s.force_normal - std::abs(s.force_tangential);
          };
          if (slip_margin(s_end) < 0 && slip_margin(s0) >= 0) {
            const double ts =
                locate([&](const State& s, double tau) { return slip_margin(sample(tau, s)); },
                       slip_margin(s0), slip_margin(s_end));
            if (ts < t_event || kind == kNone) t_event = ts, kind = kSlip;
          }
        }
      }
      if (kind != kNone) {
        // Guard against chattering: events that keep firing without time advancing.
        zero_progress = t_event <= t ? zero_progress + 1 : 0;
        if (zero_progress > 8)
          throw std::runtime_error("integrator: events repeat without progress " +
                                   at_text(t, model_.s_h(y)) + " (chattering at a junction)");
      }
      if (kind != kNone && t_event < t1) {
        // Stop exactly at the event: redo the step up to it, so no step straddles it.
        h_try = t_event - t;
        if (h_try > 0) {
          attempt(t, y, k1, h_try, y1, k7, rc);
          t1 = t_event;
          y1p = y1;
          drift = model_.project(t1, y1p, pieces_);
        } else {
          y1p = y;
          t1 = t;
        }
        have_end = false;
      }

      // ---- accept ----
      if (h_try > 0) {
        ++st_.steps;
        st_.max_drift = std::max(st_.max_drift, drift);
        if (opt_.record) {
          std::array<double, 5 * N> c;
          for (int j = 0; j < 5; ++j) Eigen::Map<State>(c.data() + j * N) = rc[j];
          res_.trajectory.append(t, h_try, pieces_, c.data());
        }
        const bool moved = drift > 0 && N != 3;
        t = t1;
        y = y1p;
        if (moved)
          need_k1 = true;
        else
          k1 = k7;
        if (opt_.record || kind != kNone) {
          const Sample s = have_end ? s_end : sample(t, y);
          st_.max_constraint_residual =
              std::max(st_.max_constraint_residual, s.constraint_residual);
          st_.max_redundant_residual = std::max(st_.max_redundant_residual, s.redundant_residual);
          record(t, y, &s);
        }
      }
      if (!rk4 && kind == kNone) {
        // PI step-size control (Hairer's DOPRI5 constants).
        const double fac11 = std::pow(std::max(err, 1e-16), 0.17);
        const double fac = std::clamp(fac11 / std::pow(facold, 0.04) / 0.9, 0.1, 5.0);
        facold = std::max(err, 1e-4);
        h = h_try / fac;
      }
      switch (kind) {
        case kNone:
          break;
        case kJunction: {
          ++st_.junction_crossings;
          ++st_.restarts;
          res_.events.push_back({"junction", t, model_.s_h(y)});
          // The landing point may sit a rounding error short of the junction: pick the next
          // piece from the junction itself and the direction of crossing.
          const int d = junction == iv.hi ? +1 : -1;
          const int motion = pieces_.motion;
          pieces_ = model_.pieces_for(y, d);
          pieces_.hand = model_.problem().hand->piece_at(junction, d);
          pieces_.motion = motion;
          need_k1 = true;
          break;
        }
        case kContact:
          res_.reason = StopReason::kContactLost;
          res_.events.push_back({"contact_lost", t, model_.s_h(y)});
          stopped = true;
          break;
        case kSlip:
          res_.reason = StopReason::kSlip;
          res_.events.push_back({"slip", t, model_.s_h(y)});
          stopped = true;
          break;
        case kBounds:
          res_.reason = StopReason::kLeftBounds;
          res_.events.push_back({"left_bounds", t, model_.s_h(y)});
          stopped = true;
          break;
      }
    }
    if (stopped) break;
    if (t_stop < opt_.t_end) {  // the motion's acceleration jumps here: restart on its next segment
      ++st_.restarts;
      ++pieces_.motion;
      need_k1 = true;
    }
  }
  res_.final = (opt_.record && !res_.steps.empty()) ? res_.steps.back() : sample(t, y);
  finish();
}

template <class Model>
void Integration<Model>::finish() {
  if (!opt_.record || res_.steps.size() < 2) {
    res_.contact_lost = res_.reason == StopReason::kContactLost;
    return;
  }
  const auto& S = res_.steps;
  const Trajectory& tr = res_.trajectory;
  const std::size_t n = S.size();
  const Extrema x = find_extrema(res_, S.front().t, S.back().t, opt_.events.time_tolerance);
  st_.event_evals += x.evaluations;
  res_.fn_min_ratio = x.fn_min_ratio;
  res_.t_fn_min = x.t_fn_min;
  res_.mu_required = x.mu_required;
  res_.t_mu_required = x.t_mu_required;
  for (std::size_t i = 1; i < n; ++i) {
    if (S[i - 1].s_h < 0 && S[i].s_h >= 0) {
      const RootResult r = brent_root([&](double tau) { return tr.s_h(tau); }, S[i - 1].t, S[i].t,
                                      S[i - 1].s_h, S[i].s_h, opt_.events.time_tolerance);
      res_.t_apex = r.x;
      res_.fn_apex_ratio = tr.sample(r.x).fn_ratio;
      res_.events.push_back({"apex", r.x, 0.0});
      break;
    }
  }
  res_.contact_lost = res_.reason == StopReason::kContactLost || res_.fn_min_ratio < 0;
}

}  // namespace

Extrema find_extrema(const RunResult& run, double t_from, double t_to, double time_tolerance) {
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
  std::size_t imin = 0, imu = 0;
  bool nonpositive = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (pts[i].fn_ratio < pts[imin].fn_ratio) imin = i;
    if (pts[i].force_normal <= 0)
      nonpositive = true;
    else if (pts[i].mu_required > pts[imu].mu_required)
      imu = i;
  }
  const auto fn = refine(imin, [](const Sample& s) { return s.fn_ratio; });
  x.t_fn_min = fn.first;
  x.fn_min_ratio = fn.second;
  if (nonpositive || x.fn_min_ratio <= 0) {
    x.mu_required = std::numeric_limits<double>::infinity();
    x.t_mu_required = x.t_fn_min;
  } else {
    const auto mu = refine(imu, [](const Sample& s) { return -s.mu_required; });
    x.t_mu_required = mu.first;
    x.mu_required = -mu.second;
  }
  return x;
}

namespace {

template <class Model>
RunResult run_with(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                   const RunOptions& options) {
  RunResult res;
  res.method = options.integrator.method;
  Model model(std::move(problem));
  Integration<Model> integration(model, options, res);
  integration.run(init);
  return res;
}

}  // namespace

RunResult simulate(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                   const RunOptions& options) {
  if (!problem) throw std::invalid_argument("simulate: no problem");
  const Formulation f = resolve_formulation(*problem, options.formulation);
  RunResult r = f == Formulation::kReduced
                    ? run_with<ReducedDiskRolling>(std::move(problem), init, options)
                    : run_with<GeneralRolling>(std::move(problem), init, options);
  r.formulation = f;
  return r;
}

}  // namespace flatland::sim
