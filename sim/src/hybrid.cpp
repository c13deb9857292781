#include "flatland/sim/hybrid.hpp"

#include "flatland/sim/roots.hpp"

#include "integration.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace flatland::sim {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Flight: the distance to the hand is checked at most this far apart (s), and at least this far
// apart while the disk is close (a touch-and-leave shorter than this, a penetration of about
// a dt^2 / 8 ~ 1e-8 m at table accelerations, goes unseen).
constexpr double kFlightMaxStep = 2e-3;
constexpr double kFlightMinStep = 1e-4;
// m: a gap below minus this is a contact (rounding of the distance is ~1e-17 m; after a lift-off
// the gap grows from 0 as t^3 and must not be mistaken for one).
constexpr double kGapTolerance = 1e-12;

double sgn(double v) { return v > 0 ? 1.0 : v < 0 ? -1.0 : 0.0; }

Eigen::Matrix2d rotation(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  return r;
}

double angle_of(const Vec2& v) { return std::atan2(v.y(), v.x()); }

/// (1 - e^-x) / x and (x - 1 + e^-x) / x^2, accurate for small x (the drag's closed forms).
double phi1(double x) {
  if (std::abs(x) < 1e-4) return 1.0 - x / 2.0 + x * x / 6.0 - x * x * x / 24.0;
  return -std::expm1(-x) / x;
}
double phi2(double x) {
  if (std::abs(x) < 1e-3) return 0.5 - x / 6.0 + x * x / 24.0 - x * x * x / 120.0;
  return (x + std::expm1(-x)) / (x * x);
}

/// The object's mechanical energy in the table plane (kinetic + potential), J.
double energy(const RollingProblem& pb, const Vec2& p, const Vec2& v, double w) {
  return 0.5 * pb.object.mass * v.squaredNorm() + 0.5 * pb.object.inertia * w * w -
         pb.object.mass * pb.gravity_vector().dot(p);
}

/// The free object from a state: p'' = g - (c/m) v, omega' = -(c_w / I) omega, in closed form.
struct Flight {
  double t0 = 0;
  Vec2 p0, v0;
  double angle0 = 0, w0 = 0;
  double k = 0, kw = 0;  // c/m, c_w/I
  Vec2 g;

  Flight(const RollingProblem& pb, const HybridState& x)
      : t0(x.t),
        p0(x.position),
        v0(x.velocity),
        angle0(x.angle),
        w0(x.angular_velocity),
        k(pb.contact.drag / pb.object.mass),
        kw(pb.contact.drag_angular / pb.object.inertia),
        g(pb.gravity_vector()) {}
  Vec2 position(double t) const {
    const double tau = t - t0;
    return p0 + v0 * tau * phi1(k * tau) + g * tau * tau * phi2(k * tau);
  }
  Vec2 velocity(double t) const {
    const double tau = t - t0;
    return v0 * std::exp(-k * tau) + g * tau * phi1(k * tau);
  }
  double angle(double t) const {
    const double tau = t - t0;
    return angle0 + w0 * tau * phi1(kw * tau);
  }
  double angular_velocity(double t) const { return w0 * std::exp(-kw * (t - t0)); }
  /// The drag's work from ta to tb, J (<= 0): -integral of c |v|^2 + c_w omega^2, by 5-point
  /// Gauss-Legendre on pieces of at most 2 ms (the closed form is smooth: exact to rounding).
  /// Computed apart from the closed form's own energy, which the audit compares it with.
  double drag_work(const RollingProblem& pb, double ta, double tb) const {
    const double c = pb.contact.drag, cw = pb.contact.drag_angular;
    if (!(tb > ta) || (c == 0 && cw == 0)) return 0.0;
    static constexpr std::array<double, 5> x = {-0.9061798459386640, -0.5384693101056831, 0.0,
                                                0.5384693101056831, 0.9061798459386640};
    static constexpr std::array<double, 5> w = {0.2369268850561891, 0.4786286704993665,
                                                0.5688888888888889, 0.4786286704993665,
                                                0.2369268850561891};
    const int pieces = static_cast<int>(std::ceil((tb - ta) / 2e-3));
    const double h = (tb - ta) / pieces;
    double work = 0;
    for (int i = 0; i < pieces; ++i) {
      const double mid = ta + (i + 0.5) * h;
      for (int j = 0; j < 5; ++j) {
        const double t = mid + 0.5 * h * x[j];
        const double om = angular_velocity(t);
        work -= 0.5 * h * w[j] * (c * velocity(t).squaredNorm() + cw * om * om);
      }
    }
    return work;
  }
  HybridState state(double t) const {
    HybridState x;
    x.t = t;
    x.mode = ContactMode::kFlight;
    x.position = position(t);
    x.velocity = velocity(t);
    x.angle = angle(t);
    x.angular_velocity = angular_velocity(t);
    return x;
  }
};

/// The hand's geometry at the point nearest to a disk, in world axes.
struct HandPoint {
  double s = 0;
  CurveGeometry g;
  Eigen::Matrix2d R;
  Vec2 rho, N, T;       ///< from the pivot to the point; outward normal; tangent
  Vec2 velocity;        ///< of the hand's material point there
  double distance = 0;  ///< gap from the disk's rim
};

