#include "flatland/sim/sensitivity.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/rolling.hpp"
#include "rolling_run.hpp"
#include "rolling_terms.hpp"

#include <ceres/jet.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>

// The sanitizer build leaves the flattening out (sim/CMakeLists.txt): there it only costs compile
// time.
#ifdef FLATLAND_SENSITIVITY_NO_FLATTEN
#define FLATLAND_FLATTEN
#else
#define FLATLAND_FLATTEN [[gnu::flatten]]
#endif

namespace flatland::sim {
namespace {

constexpr int kParameters = static_cast<int>(kButterflyParameters.size());
constexpr int kPeriod = 5;  // the period's column

const PolynomialHand& polynomial_hand(const RollingProblem& pb) {
  const auto* hand = dynamic_cast<const PolynomialHand*>(pb.hand.get());
  if (!hand)
    throw std::invalid_argument(
        "sensitivities: hand: the polynomial hand only (its a, b, c, d are the shape's "
        "parameters); got " +
        (pb.hand ? pb.hand->describe() : std::string("none")));
  return *hand;
}

const ButterflyMotion& butterfly_motion(const RollingProblem& pb) {
  const auto* motion = dynamic_cast<const ButterflyMotion*>(pb.motion.get());
  if (!motion)
    throw std::invalid_argument(
        "sensitivities: motion: the butterfly motion only (its k and period are the motion's "
        "parameters)");
  return *motion;
}

/// The reduced disk's rolling with the sensitivities of (s_h, sdot_h) to the six parameters beside
/// its state: y = (s_h, object angle, sdot_h, d s_h/dp (6), d sdot_h/dp (6)). The first three
/// components are ReducedDiskRolling's, computed by it: the run is the same run.
class ReducedDiskSensitivity {
 public:
  static constexpr int N = 3 + 2 * kParameters;
  using State = Eigen::Matrix<double, N, 1>;
  using Base = ReducedDiskRolling;

 private:
  /// `finish(geometry, hand, terms, s_h'')` of the contact's terms at one state, in any scalar:
  /// what s_h'' and the forces are made of. (A callback, not a returned struct: the hot path's
  /// Jets are not copied; returning them made a run with sensitivities 1.4 times slower.)
  template <class T, class Finish>
  auto with_contact(const T& t, const T& s, const T& sdot, const T& a, const T& b, const T& c,
                    const T& d, const T& k, const T& period, const Pieces& p,
                    Finish&& finish) const {
    const BasicCurveGeometry<T> g = detail::geometry_of(
        detail::polynomial_hand_jet(detail::polynomial_coefficients(a, b, c, d), s, p.hand),
        hand_.normal_side());
    const BasicHandKinematics<T> h = detail::butterfly_kinematics(
        detail::butterfly_coefficients(T(0.5) * period, k), t, p.motion);
    const detail::RollingTerms<T> terms = detail::rolling_terms(h, g, r_, gravity_);
    const T drive = detail::rolling_drive(h, g, terms, r_, rho2_, side_);
    return finish(g, h, terms, detail::rolling_sddot(terms, drive, sdot, r_, rho2_));
  }

  /// s_h'' by the run's formulas (rolling_terms.hpp) in any scalar. Flattened: GCC 12 at -O3 left
  /// the Jets' 8-wide Eigen assignments as calls, half of a run's time (a run with sensitivities
  /// 6.1 ms, 1.6 ms flattened, against 0.37 ms without).
  template <class T>
  FLATLAND_FLATTEN T sddot(const T& t, const T& s, const T& sdot, const T& a, const T& b,
                           const T& c, const T& d, const T& k, const T& period,
                           const Pieces& p) const {
    return with_contact<T>(t, s, sdot, a, b, c, d, k, period, p,
                           [](const auto&, const auto&, const auto&, const T& sdd) { return sdd; });
  }

