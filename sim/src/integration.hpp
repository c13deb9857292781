// The integrators (Dormand-Prince 5(4) and 8(5,3), classical RK4) with event location, shared by
// the rolling model's simulate() and the hybrid model's segments (sim/src/hybrid.cpp). Internal
// to sim/.
//
// One Integration runs one formulation (a Model: ReducedDiskRolling, ReducedDiskSliding,
// GeneralRolling in some phase) from a state until the end time or the first guard event. It
// keeps the active hand piece fixed over a segment and restarts at located junction crossings and
// at the motion's breakpoints (where the hand's acceleration jumps: the guards are evaluated there
// at once, so a violation caused by the jump is an event at that instant).
//
// Beside the model's state it integrates the work done on the object (the hand's and the
// losses', two more components left out of the error norm) for the run's energy audit, and
// compares the balance with its bound wherever a sample exists (every step when recording or
// when guards need the forces, else at the segment's end): a breach ends the segment with
// EventKind::kNumericalFailure.
#pragma once

#include "energy_ledger.hpp"
#include "flatland/sim/roots.hpp"
#include "flatland/sim/simulate.hpp"
#include "runge_kutta.hpp"
#include "step_budget.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::sim::detail {

inline std::string at_text(double t, double s_h) {
  std::ostringstream os;
  os.precision(10);
  os << "at t=" << t << " s (s_h=" << s_h << ")";
  return os.str();
}

/// With options.keep_steps, fold the oldest recorded steps into the run's extrema, apex and
/// probes and drop them (simulate.cpp), so that a recorded run's memory stays bounded.
void fold_old_steps(RunResult& res, const RunOptions& opt);

/// The energy ledger of a planar run (its audit in `audit`): the tolerance from the options, the
/// floor of the energy scale m g times the object's size.
inline EnergyLedger planar_ledger(EnergyAudit& audit, const RollingProblem& pb,
                                  const RunOptions& o) {
  const IntegratorSettings& is = o.integrator;
  const double size =
      pb.object.boundary ? pb.object.boundary->reach() : pb.object.disk_radius.value_or(0.0);
  return EnergyLedger(
      audit, energy_tolerance(is.energy_tolerance, is.method == Method::kRungeKutta4, is.rtol),
      pb.object.mass * pb.gravity * size);
}

/// A condition that must hold over a segment: it fires where `value` goes from >= 0 to < 0. At
/// the start of a segment (and right after a motion breakpoint) a value below -tolerance fires at
/// once; a value within the tolerance is taken as the boundary the segment starts on.
struct Guard {
  EventKind kind;
  std::function<double(const Sample&)> value;
  double tolerance = 0;
};

/// Where a segment ended.
template <class State>
struct SegmentEnd {
  double t = 0;
  State y;
  Pieces pieces;
  std::optional<EventKind> fired;  ///< a guard (or kLeftBounds) ended it; none: the end time
  Sample first;                    ///< the sample at the start
  Sample last;                     ///< the sample at the end
};

/// `kAudited`: integrate the works and check the energy balance (every run but a search's
/// bracketing probes, RunOptions::audit).
template <class Model, bool kAudited = true>
class Integration {
 public:
  using State = typename Model::State;
  static constexpr int N = Model::N;
  /// The state and, at N and N + 1, the work done on the object since the segment began by the
  /// hand and by the losses, J.
  static constexpr int kWorks = kAudited ? 2 : 0;
  using Y = Eigen::Matrix<double, N + kWorks, 1>;
  using Dense = DenseCoefficients<Y>;  // 5 used unless dop853
  /// The leading components of the state that the step-size control measures: all of the model's
  /// state, unless the model says fewer (Model::controlled(), e.g. a state with sensitivities
  /// beside it that may leave them out).
  int controlled_components() const {
    if constexpr (requires { model_.controlled(); })
      return model_.controlled();
    else
      return N;
  }

  /// `run_start`: where the whole run (all its segments) began, for the step budget's forecast.
  Integration(const Model& model, const RunOptions& opt, RunResult& res, std::vector<Guard> guards,
              EnergyLedger& ledger, double run_start)
      : model_(model),
        opt_(opt),
        res_(res),
        st_(res.stats),
        guards_(std::move(guards)),
        ledger_(ledger),
        run_start_(run_start) {}