HandPoint hand_point(const RollingProblem& pb, const HandKinematics& h, const Vec2& centre) {
  HandPoint out;
  out.R = rotation(h.angle);
  const Vec2 local = out.R.transpose() * (centre - h.position);
  out.s = pb.hand->nearest(local);
  out.g = pb.hand->geometry(out.s, pb.hand->piece_at(out.s, +1));
  out.rho = out.R * out.g.point;
  out.N = out.R * out.g.normal;
  out.T = out.R * out.g.tangent;
  out.velocity = h.velocity + h.angular_velocity * perp(out.rho);
  out.distance = (local - out.g.point).dot(out.g.normal) - *pb.object.disk_radius;
  return out;
}

/// A sample of the free disk: no contact force; s_h and its rate are those of the outline's
/// point nearest to the centre (continuous with the contact's at a lift-off).
Sample flight_sample(const RollingProblem& pb, const Flight& f, double t, long* gap_evals) {
  const HandKinematics h = pb.motion->at(t);
  Sample out;
  out.t = t;
  out.theta = h.angle;
  out.theta_dot = h.angular_velocity;
  out.theta_ddot = h.angular_acceleration;
  out.object_position = f.position(t);
  out.object_velocity = f.velocity(t);
  out.object_angle = f.angle(t);
  out.object_angular_velocity = f.angular_velocity(t);
  out.mode = ContactMode::kFlight;
  out.mu_required = kNaN;
  const HandPoint hp = hand_point(pb, h, out.object_position);
  if (gap_evals) ++*gap_evals;
  out.gap = hp.distance;
  out.s_h = hp.s;
  // d s*/dt from (c(s*) - p_local) . c'(s*) = 0.
  const Vec2 local = hp.R.transpose() * (out.object_position - h.position);
  const Vec2 local_rate =
      hp.R.transpose() * (out.object_velocity - h.velocity) - h.angular_velocity * perp(local);
  const CurveJet j = pb.hand->jet(hp.s, pb.hand->piece_at(hp.s, +1));
  const double fs = j.d1.squaredNorm() + (j.c - local).dot(j.d2);
  out.sdot_h = fs > 0 ? local_rate.dot(j.d1) / fs : 0.0;
  out.s_o = std::remainder(angle_of(-hp.N) - out.object_angle, 2.0 * std::numbers::pi);
  return out;
}

HybridState from_sample(const Sample& s, ContactMode mode, int sign, int hand_piece, int turn = 0) {
  HybridState x;
  x.t = s.t;
  x.mode = mode;
  x.sign = sign;
  x.turn = turn;
  x.s_h = s.s_h;
  x.sdot_h = mode == ContactMode::kRest ? 0.0 : s.sdot_h;
  x.s_o = s.s_o;
  x.sdot_o = s.sdot_o;
  x.hand_piece = hand_piece;
  x.position = s.object_position;
  x.velocity = s.object_velocity;
  x.angle = s.object_angle;
  x.angular_velocity = s.object_angular_velocity;
  return x;
}

GeneralRolling::State general_state(const HybridState& x) {
  GeneralRolling::State y;
  y << x.position.x(), x.position.y(), x.angle, x.s_o, x.s_h, x.velocity.x(), x.velocity.y(),
      x.angular_velocity, x.sdot_o, x.mode == ContactMode::kRest ? 0.0 : x.sdot_h;
  return y;
}

class Hybrid {
 public:
  Hybrid(std::shared_ptr<const RollingProblem> problem, const RunOptions& options, RunResult& res,
         Formulation formulation)
      : pb_(std::move(problem)),
        opt_(options),
        res_(res),
        formulation_(formulation),
        weight_(pb_->object.mass * pb_->gravity),
        side_(pb_->hand->normal_side()),
        ledger_(detail::planar_ledger(res.audit, *pb_, options)) {}

  void run(HybridState x);

 private:
  const RollingProblem& pb() const { return *pb_; }
  Pieces pieces_of(const HybridState& x) const {
    return {x.hand_piece, 0, pb().motion->segment_at(x.t)};
  }
  Sample sample(const HybridState& x) const;
  /// The instant's checks: a state whose mode its forces do not allow changes mode now.
  /// `crossed`: the guard whose located crossing x has just taken (transition()); the check that
  /// would take x back across that boundary is not made (see the definition).
  HybridState settle(HybridState x, std::optional<EventKind> crossed = std::nullopt);
  /// The state x sticks into where its slip stops: rolling the way s_h moves; where s_h stands
  /// still with rolling resistance, at rest if the couple can hold it, else rolling the way the
  /// couple turns it (as settle() resolves a rolling state with sdot_h = 0).
  HybridState no_slip(const HybridState& x) const;
  /// Sliding to the no-slip state `stuck` (no_slip(x), sampled as `r`): kStick, then kRest.
  void stick(HybridState& x, const HybridState& stuck, const Sample& r);
  /// The mode after the guard `fired` ended a segment at x.
  void transition(HybridState& x, EventKind fired, const Sample& at);
  /// One segment in a contact mode; false when the run ends.
  bool contact_segment(HybridState& x);
  template <class Model>
  bool run_segment(const Model& model, typename Model::State y, HybridState& x);
  std::vector<detail::Guard> guards(const HybridState& x) const;
  /// The flight until an impact, the end or a drop; false when the run ends.
  bool flight(HybridState& x);
  /// The impact at x (in flight, touching); false when the run ends there.
  bool impact(HybridState& x);
  void event(EventKind kind, const HybridState& x, const Sample* s = nullptr);
  /// Sliding: the sign of the rotation relative to the hand; where it is zero (or `at_zero`, at
  /// a located reversal), the sign of its acceleration without the rolling-resistance couple,
  /// or 0 (no couple) where the couple could hold it (an approximation: docs/DYNAMICS.md).
  int turn_of(const HybridState& x, bool at_zero = false) const;
  void change_mode(HybridState& x, ContactMode mode, int sign, EventKind kind);
  /// The energy balance at a state off the integrator's segments (a flight's end, right after
  /// an impact); false (the run stops as a numerical failure) when it broke.
  bool audit(const HybridState& x);
  /// Whether the run stops after a transition (stop_at_transition).
  bool stop_here() {
    if (!opt_.stop_at_transition) return false;
    res_.reason = StopReason::kTransition;
    return true;
  }