 public:
  ReducedDiskSensitivity(std::shared_ptr<const RollingProblem> problem, bool control_error)
      : base_(problem),
        hand_(polynomial_hand(*problem)),
        motion_(butterfly_motion(*problem)),
        r_(*problem->object.disk_radius),
        rho2_(problem->object.inertia / problem->object.mass),
        side_(problem->hand->normal_side()),
        gravity_(problem->gravity_vector()),
        gravity_magnitude_(problem->gravity),
        control_error_(control_error) {}

  State initial_state(const InitialContact& init) const {
    State y = State::Zero();  // the initial contact does not depend on the parameters
    y.head<3>() = base_.initial_state(init);
    return y;
  }

  void derivative(double t, const State& y, const Pieces& p, State& dy,
                  Power* power = nullptr) const {
    Base::State head = y.head<3>(), dhead;
    base_.derivative(t, head, p, dhead, power);
    dy.head<3>() = dhead;
    // s_h'' as a function of (s_h, sdot_h, a, b, c, d, k, period), differentiated forward.
    using J = ceres::Jet<double, 2 + kParameters>;
    const J s(y[0], 0), sdot(y[2], 1);
    const J a(hand_.a(), 2), b(hand_.b(), 3), c(hand_.c(), 4), d(hand_.d(), 5);
    const J k(motion_.k(), 6), period(motion_.period(), 7);
    const J sdd = sddot<J>(J(t), s, sdot, a, b, c, d, k, period, p);
    // S' = f_x S + f_p, row by row: (d s_h/dp)' = d sdot_h/dp, and
    // (d sdot_h/dp)' = s''_s d s_h/dp + s''_sdot d sdot_h/dp + s''_p.
    const auto S_s = y.segment<kParameters>(3);
    const auto S_v = y.segment<kParameters>(3 + kParameters);
    dy.segment<kParameters>(3) = S_v;
    dy.segment<kParameters>(3 + kParameters) =
        sdd.v[0] * S_s + sdd.v[1] * S_v + sdd.v.template tail<kParameters>();
  }

  /// f_n / (m g) and f_t / (m g) at (t, s_h, sdot_h) on pieces p, and their derivatives in the
  /// parameters given S = d(s_h, sdot_h)/dp there: the chain rule through the state, plus the
  /// parameters' own part.
  struct ForceRatios {
    double fn = 0, ft = 0;
    ParameterGradient dfn, dft;
  };
  ForceRatios force_ratios(double t, double s_h, double sdot_h, const ButterflyJacobian& S,
                           const Pieces& p) const {
    using J = ceres::Jet<double, 2 + kParameters>;
    const J s(s_h, 0), sdot(sdot_h, 1);
    const J a(hand_.a(), 2), b(hand_.b(), 3), c(hand_.c(), 4), d(hand_.d(), 5);
    const J k(motion_.k(), 6), period(motion_.period(), 7);
    // f / m in the hand's axes, along its normal and tangent.
    const auto [fn, ft] = with_contact<J>(
        J(t), s, sdot, a, b, c, d, k, period, p,
        [&](const BasicCurveGeometry<J>& g, const BasicHandKinematics<J>& h,
            const detail::RollingTerms<J>& terms, const J& sdd) {
          const detail::Vec2T<J> accel = detail::relative_acceleration(h, g, terms, sdot, sdd);
          return std::pair<J, J>(accel.dot(g.normal) / gravity_magnitude_,
                                 accel.dot(g.tangent) / gravity_magnitude_);
        });
    auto total = [&](const J& f) -> ParameterGradient {
      return f.v[0] * S.row(0) + f.v[1] * S.row(1) + f.v.template tail<kParameters>().transpose();
    };
    return {fn.a, ft.a, total(fn), total(ft)};
  }

