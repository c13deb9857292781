#include "flatland/sim/sensitivity.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/rolling.hpp"
#include "rolling_run.hpp"
#include "rolling_terms.hpp"

#include <ceres/jet.h>

#include <cmath>
#include <stdexcept>
#include <string>

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

  ReducedDiskSensitivity(std::shared_ptr<const RollingProblem> problem, bool control_error)
      : base_(problem),
        hand_(polynomial_hand(*problem)),
        motion_(butterfly_motion(*problem)),
        r_(*problem->object.disk_radius),
        rho2_(problem->object.inertia / problem->object.mass),
        side_(problem->hand->normal_side()),
        gravity_(problem->gravity_vector()),
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
  /// s_h'' by the run's formulas (rolling_terms.hpp) in any scalar. Flattened: GCC 12 at -O3 left
  /// the Jets' 8-wide Eigen assignments as calls, half of a run's time (a run with sensitivities
  /// 6.1 ms, 1.6 ms flattened, against 0.37 ms without).
  template <class T>
  FLATLAND_FLATTEN T sddot(const T& t, const T& s, const T& sdot, const T& a, const T& b,
                           const T& c, const T& d, const T& k, const T& period,
                           const Pieces& p) const {
    const BasicCurveGeometry<T> g = detail::geometry_of(
        detail::polynomial_hand_jet(detail::polynomial_coefficients(a, b, c, d), s, p.hand),
        hand_.normal_side());
    const BasicHandKinematics<T> h = detail::butterfly_kinematics(
        detail::butterfly_coefficients(T(0.5) * period, k), t, p.motion);
    const detail::RollingTerms<T> terms = detail::rolling_terms(h, g, r_, gravity_);
    const T drive = detail::rolling_drive(h, g, terms, r_, rho2_, side_);
    return detail::rolling_sddot(terms, drive, sdot, r_, rho2_);
  }

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
  bool control_error_;
};

}  // namespace

RunSensitivities simulate_with_sensitivities(std::shared_ptr<const RollingProblem> problem,
                                             const InitialContact& init, const RunOptions& options,
                                             const SensitivityOptions& sensitivity) {
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
  if (out.run.reason == StopReason::kEndTime && options.t_end == motion.period()) {
    // x(2T(p)): the state at 2T- plus its rate times d(2T)/dp (1 for the period).
    ButterflyJacobian m = out.end;
    m(0, kPeriod) += out.run.final.sdot_h;
    m(1, kPeriod) += out.run.final.sddot_h;
    out.motion_end = m;
  }
  out.breakpoint_jumps = out.run.final.t > motion.period() ? 1 : 0;
  return out;
}

}  // namespace flatland::sim