  std::shared_ptr<const RollingProblem> pb_;
  const RunOptions& opt_;
  RunResult& res_;
  Formulation formulation_;
  double weight_, side_;
  detail::EnergyLedger ledger_;
  HybridState final_;
  bool lifted_off_ = false;  ///< the flight about to start left the hand at a lift-off
};

Sample Hybrid::sample(const HybridState& x) const { return sample_state(pb_, x, formulation_); }

bool Hybrid::audit(const HybridState& x) {
  const RollingProblem& pb = *pb_;
  const double kinetic = energy(pb, Vec2::Zero(), x.velocity, x.angular_velocity);
  if (ledger_.check(x.t, energy(pb, x.position, x.velocity, x.angular_velocity), kinetic))
    return true;
  res_.reason = StopReason::kNumericalFailure;
  event(EventKind::kNumericalFailure, x);
  return false;
}

void Hybrid::event(EventKind kind, const HybridState& x, const Sample* s) {
  RecordedEvent e;
  e.kind = kind;
  e.t = x.t;
  e.s_h = s ? s->s_h : x.s_h;
  e.position = x.position;
  res_.events.push_back(e);
}

void Hybrid::change_mode(HybridState& x, ContactMode mode, int sign, EventKind kind) {
  if (mode != x.mode) ++res_.stats.mode_changes;
  lifted_off_ = kind == EventKind::kLiftOff;
  x.mode = mode;
  x.sign = sign;
  x.turn = 0;
  if (mode == ContactMode::kRest) x.sdot_h = 0;
  if (mode == ContactMode::kSliding) x.turn = turn_of(x);
  event(kind, x);
}

int Hybrid::turn_of(const HybridState& x, bool at_zero) const {
  const double delta = pb().contact.rolling_resistance;
  if (x.mode != ContactMode::kSliding || !(delta > 0)) return 0;
  const double relative = x.angular_velocity - pb().motion->at(x.t).angular_velocity;
  if (!at_zero && std::abs(relative) > 1e-9) return relative > 0 ? 1 : -1;
  HybridState free = x;
  free.turn = 0;
  const Sample s = sample(free);
  const double accel = s.object_angular_acceleration - s.theta_ddot;
  if (std::abs(pb().object.inertia * accel) <= delta * s.force_normal) return 0;
  return accel > 0 ? 1 : -1;
}

HybridState Hybrid::no_slip(const HybridState& x) const {
  HybridState roll = x;
  roll.mode = ContactMode::kRolling;
  roll.sign = x.sdot_h > 0 ? 1 : x.sdot_h < 0 ? -1 : 0;
  const double delta = pb().contact.rolling_resistance;
  if (roll.sign != 0 || !(delta > 0)) return roll;
  // Without a direction the rolling-resistance couple is undetermined: checked with none (sign
  // 0), a rolling the couple then turned one way could need more friction than the check said,
  // and a slip started there stuck again at the same instant, over and over.
  HybridState rest = roll;
  rest.mode = ContactMode::kRest;
  const Sample r = sample(rest);
  const double radius = pb().object.disk_radius ? *pb().object.disk_radius : 1.0;
  if (std::abs(r.rolling_couple) < delta * r.force_normal - 1e-12 * weight_ * radius) return rest;
  roll.sign = static_cast<int>(side_ * sgn(r.rolling_couple));
  return roll;
}

void Hybrid::stick(HybridState& x, const HybridState& stuck, const Sample& r) {
  x = from_sample(r, ContactMode::kSliding, x.sign, x.hand_piece);
  change_mode(x, ContactMode::kRolling, stuck.sign, EventKind::kStick);
  if (stuck.mode == ContactMode::kRest) change_mode(x, ContactMode::kRest, 0, EventKind::kRest);
}