  double project(double, State&, const Pieces&) const { return 0.0; }
  /// The step-size control measures the state alone, or the sensitivities too
  /// (SensitivityOptions::control_error).
  int controlled() const { return control_error_ ? N : 3; }
  Sample sample(double t, const State& y, const Pieces& p) const {
    return base_.sample(t, y.head<3>(), p);
  }
  Pieces pieces_for(const State& y, int direction) const {
    return base_.pieces_for(y.head<3>(), direction);
  }
  static double s_h(const State& y) { return y[0]; }
  static double sdot_h(const State& y) { return y[2]; }
  const RollingProblem& problem() const { return base_.problem(); }

  /// The jump of the sensitivities where the pieces switch at t: S+ = S- + (f- - f+) dtau/dp,
  /// tau the switch's time. A junction s_h = s_j: dtau/dp = -(d s_h/dp) / sdot_h. The motion's
  /// end 2T: dtau/dp is 1 for the period, 0 for the rest; its start (t = 0) does not move.
  /// Only s_h'' jumps (s_h and sdot_h are continuous), so only the rate's row changes.
  void cross(double t, State& y, const Pieces& before, const Pieces& after) const {
    const double jump = rate_of_sdot(t, y, after) - rate_of_sdot(t, y, before);
    if (before.hand != after.hand) {
      const double sdot = y[2];
      if (sdot == 0 || !std::isfinite(jump / sdot))
        throw std::runtime_error(
            "sensitivities: the disk reaches the junction at s_h = " + format_significant(y[0], 6) +
            " with zero speed (t = " + format_significant(t, 9) +
            " s): the run's end is not differentiable there");
      y.segment<kParameters>(3 + kParameters) += jump / sdot * y.segment<kParameters>(3);
    }
    if (after.motion == before.motion + 1 && before.motion == 1)  // 2T: the quintic ends
      y[3 + kParameters + kPeriod] -= jump;
  }

 private:
  double rate_of_sdot(double t, const State& y, const Pieces& p) const {
    Base::State head = y.head<3>(), dhead;
    base_.derivative(t, head, p, dhead);
    return dhead[2];
  }