  /// Integrate from (t, y) on `pieces` (y on the contact manifold) to opt.t_end, or to the first
  /// guard event, junction crossings and motion breakpoints included. When recording, the start
  /// sample and every step are appended to the run, in a new part of its trajectory.
  SegmentEnd<State> run_from(double t, State y, Pieces pieces);

  /// The sample at (t, y) on the active pieces (counted as an event evaluation).
  Sample sample(double t, const State& y) {
    ++st_.event_evals;
    return model_.sample(t, y, pieces_);
  }
  void set_pieces(const Pieces& p) { pieces_ = p; }

 private:
  static State head(const Y& y) { return y.template head<N>(); }
  /// After a switch of pieces at t (a junction, a motion breakpoint): a model whose state carries
  /// sensitivities applies their jump there (its `cross`); the others' states are continuous.
  void cross(double t, Y& y, const Pieces& before) {
    if constexpr (requires(State & x) { model_.cross(t, x, before, pieces_); }) {
      State x = head(y);
      model_.cross(t, x, before, pieces_);
      y.template head<N>() = x;
    }
  }
  Sample sample_at(double t, const Y& y) { return sample(t, State(head(y))); }
  double s_h(const Y& y) const { return Model::s_h(head(y)); }
  /// The model's projection of the state part (the works are not constrained).
  double project(double t, Y& y) const {
    State s = head(y);
    const double drift = model_.project(t, s, pieces_);
    y.template head<N>() = s;
    return drift;
  }
  void rhs(double t, const Y& y, Y& dy) {
    if constexpr (kAudited) {
      State d;
      Power power;
      model_.derivative(t, head(y), pieces_, d, &power);
      dy.template head<N>() = d;
      dy[N] = power.hand;
      dy[N + 1] = power.losses;
    } else {
      model_.derivative(t, y, pieces_, dy);
    }
    ++st_.rhs_evals;
  }
  /// One step of size h from (t, y) with k1 = f(t, y): y1, k7 = f(t + h, y1) and the scaled
  /// error norm (0 for RK4), and the dense output in `rc` except for DOP853, whose three extra
  /// stages are paid only for accepted recorded steps (dop853_dense on k853_). `trial` steps
  /// (event location on the step map) keep DOP853's stages out of the step's own (k853_).
  double attempt(double t, const Y& y, const Y& k1, double h, Y& y1, Y& k7, Dense& rc,
                 bool trial = false);
  double initial_step(double t, const Y& y, const Y& f0, double t_stop);
  void record(double t, const State& y, const Sample* s);
  /// The energy balance at a sample; false when it broke.
  bool audit(const Sample& s) {
    if constexpr (!kAudited) return true;
    const double kinetic = kinetic_energy(model_.problem(), s);
    return ledger_.check(s.t,
                         kinetic - model_.problem().object.mass *
                                       model_.problem().gravity_vector().dot(s.object_position),
                         kinetic);
  }
  /// The first guard violated at a segment's start (beyond its tolerance).
  std::optional<EventKind> violated(const Sample& s) const {
    for (const Guard& g : guards_)
      if (g.value(s) < -g.tolerance) return g.kind;
    return std::nullopt;
  }

  const Model& model_;
  const RunOptions& opt_;
  RunResult& res_;
  RunStats& st_;
  std::vector<Guard> guards_;
  EnergyLedger& ledger_;
  double run_start_;
  Pieces pieces_;
  Stages853<Y> k853_;
};

template <class Model, bool kAudited>
double Integration<Model, kAudited>::attempt(double t, const Y& y, const Y& k1, double h, Y& y1,
                                             Y& k7, Dense& rc, bool trial) {
  const auto f = [this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); };
  const double rtol = opt_.integrator.rtol, atol = opt_.integrator.atol;
  if (opt_.integrator.method == Method::kDormandPrince853) {
    if (!trial)
      return dop853_step(f, t, y, k1, h, rtol, atol, y1, k7, k853_, controlled_components());
    Stages853<Y> scratch;
    return dop853_step(f, t, y, k1, h, rtol, atol, y1, k7, scratch, controlled_components());
  }
  if (opt_.integrator.method == Method::kRungeKutta4) {
    rk4_step(f, t, y, k1, h, y1, k7, rc);  // k7 is reused as the next step's k1
    return 0.0;
  }
  return dopri5_step(f, t, y, k1, h, rtol, atol, y1, k7, rc, controlled_components());
}