// A located crossing is trusted. Brent locates a guard's zero to the event tolerance in time and
// returns the better end of its last bracket, which may lie on either side: the state a segment
// ends in sits on the boundary only up to about time_tolerance x |d guard / dt| (1e-11 N at a slip
// onset where the friction margin changes at ~10 N/s), more than this function's tolerances
// (1e-12 m g). Checked again here, a state a little short of the boundary read as strictly inside
// the mode it was leaving: a slip start on the near side of the cone re-stuck at once ("rolling
// strictly inside the cone"), the rolling segment then found the same crossing at the same
// instant, and the run stopped on the stall check ("keeps changing mode without time advancing",
// ~3 % of random worlds at event_tolerance 1e-12). A state at a located crossing is on the
// boundary by definition, and a boundary case goes to the mode the event entered: after a slip
// start the disk slides on (no stick test), after a release it rolls on (no rest test), after a
// reversal of the slip (a located stick whose rolling needs more than mu) or of the relative
// rotation (kTurn), the sign the transition chose stands (the slip velocity or the relative
// rotation left at the crossing is the location's residual, its sign is noise). The other
// transitions are already checked at the same state with complementary bounds (a stick or a rest
// decided with <= the bound is undone only beyond bound + tolerance); a lift-off leaves for the
// flight, whose first step looks for the disk leaving before it takes a touch for an impact
// (flight()). The checks that concern another boundary still run.
HybridState Hybrid::settle(HybridState x, std::optional<EventKind> crossed) {
  const double mu = pb().contact.mu_static();
  const double delta = pb().contact.rolling_resistance;
  const double tol_f = 1e-12 * weight_;
  const double radius = pb().object.disk_radius ? *pb().object.disk_radius : 1.0;
  // Not sliding, the disk slides now if it needs more than the static friction.
  const auto slips = [&](const Sample& s) {
    if (!(std::abs(s.force_tangential) > mu * s.force_normal + tol_f)) return false;
    x = from_sample(s, x.mode, x.sign, x.hand_piece);
    change_mode(x, ContactMode::kSliding, s.force_tangential > 0 ? -1 : +1, EventKind::kSlipStart);
    return true;
  };
  // A sliding state given without its slip's sign: any sign samples the slip velocity, and the
  // sliding branch below sets it.
  if (x.mode == ContactMode::kSliding && x.sign == 0) x.sign = 1;
  for (int i = 0; i < 8; ++i) {
    if (x.mode == ContactMode::kFlight) return x;
    // Once the mode changed here, the crossing is no longer what the state sits on.
    const auto on = [&](EventKind kind) { return i == 0 && crossed && *crossed == kind; };
    const Sample s = sample(x);
    if (s.force_normal < -tol_f) {
      if (!pb().object.disk_radius) return x;  // run() stops it
      x = from_sample(s, x.mode, x.sign, x.hand_piece);
      change_mode(x, ContactMode::kFlight, 0, EventKind::kLiftOff);
      return x;
    }
    switch (x.mode) {
      case ContactMode::kRolling:
        if (slips(s)) continue;
        if (delta > 0) {
          if (x.sdot_h != 0) {
            x.sign = x.sdot_h > 0 ? +1 : -1;
          } else if (!on(EventKind::kRelease)) {
            HybridState rest = x;
            rest.mode = ContactMode::kRest;
            const Sample r = sample(rest);
            // Strictly inside the bound: on it (right after a release) the disk rolls on.
            if (std::abs(r.rolling_couple) < delta * r.force_normal - tol_f * radius) {
              change_mode(x, ContactMode::kRest, 0, EventKind::kRest);
              continue;
            }
            x.sign = static_cast<int>(side_ * sgn(r.rolling_couple));
          }
        }
        return x;
      case ContactMode::kRest:
        if (slips(s)) continue;
        if (std::abs(s.rolling_couple) > delta * s.force_normal + tol_f * radius) {
          change_mode(x, ContactMode::kRolling, static_cast<int>(side_ * sgn(s.rolling_couple)),
                      EventKind::kRelease);
          continue;
        }
        return x;
      case ContactMode::kSliding: {
        // At a located reversal of the slip or of the relative rotation, what is left of it is
        // the location's residual: the transition's sign stands.
        if (!on(EventKind::kStick) && std::abs(s.slip_velocity) > 1e-12) {
          x.sign = s.slip_velocity > 0 ? +1 : -1;
          if (x.turn == 0) x.turn = turn_of(x, on(EventKind::kTurn));
          return x;
        }
        // No slip: rolling if the friction it needs is strictly inside the cone (on the cone,
        // as right after a slip started, it slides on).
        const HybridState stuck = no_slip(x);
        const Sample r = sample(stuck);
        if (!on(EventKind::kSlipStart) &&
            std::abs(r.force_tangential) < mu * r.force_normal - tol_f) {
          stick(x, stuck, r);
          continue;
        }
        const int sign = r.force_tangential > 0 ? -1 : +1;
        if (sign != x.sign) event(EventKind::kSlipReverse, x);
        x.sign = sign;
        x.turn = turn_of(x, on(EventKind::kTurn));
        return x;
      }
      case ContactMode::kFlight:
        return x;
    }
  }
  throw std::runtime_error("hybrid: the contact mode does not settle at t=" + std::to_string(x.t) +
                           " s (s_h=" + std::to_string(x.s_h) + ")");
}

void Hybrid::transition(HybridState& x, EventKind fired, const Sample& at) {
  const double delta = pb().contact.rolling_resistance;
  switch (fired) {
    case EventKind::kLiftOff:
      change_mode(x, ContactMode::kFlight, 0, EventKind::kLiftOff);
      return;
    case EventKind::kSlipStart:
      change_mode(x, ContactMode::kSliding, at.force_tangential > 0 ? -1 : +1,
                  EventKind::kSlipStart);
      return;
    case EventKind::kRelease:
      change_mode(x, ContactMode::kRolling, static_cast<int>(side_ * sgn(at.rolling_couple)),
                  EventKind::kRelease);
      return;
    case EventKind::kRest: {
      // The rolling stopped: the couple holds the disk, or it rolls back.
      x.sdot_h = 0;
      HybridState rest = x;
      rest.mode = ContactMode::kRest;
      const Sample r = sample(rest);
      if (std::abs(r.rolling_couple) <= delta * r.force_normal) {
        change_mode(x, ContactMode::kRest, 0, EventKind::kRest);
      } else {
        x.sign = static_cast<int>(side_ * sgn(r.rolling_couple));
        x.mode = ContactMode::kRolling;
      }
      return;
    }
    case EventKind::kStick: {
      const HybridState stuck = no_slip(x);
      const Sample r = sample(stuck);
      if (std::abs(r.force_tangential) <= pb().contact.mu_static() * r.force_normal) {
        stick(x, stuck, r);
      } else {
        x.sign = r.force_tangential > 0 ? -1 : +1;
        x.turn = turn_of(x);
        event(EventKind::kSlipReverse, x);
      }
      return;
    }
    case EventKind::kTurn:
      x.turn = turn_of(x, true);
      return;
    default:
      throw std::logic_error("hybrid: unexpected event " + to_string(fired));
  }
}