  Base base_;
  const PolynomialHand& hand_;
  const ButterflyMotion& motion_;
  double r_, rho2_, side_;
  Eigen::Vector2d gravity_;
  double gravity_magnitude_;  ///< m/s^2 in the table's plane: the ratios' weight per unit mass
  bool control_error_;
};

}  // namespace

namespace {

/// The problems and options sensitivities are defined for; std::invalid_argument otherwise.
void require_supported(const std::shared_ptr<const RollingProblem>& problem,
                       const RunOptions& options) {
  if (!problem) throw std::invalid_argument("sensitivities: no problem");
  problem->contact.validate();
  if (options.model != ContactModel::kRolling)
    throw std::invalid_argument(
        "sensitivities: contact.model: the rolling model only (the hybrid model's mode changes "
        "and impacts have no sensitivities yet)");
  if (resolve_formulation(*problem, options.formulation) != Formulation::kReduced)
    throw std::invalid_argument(
        "sensitivities: integrator.formulation: the reduced formulation of a disk only");
  if (options.integrator.method == Method::kRungeKutta4)
    throw std::invalid_argument(
        "sensitivities: integrator.method: an adaptive method (dopri5, dop853): the fixed-step "
        "rk4 does not locate the junctions' crossings to the time tolerance");
  polynomial_hand(*problem);
  butterfly_motion(*problem);
}

}  // namespace

RunSensitivities simulate_with_sensitivities(std::shared_ptr<const RollingProblem> problem,
                                             const InitialContact& init, const RunOptions& options,
                                             const SensitivityOptions& sensitivity) {
  require_supported(problem, options);
  const ButterflyMotion& motion = butterfly_motion(*problem);
  RunSensitivities out;
  ReducedDiskSensitivity::State y;
  detail::require_finite(init);
  out.run = detail::run_rolling(ReducedDiskSensitivity(problem, sensitivity.control_error), init,
                                options, &y);
  out.run.formulation = Formulation::kReduced;
  for (int j = 0; j < kParameters; ++j) {
    out.end(0, j) = y[3 + j];
    out.end(1, j) = y[3 + kParameters + j];
  }
  for (const RecordedEvent& e : out.run.events) {
    if (e.kind == EventKind::kJunction) ++out.junction_jumps;
  }
  if (out.run.reason == StopReason::kEndTime && options.t_end > 0) {
    // x(t_end (2T)' / 2T): the state at t_end (before the motion's end jump, where t_end = 2T) plus
    // its rate times d t_end / dp (t_end / 2T for the period).
    const double moves = options.t_end / motion.period();
    ButterflyJacobian m = out.end;
    m(0, kPeriod) += moves * out.run.final.sdot_h;
    m(1, kPeriod) += moves * out.run.final.sddot_h;
    out.scaled_end = m;
  }
  out.breakpoint_jumps = out.run.final.t > motion.period() ? 1 : 0;
  return out;
}

ForceMarginSensitivities force_margin_sensitivities(std::shared_ptr<const RollingProblem> problem,
                                                    const InitialContact& init,
                                                    const RunOptions& options, double t_from,
                                                    double t_to, std::optional<double> mu,
                                                    int pieces) {
  require_supported(problem, options);
  detail::require_finite(init);
  if (!(std::isfinite(t_from) && std::isfinite(t_to) && t_from < t_to))
    throw std::invalid_argument("force margins: the window [" + format_significant(t_from, 9) +
                                ", " + format_significant(t_to, 9) +
                                "] s must be finite and not empty");
  if (t_from < init.t0 || t_to > options.t_end)
    throw std::invalid_argument("force margins: the window [" + format_significant(t_from, 9) +
                                ", " + format_significant(t_to, 9) + "] s is not inside the run [" +
                                format_significant(init.t0, 9) + ", " +
                                format_significant(options.t_end, 9) + "] s");
  if (pieces < 1 || pieces > 1000)
    throw std::invalid_argument("force margins: pieces must be in [1, 1000], got " +
                                std::to_string(pieces));
  if (mu && !(*mu > 0 && std::isfinite(*mu)))
    throw std::invalid_argument("force margins: mu must be positive and finite, got " +
                                format_significant(*mu, 6));
  ForceMarginSensitivities out;
  RunOptions recorded = options;
  recorded.record = true;
  // The recorded run carries its sensitivities: the same run simulate() gives, and d(s_h,
  // sdot_h)/dp at its end without a run of its own (a design needs them at T).
  RunSensitivities whole = simulate_with_sensitivities(problem, init, recorded);
  out.run = std::move(whole.run);
  out.end = whole.end;
  out.runs = 1;
  out.rhs_evals = out.run.stats.rhs_evals;
  if (out.run.final.t < t_to)
    throw std::runtime_error(
        "force margins: the run ended at t = " + format_significant(out.run.final.t, 9) + " s (" +
        to_string(out.run.reason) + "), before the window's end " + format_significant(t_to, 9) +
        " s");
  const ReducedDiskSensitivity model(problem, false);
  // The state and its sensitivities at time t: from one more run with sensitivities (none at the
  // run's start, where the state does not depend on the parameters), each time run once.
  struct StateAt {
    double s, sdot;
    ButterflyJacobian S;
  };
  std::map<double, StateAt> states;
  states.emplace(out.run.final.t, StateAt{out.run.final.s_h, out.run.final.sdot_h, out.end});
  auto state_at = [&](double t) -> const StateAt& {
    if (auto it = states.find(t); it != states.end()) return it->second;
    StateAt x{init.s_h, init.sdot_h, ButterflyJacobian::Zero()};
    if (t > init.t0) {
      RunOptions to_t = options;
      to_t.record = false;
      to_t.t_end = t;
      const RunSensitivities r = simulate_with_sensitivities(problem, init, to_t);
      ++out.runs;
      out.rhs_evals += r.run.stats.rhs_evals;
      x = {r.run.final.s_h, r.run.final.sdot_h, r.end};
    }
    return states.emplace(t, x).first->second;
  };
  // A margin's gradient at its extremum's time. At a motion breakpoint the forces jump; the
  // recorded run's value there is the earlier segment's or the later one's, and `value_of` picks
  // the segment that gives the extremum found.
  using Ratios = ReducedDiskSensitivity::ForceRatios;
  auto margin = [&](double value, double t, auto value_of, auto gradient_of) {
    MarginSensitivity m;
    m.value = value;
    m.t = t;
    if (!std::isfinite(value)) return m;
    const StateAt& x = state_at(t);
    const int hand_piece = problem->hand->piece_at(x.s, x.sdot < 0 ? -1 : 1);
    const int segment = problem->motion->segment_at(t);
    const double tolerance = 1e-6 * std::max(1.0, std::abs(value));
    for (const int motion_segment : {segment, segment - 1}) {
      if (motion_segment < 0) break;
      const Ratios f =
          model.force_ratios(t, x.s, x.sdot, x.S, {.hand = hand_piece, .motion = motion_segment});
      if (std::abs(value_of(f) - value) <= tolerance) {
        m.gradient = gradient_of(f);
        m.fn_ratio = f.fn;
        m.ft_ratio = f.ft;
        return m;
      }
    }
    throw std::runtime_error("force margins: the extremum " + format_significant(value, 9) +
                             " at t = " + format_significant(t, 9) +
                             " s is not what the run's formulas give there (segment " +
                             std::to_string(segment) + ")");
  };
  auto abs_ft_gradient = [](const Ratios& f) -> ParameterGradient {
    return f.ft < 0 ? ParameterGradient(-f.dft) : f.dft;
  };
  for (int i = 0; i < pieces; ++i) {
    WindowMargins w;
    w.t_from = i == 0 ? t_from : t_from + (t_to - t_from) * i / pieces;
    w.t_to = i + 1 == pieces ? t_to : t_from + (t_to - t_from) * (i + 1) / pieces;
    const Extrema x = find_extrema(out.run, w.t_from, w.t_to, options.events.time_tolerance, mu);
    w.fn_min_ratio = margin(
        x.fn_min_ratio, x.t_fn_min, [](const Ratios& f) { return f.fn; },
        [](const Ratios& f) -> ParameterGradient { return f.dfn; });
    // |f_t| / f_n: d = (sgn(f_t) d f_t f_n - |f_t| d f_n) / f_n^2.
    w.mu_required = margin(
        x.mu_required, x.t_mu_required, [](const Ratios& f) { return std::abs(f.ft) / f.fn; },
        [&](const Ratios& f) -> ParameterGradient {
          return (abs_ft_gradient(f) * f.fn - std::abs(f.ft) * f.dfn) / (f.fn * f.fn);
        });
    if (mu)
      w.friction_margin = margin(
          x.friction_margin, x.t_friction_margin,
          [&](const Ratios& f) { return *mu * f.fn - std::abs(f.ft); },
          [&](const Ratios& f) -> ParameterGradient { return *mu * f.dfn - abs_ft_gradient(f); });
    out.windows.push_back(w);
  }
  // The whole window's extrema: its parts' (each part's ends are in it).
  auto pick = [&](MarginSensitivity WindowMargins::*field, bool largest) {
    const MarginSensitivity* best = nullptr;
    for (const WindowMargins& w : out.windows) {
      const MarginSensitivity& m = w.*field;
      if (std::isnan(m.value)) continue;
      if (!best || (largest ? m.value > best->value : m.value < best->value)) best = &m;
    }
    return best ? *best : MarginSensitivity{};
  };
  out.fn_min_ratio = pick(&WindowMargins::fn_min_ratio, false);
  out.mu_required = pick(&WindowMargins::mu_required, true);
  if (mu) out.friction_margin = pick(&WindowMargins::friction_margin, false);
  return out;
}

}  // namespace flatland::sim