template <class Model, bool kAudited>
double Integration<Model, kAudited>::initial_step(double t, const Y& y, const Y& f0,
                                                  double t_stop) {
  return starting_step([this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); }, t, y, f0, t_stop,
                       opt_.integrator.rtol, opt_.integrator.atol, opt_.integrator.max_step,
                       opt_.integrator.method == Method::kDormandPrince853 ? 8.0 : 5.0,
                       controlled_components());
}

template <class Model, bool kAudited>
void Integration<Model, kAudited>::record(double t, const State& y, const Sample* s) {
  if (!opt_.record) return;
  res_.steps.push_back(s ? *s : sample(t, y));
  fold_old_steps(res_, opt_);
}

template <class Model, bool kAudited>
SegmentEnd<typename Model::State> Integration<Model, kAudited>::run_from(double t, State y_start,
                                                                         Pieces pieces) {
  const IntegratorSettings& is = opt_.integrator;
  const EventSettings& ev = opt_.events;
  const bool rk4 = is.method == Method::kRungeKutta4;
  const bool dop853 = is.method == Method::kDormandPrince853;
  const int terms = dop853 ? 8 : 5;
  pieces_ = pieces;
  SegmentEnd<State> end;
  Y y;
  if constexpr (kAudited)
    y << y_start, 0.0, 0.0;  // the works start from zero in every segment
  else
    y = y_start;

  if (opt_.record) {
    res_.trajectory.begin_part(
        N,
        [m = model_](double tt, const double* yy, const Pieces& p) {
          State s = Eigen::Map<const State>(yy);
          m.project(tt, s, p);
          return m.sample(tt, s, p);
        },
        terms, N == 10 ? 4 : 0);
  }
  Sample s_start = sample_at(t, y);
  end.first = s_start;
  record(t, head(y), &s_start);
  if constexpr (kAudited)
    ledger_.start(mechanical_energy(model_.problem(), s_start),
                  kinetic_energy(model_.problem(), s_start));
  const auto stop_now = [&](EventKind kind, const Sample& s) {
    end.t = t;
    end.y = head(y);
    end.pieces = pieces_;
    end.fired = kind;
    end.last = s;
    return end;
  };
  // The balance at the segment's start: a jump between segments (a change of mode, an impact)
  // shows here.
  if (!audit(s_start)) return stop_now(EventKind::kNumericalFailure, s_start);
  if (auto kind = violated(s_start)) return stop_now(*kind, s_start);

  std::vector<double> stops;
  for (double b : model_.problem().motion->breakpoints())
    if (b > t && b < opt_.t_end) stops.push_back(b);
  std::sort(stops.begin(), stops.end());
  stops.push_back(opt_.t_end);

  Y k1, y1, k7;
  Dense rc;
  bool need_k1 = true;
  double h = rk4 ? is.fixed_step : 0.0;
  double facold = 1e-4;  // PI step-size controller memory
  bool last_rejected = false;
  std::optional<EventKind> stopped;
  int zero_progress = 0;
  const bool need_force = !guards_.empty();

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
                                 ") exhausted " + at_text(t, s_h(y)));
      forecast_step_budget(st_.steps + st_.rejected, is.max_steps, run_start_, t, opt_.t_end);
      const double err = attempt(t, y, k1, h_try, y1, k7, rc);
      if (!rk4 && err > 1.0) {
        ++st_.rejected;
        last_rejected = true;
        h = h_try * (!std::isfinite(err) ? 0.1
                     : dop853            ? std::max(1.0 / 3.0, 0.9 * std::pow(err, -1.0 / 8.0))
                                         : std::max(0.2, 0.9 * std::pow(err, -0.2)));
        if (!(h >= 1e-14 * std::max(1.0, std::abs(t))))  // NaN too
          throw std::runtime_error("integrator: step size underflow " + at_text(t, s_h(y)) +
                                   " (singular or non-finite dynamics)");
        continue;
      }
      if (!y1.allFinite())
        throw std::runtime_error("integrator: non-finite state " + at_text(t, s_h(y)) +
                                 " (reduce integrator.step)");
      double t1 = (h_try == t_stop - t) ? t_stop : t + h_try;
      Y y1p = y1;
      double drift = project(t1, y1p);

      // ---- events on (t, t1] ----
      const PieceInterval iv = model_.problem().hand->piece_interval(pieces_.hand);
      const double s1 = s_h(y1p);
      enum Kind { kNone, kJunction, kGuard, kBounds } kind = kNone;
      EventKind guard_kind = EventKind::kLeftBounds;
      double t_event = t1, junction = 0;
      // Events are located on the integrator's own step map, h -> step(y, h), rather than on the
      // dense output: the step that then ends on the event lands on it by construction (a coarse
      // fixed step's Hermite interpolant can be far off), and g(h_try) is exactly g1.
      const double h_full = h_try;
      auto step_state = [&](double hh) {
        Y out, k7_unused;
        Dense rc_unused;
        attempt(t, y, k1, hh, out, k7_unused, rc_unused, true);
        project(t + hh, out);
        return out;
      };
      auto locate = [&](const std::function<double(const Y&, double)>& g, double g0, double g1,
                        double from = 0.0) {
        return t + brent_root([&](double hh) { return g(step_state(hh), t + hh); }, from, h_full,
                              g0, g1, ev.time_tolerance)
                       .x;
      };
      if (s1 > iv.hi || s1 < iv.lo) {
        junction = s1 > iv.hi ? iv.hi : iv.lo;
        const double g0 = s_h(y) - junction, g1 = s1 - junction;
        // A previous crossing may have landed a rounding error short of its junction; if the
        // disk turns back right there, it is already across at the start of this step.
        const double tj =
            (g0 > 0) == (g1 > 0) || g0 == 0
                ? t
                : locate([&](const Y& s, double) { return s_h(s) - junction; }, g0, g1);
        if (tj < t_event || kind == kNone) t_event = tj, kind = kJunction;
      }
      if (ev.s_h_bounds && (s1 < ev.s_h_bounds->first || s1 > ev.s_h_bounds->second)) {
        const double bound =
            s1 < ev.s_h_bounds->first ? ev.s_h_bounds->first : ev.s_h_bounds->second;
        const double g0 = s_h(y) - bound, g1 = s1 - bound;
        const double tb = (g0 > 0) == (g1 > 0) || g0 == 0
                              ? t
                              : locate([&](const Y& s, double) { return s_h(s) - bound; }, g0, g1);
        if (tb < t_event || kind == kNone) t_event = tb, kind = kBounds;
      }
      Sample s_end;
      bool have_end = false;
      if (need_force) {
        s_end = sample_at(t1, y1p);
        have_end = true;
        for (const Guard& gd : guards_) {
          const double g0 = gd.value(s_start), g1 = gd.value(s_end);
          if (!(g1 < 0)) continue;
          const auto value = [&](const Y& s, double tau) { return gd.value(sample_at(tau, s)); };
          double tg = t;
          if (g0 > 0) {
            tg = locate(value, g0, g1);
          } else {
            // The guard starts on its boundary (exactly 0: a segment starts where its mode was
            // entered, a slip at zero slip velocity, a rolling at sdot_h = 0) or a rounding error
            // on the wrong side of one it was meant to leave (within the tolerance). If the value
            // stays below zero, the guard holds no longer: it fires at the start. But it may rise
            // first and come back within the step (a slip that grows and dies out, a rolling
            // that turns back), and then the fall is the event: fired at the start instead, the
            // transition found the mode it left still wanted and the segment started again at
            // the same instant, over and over. The step map is probed at h/2, h/4, ... down to
            // the time tolerance for a value above zero.
            for (double hh = 0.5 * h_full; hh > ev.time_tolerance; hh *= 0.5) {
              const double gm = value(step_state(hh), t + hh);
              if (gm > 0) {
                tg = locate(value, gm, g1, hh);
                break;
              }
            }
          }
          if (tg < t_event || kind == kNone) t_event = tg, kind = kGuard, guard_kind = gd.kind;
        }
      }
      if (kind != kNone) {
        // Guard against chattering: events that keep firing without time advancing.
        zero_progress = t_event <= t ? zero_progress + 1 : 0;
        if (zero_progress > 8)
          throw std::runtime_error("integrator: events repeat without progress " +
                                   at_text(t, s_h(y)) + " (chattering at a junction)");
      }
      if (kind != kNone && t_event < t1) {
        // Stop exactly at the event: redo the step up to it, so no step straddles it.
        h_try = t_event - t;
        if (h_try > 0) {
          attempt(t, y, k1, h_try, y1, k7, rc);
          t1 = t_event;
          y1p = y1;
          drift = project(t1, y1p);
        } else {
          y1p = y;
          t1 = t;
        }
        have_end = false;
      }

      // ---- accept ----
      Sample s_new;
      if (h_try > 0) {
        ++st_.steps;
        st_.max_drift = std::max(st_.max_drift, drift);
        if (opt_.record) {
          if (dop853)
            dop853_dense([this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); }, t, y, y1,
                         h_try, k853_, rc);
          std::array<double, 8 * N> c;
          for (int j = 0; j < terms; ++j) Eigen::Map<State>(c.data() + j * N) = head(rc[j]);
          res_.trajectory.append(t, h_try, pieces_, c.data());
        }
        if constexpr (kAudited) ledger_.add_work(y1p[N] - y[N], y1p[N + 1] - y[N + 1]);
        const bool moved = drift > 0 && N == 10;
        t = t1;
        y = y1p;
        if (moved)
          need_k1 = true;
        else
          k1 = k7;
        if (opt_.record || kind != kNone || need_force) {
          s_new = have_end ? s_end : sample_at(t, y);
          st_.max_constraint_residual =
              std::max(st_.max_constraint_residual, s_new.constraint_residual);
          st_.max_redundant_residual =
              std::max(st_.max_redundant_residual, s_new.redundant_residual);
          record(t, head(y), &s_new);
          s_start = s_new;
          if (!audit(s_new)) {
            stopped = EventKind::kNumericalFailure;
            break;
          }
        }
      }
      if (!rk4 && kind == kNone && dop853) {
        // Hairer's DOP853 control: plain I controller (beta = 0) on the h^8 error norm, growth
        // at most 6x and shrink at most 3x; no growth right after a rejection.
        const double fac =
            std::clamp(std::pow(std::max(err, 1e-30), 1.0 / 8.0) / 0.9, 1.0 / 6, 3.0);
        h = h_try / fac;
        if (last_rejected) h = std::min(h, h_try);
      } else if (!rk4 && kind == kNone) {
        // PI step-size control (Hairer's DOPRI5 constants).
        const double fac11 = std::pow(std::max(err, 1e-16), 0.17);
        const double fac = std::clamp(fac11 / std::pow(facold, 0.04) / 0.9, 0.1, 5.0);
        facold = std::max(err, 1e-4);
        h = h_try / fac;
      }
      last_rejected = false;
      switch (kind) {
        case kNone:
          break;
        case kJunction: {
          ++st_.junction_crossings;
          ++st_.restarts;
          RecordedEvent junction_event;
          junction_event.kind = EventKind::kJunction;
          junction_event.t = t;
          junction_event.s_h = s_h(y);
          res_.events.push_back(junction_event);
          // The landing point may sit a rounding error short of the junction: pick the next
          // piece from the junction itself and the direction of crossing.
          const int d = junction == iv.hi ? +1 : -1;
          const int motion = pieces_.motion;
          const Pieces before = pieces_;
          pieces_ = model_.pieces_for(head(y), d);
          pieces_.hand = model_.problem().hand->piece_at(junction, d);
          pieces_.motion = motion;
          cross(t, y, before);
          need_k1 = true;
          if (need_force) s_start = sample_at(t, y);
          break;
        }
        case kGuard:
          stopped = guard_kind;
          break;
        case kBounds:
          stopped = EventKind::kLeftBounds;
          break;
      }
    }
    if (stopped) break;
    if (t_stop < opt_.t_end) {  // the motion's acceleration jumps here: restart on its next segment
      ++st_.restarts;
      const Pieces before = pieces_;
      ++pieces_.motion;
      cross(t, y, before);
      need_k1 = true;
      if (need_force) {
        // The forces jump with the acceleration: a guard the jump violates fires here and now.
        s_start = sample_at(t, y);
        if (auto kind = violated(s_start)) {
          record(t, head(y), &s_start);
          return stop_now(*kind, s_start);
        }
      }
    }
  }
  end.t = t;
  end.y = head(y);
  end.pieces = pieces_;
  end.fired = stopped;
  end.last = (opt_.record && !res_.steps.empty() && res_.steps.back().t == t) ? res_.steps.back()
                                                                              : sample_at(t, y);
  // Runs that sample no step (searches) are audited here, at their end.
  if (kAudited && !ledger_.audit().broken && !audit(end.last))
    end.fired = EventKind::kNumericalFailure;
  return end;
}

}  // namespace flatland::sim::detail