std::vector<detail::Guard> Hybrid::guards(const HybridState& x) const {
  // Where a segment starts on the boundary it leaves (at a located event), a guard may read a
  // little below zero: the event's location leaves about (time tolerance) x (rate of change).
  const double tol_f = 1e-9 * weight_, tol_v = 1e-9;
  std::vector<detail::Guard> g;
  g.push_back({EventKind::kLiftOff, [](const Sample& s) { return s.force_normal; }, tol_f});
  const double mu = pb().contact.mu_static();
  const double delta = pb().contact.rolling_resistance;
  if (x.mode != ContactMode::kSliding && std::isfinite(mu))
    g.push_back(
        {EventKind::kSlipStart,
         [mu](const Sample& s) { return mu * s.force_normal - std::abs(s.force_tangential); },
         tol_f});
  if (x.mode == ContactMode::kRolling && delta > 0 && x.sign != 0) {
    const double sign = x.sign;
    g.push_back({EventKind::kRest, [sign](const Sample& s) { return sign * s.sdot_h; }, tol_v});
  }
  if (x.mode == ContactMode::kRest) {
    const double r = pb().object.disk_radius ? *pb().object.disk_radius : 1.0;
    g.push_back(
        {EventKind::kRelease,
         [delta](const Sample& s) { return delta * s.force_normal - std::abs(s.rolling_couple); },
         tol_f * r});
  }
  if (x.mode == ContactMode::kSliding) {
    const double sign = x.sign;
    g.push_back(
        {EventKind::kStick, [sign](const Sample& s) { return sign * s.slip_velocity; }, tol_v});
    if (delta > 0 && x.turn != 0) {
      const double turn = x.turn;
      g.push_back(
          {EventKind::kTurn,
           [turn](const Sample& s) { return turn * (s.object_angular_velocity - s.theta_dot); },
           tol_v});
    }
  }
  return g;
}

template <class Model>
bool Hybrid::run_segment(const Model& model, typename Model::State y, HybridState& x) {
  detail::Integration<Model> integration(model, opt_, res_, guards(x), ledger_, res_.initial.t);
  Pieces pieces = pieces_of(x);
  model.project(x.t, y, pieces);
  const double t0 = x.t;
  const auto end = integration.run_from(x.t, y, pieces);
  res_.stats.mode_time[static_cast<int>(x.mode)] += end.t - t0;
  const ContactMode mode = x.mode;
  x = from_sample(end.last, mode, x.sign, end.pieces.hand, x.turn);
  final_ = x;
  res_.final = end.last;
  if (!end.fired) return false;  // the end time
  if (*end.fired == EventKind::kNumericalFailure) {
    res_.reason = StopReason::kNumericalFailure;
    event(EventKind::kNumericalFailure, x);
    return false;
  }
  if (*end.fired == EventKind::kLeftBounds) {
    res_.reason = StopReason::kLeftBounds;
    event(EventKind::kLeftBounds, x);
    return false;
  }
  if (*end.fired == EventKind::kLiftOff && !pb().object.disk_radius) {
    res_.reason = StopReason::kContactLost;
    event(EventKind::kContactLost, x);
    return false;
  }
  // Located (the guard within its tolerance of 0 where the segment ended), or violated at once
  // (beyond it: at the segment's start or at a jump of the hand's acceleration).
  bool located = false;
  for (const detail::Guard& g : guards(x))
    if (g.kind == *end.fired) located = g.value(end.last) >= -g.tolerance;
  transition(x, *end.fired, end.last);
  final_ = x;
  if (stop_here()) return false;
  x = located ? settle(x, *end.fired) : settle(x);
  final_ = x;
  return true;
}

bool Hybrid::contact_segment(HybridState& x) {
  if (formulation_ == Formulation::kGeneral) {
    const GeneralRolling model(pb_, {x.mode, x.sign, x.turn});
    return run_segment(model, general_state(x), x);
  }
  if (x.mode == ContactMode::kSliding) {
    const ReducedDiskSliding model(pb_, x.sign, x.turn);
    ReducedDiskSliding::State y(x.s_h, x.angle, x.sdot_h, x.angular_velocity);
    return run_segment(model, y, x);
  }
  const ReducedDiskRolling model(pb_, {x.mode, x.sign});
  ReducedDiskRolling::State y(x.s_h, x.angle, x.mode == ContactMode::kRest ? 0.0 : x.sdot_h);
  return run_segment(model, y, x);
}

bool Hybrid::flight(HybridState& x) {
  const RollingProblem& pb = *pb_;
  const Flight f(pb, x);
  const bool lifted_off = std::exchange(lifted_off_, false);
  const double r = *pb.object.disk_radius;
  const double reach = pb.hand->reach() + r;
  long& gap_evals = res_.stats.gap_evals;
  // The disk and the hand at one time.
  struct Probe {
    double t;
    HandKinematics h;
    Vec2 p, v;
  };
  const auto probe = [&](double t) {
    return Probe{t, pb.motion->at(t), f.position(t), f.velocity(t)};
  };
  const auto gap_of = [&](const Probe& q) {
    ++gap_evals;
    return hand_point(pb, q.h, q.p).distance;
  };
  // An upper bound of the speed at which the gap can close: the disk's speed plus that of the
  // fastest hand point that can reach it.
  const auto closing_speed = [&](const Probe& q) {
    const double turning = q.h.angular_velocity == 0 ? 0.0 : std::abs(q.h.angular_velocity) * reach;
    return q.v.norm() + q.h.velocity.norm() + turning;
  };
  const double t0 = x.t;
  Probe q = probe(x.t);
  double gap = gap_of(q);
  bool ended = false, dropped = false;
  std::optional<double> t_contact;
  if (opt_.record) res_.steps.push_back(flight_sample(pb, f, q.t, &gap_evals));
  while (!ended) {
    // As far as the gap cannot close, checked with the speeds at both ends of the step.
    const double speed0 = closing_speed(q);
    double dt = std::clamp(gap / (1.1 * speed0 + 1e-9), kFlightMinStep, kFlightMaxStep);
    Probe q1 = probe(std::min(q.t + dt, opt_.t_end));
    const double speed1 = closing_speed(q1);
    if (speed1 > speed0) {
      dt = std::clamp(gap / (1.1 * speed1 + 1e-9), kFlightMinStep, kFlightMaxStep);
      q1 = probe(std::min(q.t + dt, opt_.t_end));
    }
    const double gap1 = gap_of(q1);
    if (gap1 < -kGapTolerance) {
      // Touching at the start. After a bounce, a flight that ends within this step ends the
      // bouncing in contact (impact(): the rule that ends a chattering sequence). After a
      // lift-off, the disk may leave and come back within the step: then the return is the
      // contact. Taken at the start instead, the impact found the disk still leaving (touching
      // while separating: caught), it lifted off again at the same instant, and so on. The gap
      // is probed at half the step, a quarter, ... down to the time tolerance.
      double t_from = q.t, gap_from = gap;
      for (double dt_probe = 0.5 * (q1.t - q.t);
           lifted_off && gap_from <= 0 && dt_probe > opt_.events.time_tolerance; dt_probe *= 0.5) {
        const double g = gap_of(probe(q.t + dt_probe));
        if (g > 0) t_from = q.t + dt_probe, gap_from = g;
      }
      if (gap_from <= 0) {
        t_contact = q.t;
      } else {
        t_contact = brent_root([&](double tt) { return gap_of(probe(tt)); }, t_from, q1.t, gap_from,
                               gap1, opt_.events.time_tolerance)
                        .x;
      }
      break;
    }
    q = q1;
    gap = gap1;
    if (opt_.record) res_.steps.push_back(flight_sample(pb, f, q.t, &gap_evals));
    // Out of reach and moving away with gravity pulling away too: it cannot come back.
    if (q.h.velocity.norm() == 0 && q.h.acceleration.norm() == 0) {
      const Vec2 d = q.p - q.h.position;
      if (d.norm() > reach && d.dot(q.v) >= 0 && d.dot(pb.gravity_vector()) >= 0) dropped = true;
    }
    ended = dropped || q.t >= opt_.t_end;
  }
  double t = q.t;
  const double t_last = t_contact ? *t_contact : t;
  res_.stats.mode_time[static_cast<int>(ContactMode::kFlight)] += t_last - t0;
  if (opt_.record) {
    const auto problem = pb_;
    res_.trajectory.add_closed_part(
        t0, t_last, [problem, f](double tt) { return flight_sample(*problem, f, tt, nullptr); });
  }
  x = f.state(t_last);
  final_ = x;
  res_.final = flight_sample(pb, f, t_last, &gap_evals);
  ledger_.add_work(0.0, f.drag_work(pb, t0, t_last));
  if (!audit(x)) return false;
  if (dropped) {
    res_.reason = StopReason::kDropped;
    event(EventKind::kDropped, x, &res_.final);
    return false;
  }
  if (!t_contact) return false;
  return impact(x);
}

bool Hybrid::impact(HybridState& x) {
  const RollingProblem& pb = *pb_;
  const HandKinematics h = pb.motion->at(x.t);
  const HandPoint hp = hand_point(pb, h, x.position);
  const double r = *pb.object.disk_radius;
  const Vec2 arm = -r * hp.N;  // centre -> contact point
  const Vec2 v_rel = x.velocity + x.angular_velocity * perp(arm) - hp.velocity;
  const double vn = v_rel.dot(hp.N), vt = v_rel.dot(hp.T);
  const double e_before = energy(pb, x.position, x.velocity, x.angular_velocity);
  RecordedEvent e;
  e.kind = EventKind::kImpact;
  e.t = x.t;
  e.s_h = hp.s;
  e.position = x.position;
  Eigen::Vector2d impulse = Eigen::Vector2d::Zero();
  ImpactResult result;
  result.vn_before = result.vn_after = vn;
  result.vt_before = result.vt_after = vt;
  const ContactLaw& law = pb.contact;
  const Eigen::Matrix2d W = inverse_effective_mass(pb.object.mass, pb.object.inertia, arm, hp.N,
                                                   hp.T, opt_.hand_inertia, hp.rho);
  if (vn < 0) {
    result = sim::impact(W, vn, vt, law);
    if (result.vn_after <= law.capture_velocity && law.restitution > 0) {
      // A rebound this small ends the bouncing: the impact is plastic and the disk stays.
      ContactLaw plastic = law;
      plastic.restitution = 0;
      result = sim::impact(W, vn, vt, plastic);
    }
    impulse = Eigen::Vector2d(result.impulse_normal, result.impulse_tangential);
  } else {
    // Touching while separating: the last bounce's flight ended within the flight's smallest
    // step (a disk skidding along a concave part bounces ever faster). The bounces end in
    // contact: the normal relative velocity left is taken away (the kinetic energy decreases).
    impulse = Eigen::Vector2d(-vn / W(0, 0), 0.0);
    result.impulse_normal = impulse[0];
    result.vn_after = 0;
    result.vt_after = vt + W(1, 0) * impulse[0];
    result.energy_change = impulse[0] * vn + 0.5 * W(0, 0) * impulse[0] * impulse[0];
  }
  e.caught = result.vn_after <= law.capture_velocity;
  const Vec2 p_world = impulse[0] * hp.N + impulse[1] * hp.T;
  const Vec2 p_applied = opt_.testing_impulse_factor * p_world;
  x.velocity += p_applied / pb.object.mass;
  x.angular_velocity += cross2(arm, p_applied) / pb.object.inertia;
  double hand_rate = h.angular_velocity;
  if (opt_.hand_inertia) {
    e.hand_rate_change = -cross2(hp.rho, p_world) / *opt_.hand_inertia;
    hand_rate += e.hand_rate_change;
  }
  e.impact = result;
  e.energy_change = energy(pb, x.position, x.velocity, x.angular_velocity) - e_before;
  res_.events.push_back(e);
  ++res_.stats.impacts;
  // The audit's account of the impact, from the law and the impulse, apart from the velocities
  // just changed: the object's energy changes by the law's dissipation plus the impulse's work
  // through the hand's point, P . v_hand, less what a hand of finite inertia gave way,
  // (1/2) P . W_hand P (docs/DYNAMICS.md, "Energy audit").
  const double hand_give =
      opt_.hand_inertia ? 0.5 * std::pow(cross2(hp.rho, p_world), 2) / *opt_.hand_inertia : 0.0;
  ledger_.add_impact(result.energy_change, p_world.dot(hp.velocity) - hand_give);
  if (!audit(x)) {
    final_ = x;
    return false;
  }
  if (e.caught) {
    // In contact at the nearest point, with the tangential motion the impact left; the normal
    // relative velocity is zero. Contact coordinates with the hand's rate after the impact.
    const double sigma = hp.g.speed * (1.0 + r * hp.g.curvature);
    const Vec2 q = hp.R * (hp.g.point + r * hp.g.normal);
    x.s_h = hp.s;
    x.hand_piece = pb.hand->piece_at(hp.s, vt >= 0 ? +1 : -1);
    x.sdot_h = (x.velocity - h.velocity - hand_rate * perp(q)).dot(hp.T) / sigma;
    x.s_o = std::remainder(angle_of(-hp.N) - x.angle, 2.0 * std::numbers::pi);
    x.sdot_o = hand_rate - side_ * hp.g.curvature * hp.g.speed * x.sdot_h - x.angular_velocity;
    x.position = h.position + q;
    ++res_.stats.mode_changes;
    if (result.sticking || std::abs(result.vt_after) == 0) {
      x.mode = ContactMode::kRolling;
      x.sign = x.sdot_h > 0 ? 1 : x.sdot_h < 0 ? -1 : 0;
    } else {
      x.mode = ContactMode::kSliding;
      x.sign = result.vt_after > 0 ? +1 : -1;
    }
  }
  final_ = x;
  if (opt_.hand_inertia || stop_here()) {
    res_.reason = StopReason::kTransition;
    return false;
  }
  if (x.mode != ContactMode::kFlight) {
    x = settle(x);
    final_ = x;
  }
  return true;
}

void Hybrid::run(HybridState x) {
  validate_run_options(opt_, x.t);
  check_drag_stiffness(pb(), opt_.integrator, opt_.t_end - x.t);
  x = settle(x);
  if (x.mode != ContactMode::kFlight && x.sdot_h == 0) {
    // Starting at rest on a junction: the side the disk will move to is the active piece.
    const Sample s = sample(x);
    x.hand_piece = pb().hand->piece_at(x.s_h, s.sddot_h < 0 ? -1 : +1);
  }
  final_ = x;
  res_.initial = sample(x);
  ledger_.start(mechanical_energy(pb(), res_.initial), kinetic_energy(pb(), res_.initial));
  bool going = true;
  // Transitions that keep coming back without time advancing would never end.
  double t_last = x.t;
  int stalled = 0;
  while (going && x.t < opt_.t_end) {
    if (x.mode == ContactMode::kFlight)
      going = flight(x);
    else
      going = contact_segment(x);
    stalled = x.t > t_last ? 0 : stalled + 1;
    t_last = x.t;
    if (stalled > 16) {
      std::ostringstream os;
      os.precision(10);
      os << "hybrid: the contact keeps changing mode without time advancing at t=" << x.t
         << " s (s_h=" << x.s_h << ", mode " << to_string(x.mode) << ")";
      throw std::runtime_error(os.str());
    }
  }
  res_.final_state = final_;
  if (res_.steps.empty() || res_.final.t != final_.t) res_.final = sample(final_);
  finish_run(res_, opt_);
}

}  // namespace

std::vector<FlightReport> flight_reports(const RunResult& run) {
  return flight_reports(run.events, run.initial);
}

std::vector<FlightReport> flight_reports(const std::vector<RecordedEvent>& all,
                                         const Sample& initial) {
  std::vector<FlightReport> out;
  std::vector<const RecordedEvent*> events;
  for (const RecordedEvent& e : all) events.push_back(&e);
  std::stable_sort(events.begin(), events.end(),
                   [](const RecordedEvent* a, const RecordedEvent* b) { return a->t < b->t; });
  FlightReport* open = nullptr;
  const auto begin = [&](double t, double s_h) {
    out.push_back({});
    open = &out.back();
    open->t_lift_off = t;
    open->s_lift_off = s_h;
  };
  if (initial.mode == ContactMode::kFlight) begin(initial.t, initial.s_h);
  for (const RecordedEvent* e : events) {
    if (e->kind == EventKind::kLiftOff) {
      begin(e->t, e->s_h);
      continue;
    }
    if (e->kind == EventKind::kImpact) {
      if (!open) begin(e->t, e->s_h);  // (an impact always follows a flight)
      if (!open->t_landing) {
        open->t_landing = e->t;
        open->s_landing = e->s_h;
        open->landing_position = e->position;
        if (e->impact) {
          open->impulse_normal = e->impact->impulse_normal;
          open->impulse_tangential = e->impact->impulse_tangential;
        }
      }
      if (e->caught) {
        open->t_caught = e->t;
        open = nullptr;
      } else {
        ++open->bounces;
      }
      continue;
    }
    if (e->kind == EventKind::kDropped && open) {
      open->dropped = true;
      open = nullptr;
    }
  }
  return out;
}

HybridState fly(const RollingProblem& problem, const HybridState& x, double t) {
  if (x.mode != ContactMode::kFlight) throw std::logic_error("fly: the object is not in flight");
  return Flight(problem, x).state(t);
}

HandGap disk_gap(const RollingProblem& problem, const HandKinematics& h, const Vec2& centre) {
  if (!problem.object.disk_radius) throw std::invalid_argument("disk_gap: the object is no disk");
  const HandPoint hp = hand_point(problem, h, centre);
  return {hp.distance, hp.s};
}

HybridState hybrid_state(const RollingProblem& problem, const InitialContact& init) {
  const HandKinematics h = problem.motion->at(init.t0);
  const int dir = init.sdot_h < 0 ? -1 : +1;
  const int piece = problem.hand->piece_at(init.s_h, dir);
  const CurveGeometry g = problem.hand->geometry(init.s_h, piece);
  const Vec2 n = rotation(h.angle) * g.normal;
  HybridState x;
  x.t = init.t0;
  x.mode = ContactMode::kRolling;
  x.s_h = init.s_h;
  x.sdot_h = init.sdot_h;
  x.sign = init.sdot_h > 0 ? 1 : init.sdot_h < 0 ? -1 : 0;
  x.hand_piece = piece;
  if (problem.object.disk_radius) {
    x.angle = init.s_o ? angle_of(-n) - *init.s_o : init.object_angle;
    x.s_o = std::remainder(angle_of(-n) - x.angle, 2.0 * std::numbers::pi);
  } else {
    x.s_o = init.s_o ? *init.s_o : -0.5 * std::numbers::pi;
    const Vec2 no = problem.object.boundary->geometry(x.s_o).normal;
    x.angle = angle_of(-n) - angle_of(no);
  }
  // Position and velocities follow from the contact (the models rebuild them).
  return x;
}

Sample sample_state(std::shared_ptr<const RollingProblem> problem, const HybridState& x,
                    Formulation formulation) {
  const Formulation f = resolve_formulation(*problem, formulation);
  const Pieces p{x.hand_piece, 0, problem->motion->segment_at(x.t)};
  if (x.mode == ContactMode::kFlight)
    return flight_sample(*problem, Flight(*problem, x), x.t, nullptr);
  if (f == Formulation::kGeneral) {
    const GeneralRolling model(problem, {x.mode, x.sign, x.turn});
    GeneralRolling::State y = general_state(x);
    model.project(x.t, y, p);
    return model.sample(x.t, y, p);
  }
  if (x.mode == ContactMode::kSliding) {
    const ReducedDiskSliding model(problem, x.sign, x.turn);
    return model.sample(x.t, {x.s_h, x.angle, x.sdot_h, x.angular_velocity}, p);
  }
  const ReducedDiskRolling model(problem, {x.mode, x.sign});
  return model.sample(x.t, {x.s_h, x.angle, x.mode == ContactMode::kRest ? 0.0 : x.sdot_h}, p);
}

RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const HybridState& start,
                          const RunOptions& options) {
  if (!problem) throw std::invalid_argument("simulate: no problem");
  problem->contact.validate();
  if (options.hand_inertia && !(*options.hand_inertia > 0))
    throw std::invalid_argument("hand inertia: must be positive (kg m^2)");
  const ContactLaw& law = problem->contact;
  if (law.rolling_resistance > 0 && problem->object.disk_radius && law.mu &&
      !(law.rolling_resistance < law.kinetic() * *problem->object.disk_radius))
    throw std::invalid_argument(
        "contact.rolling_resistance: must be below mu_kinetic x the disk's radius (" +
        std::to_string(law.kinetic() * *problem->object.disk_radius) +
        " m): the rolling-resistance couple would exceed the friction couple and could hold a "
        "sliding disk's rotation");
  RunResult res;
  res.method = options.integrator.method;
  res.formulation = resolve_formulation(*problem, options.formulation);
  Hybrid hybrid(problem, options, res, res.formulation);
  hybrid.run(start);
  return res;
}

RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                          const RunOptions& options) {
  if (!problem) throw std::invalid_argument("simulate: no problem");
  if (!std::isfinite(init.s_h) || !std::isfinite(init.sdot_h) || !std::isfinite(init.t0))
    throw std::invalid_argument("initial: s_h, sdot_h and t0 must be finite");
  return simulate_hybrid(problem, hybrid_state(*problem, init), options);
}

}  // namespace flatland::sim
