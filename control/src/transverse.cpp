#include "flatland/control/transverse.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/format.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace flatland::control {
namespace {

// RK4 on the Riccati equation: sub-steps of at most 0.5 / (its fastest rate), well inside RK4's
// stability bound (2.78); at most this many per grid interval (beyond: the weights are absurd).
constexpr double kRiccatiStepRate = 0.5;
constexpr int kMaxRiccatiSubsteps = 100000;

const char* const kQNames[3] = {"q[0]", "q[1]", "q[2]"};
const char* const kTerminalNames[3] = {"terminal[0]", "terminal[1]", "terminal[2]"};

[[noreturn]] void bad_field(const std::string& field, const std::string& reason, double value) {
  throw std::invalid_argument("controller.transverse." + field + ": " + reason + ", got " +
                              sim::format_significant(value));
}

void check_config(const TransverseConfig& c) {
  for (int i = 0; i < 3; ++i) {
    if (!(c.q[i] >= 0) || !std::isfinite(c.q[i]))
      bad_field(kQNames[i], "must be a finite number >= 0", c.q[i]);
    if (!(c.terminal[i] >= 0) || !std::isfinite(c.terminal[i]))
      bad_field(kTerminalNames[i], "must be a finite number >= 0", c.terminal[i]);
  }
  if (!(c.r > 0) || !std::isfinite(c.r)) bad_field("r", "must be positive", c.r);
  if (!(c.grid_step > 0) || !(c.grid_step <= 0.01))
    bad_field("grid_step", "must be in (0, 0.01] s", c.grid_step);
}

/// The Riccati equation's right-hand side in reversed time, dP/d(-tau).
Eigen::Matrix3d riccati_rate(const TransverseSystem& sys, const Eigen::Matrix3d& P,
                             const Eigen::Matrix3d& Q, double r) {
  const Eigen::Vector3d PB = P * sys.B;
  return sys.A.transpose() * P + P * sys.A - PB * PB.transpose() / r + Q;
}

/// The paper's stages as the transverse law uses them: always in feedback (its dip and finish).
PaperConfig in_feedback(PaperConfig stages) {
  stages.feedback = true;
  return stages;
}

}  // namespace

RollingPartials rolling_partials(const sim::RollingProblem& model, double theta, double theta_dot,
                                 double u, double s_h, double sdot_h) {
  if (!model.hand || !model.object.disk_radius)
    throw std::invalid_argument(
        "controller.transverse: the nominal model must be a disk on a hand");
  if (model.contact.has_losses())
    throw std::invalid_argument(
        "controller.transverse: the nominal model must be lossless (the plan's rolling model)");
  // The lossless rolling equation (docs/DYNAMICS.md) with the pivot fixed:
  //   sddot = -(sigma_s sdot^2 + drive / m) / sigma,  m = 1 + rho^2 / r^2,
  //   drive = g (sin theta T_x + cos theta T_y) + u (perp(q).T - side rho^2 / r) - thetadot^2 q.T
  // where sigma = |J| (1 + r kappa) and q = c + r n is the disk's centre in the hand frame.
  const double r = *model.object.disk_radius;
  const double rho2 = model.object.inertia / model.object.mass;
  const double side = model.hand->normal_side();
  const sim::CurveGeometry g = model.hand->geometry(s_h, model.hand->piece_at(s_h, +1));
  const double one_rk = 1.0 + r * g.curvature;
  const double sigma = g.speed * one_rk;
  const double sigma_s = g.speed_ds * one_rk + g.speed * r * g.curvature_ds;
  const sim::Vec2 q = g.point + r * g.normal;
  const double m = 1.0 + rho2 / (r * r);
  const double c = std::cos(theta), s = std::sin(theta);
  const double gravity_t = model.gravity * (s * g.tangent.x() + c * g.tangent.y());
  const double gravity_t_dtheta = model.gravity * (c * g.tangent.x() - s * g.tangent.y());
  const double lever = sim::perp(q).dot(g.tangent) - side * rho2 / r;
  const double q_t = q.dot(g.tangent);
  const double drive = gravity_t + u * lever - theta_dot * theta_dot * q_t;
  RollingPartials p;
  p.f = -(sigma_s * sdot_h * sdot_h + drive / m) / sigma;
  p.d_theta = -gravity_t_dtheta / (m * sigma);
  p.d_theta_dot = 2.0 * theta_dot * q_t / (m * sigma);
  p.d_u = -lever / (m * sigma);
  p.d_sdot = -2.0 * sigma_s * sdot_h / sigma;
  return p;
}

TransverseSystem transverse_linearisation(const sim::RollingProblem& model, const OrbitPoint& p) {
  if (!(p.sdot_h > 0))
    throw std::invalid_argument(
        "controller.transverse: the planned sdot_h must be positive along the servo stretch, "
        "got " +
        sim::format_significant(p.sdot_h) + " at plan time " + sim::format_significant(p.tau, 4) +
        " s");
  const RollingPartials f =
      rolling_partials(model, p.theta, p.theta_dot, p.theta_ddot, p.s_h, p.sdot_h);
  // tau advances at sdot_h / sdot_h*(tau); e1, e2 are exactly linear, e3 to first order.
  TransverseSystem sys;
  sys.A << 0.0, 1.0, -p.theta_dot / p.sdot_h,  //
      0.0, 0.0, -p.theta_ddot / p.sdot_h,      //
      f.d_theta, f.d_theta_dot, f.d_sdot - p.sddot_h / p.sdot_h;
  sys.B << 0.0, 1.0, f.d_u;
  return sys;
}

TransverseController::TransverseController(TransverseConfig config, PaperConfig stages)
    : config_(config), stages_(in_feedback(stages)) {
  check_config(config_);
}

OrbitPoint TransverseController::orbit(double tau) const {
  if (!plan_) throw std::logic_error("TransverseController::orbit before start");
  const sim::HandKinematics h = plan_->hand(tau);
  OrbitPoint p;
  p.tau = tau;
  p.theta = h.angle;
  p.theta_dot = h.angular_velocity;
  p.theta_ddot = h.angular_acceleration;
  p.s_h = plan_->s_h_at(tau);
  p.sdot_h = plan_->sdot_h_at(tau);
  p.sddot_h = rolling_partials(*model_, p.theta, p.theta_dot, p.theta_ddot, p.s_h, p.sdot_h).f;
  return p;
}

void TransverseController::start(const ControllerContext& context) {
  if (!context.plan) throw std::invalid_argument("controller: no plan");
  if (!context.model) throw std::invalid_argument("controller.transverse: no nominal model");
  stages_.start(context);
  plan_ = context.plan;
  model_ = context.model;
  tau_begin_ = plan_->time_at(plan_->s_from());
  tau_end_ = plan_->time_at(plan_->s_to());
  solve_riccati();
}

void TransverseController::solve_riccati() {
  const double span = tau_end_ - tau_begin_;
  const int n = std::max(1, static_cast<int>(std::ceil(span / config_.grid_step - 1e-9)));
  grid_h_ = span / n;
  const Eigen::Matrix3d Q = Eigen::Vector3d(config_.q[0], config_.q[1], config_.q[2]).asDiagonal();
  Eigen::Matrix3d P =
      Eigen::Vector3d(config_.terminal[0], config_.terminal[1], config_.terminal[2]).asDiagonal();
  const double r = config_.r;
  const auto system = [&](double tau) { return transverse_linearisation(*model_, orbit(tau)); };
  gains_.assign(static_cast<std::size_t>(n) + 1, TransverseGain{});
  const auto store = [&](int i, const TransverseSystem& sys) {
    TransverseGain& g = gains_[static_cast<std::size_t>(i)];
    g.tau = tau_begin_ + grid_h_ * i;
    g.P = P;
    g.K = (sys.B.transpose() * P) / r;
    // The cost-to-go is positive definite when the weights penalise every direction of the error
    // somewhere along the orbit; a P that is not (or not finite) would give a meaningless gain.
    if (!P.allFinite() ||
        Eigen::LLT<Eigen::Matrix3d>(0.5 * (P + P.transpose())).info() != Eigen::Success)
      throw std::invalid_argument(
          "controller.transverse.q: the Riccati solution is not positive definite at plan time " +
          sim::format_significant(g.tau, 4) + " s (make the weights q or terminal positive)");
  };
  TransverseSystem at = system(tau_end_);
  store(n, at);
  // Backwards in tau: classical RK4 on dP/d(-tau) = A^T P + P A - P B B^T P / r + Q. Its
  // linearisation in P is dP' = Acl^T dP + dP Acl with the closed loop Acl = A - B K, so its
  // fastest rate is about 2 |Acl|; each grid interval is cut into sub-steps short against it (a
  // terminal cost far above the stationary one makes |K|, and that rate, large near the end).
  for (int i = n; i > 0; --i) {
    const double tau = tau_begin_ + grid_h_ * i;
    const TransverseSystem end = system(tau - grid_h_);
    const double rate = 2.0 * (at.A - at.B * (at.B.transpose() * P) / r).norm();
    const int substeps = static_cast<int>(std::ceil(grid_h_ * rate / kRiccatiStepRate - 1e-9));
    if (substeps > kMaxRiccatiSubsteps)
      throw std::invalid_argument(
          "controller.transverse.r: the Riccati equation is too stiff at plan time " +
          sim::format_significant(tau, 4) + " s (rate " + sim::format_significant(rate, 3) +
          " 1/s; raise r or lower the terminal weights)");
    const int m = std::max(1, substeps);
    const double h = grid_h_ / m;
    for (int j = 0; j < m; ++j) {
      const double from = tau - h * j;
      const TransverseSystem start = j == 0 ? at : system(from);
      const TransverseSystem mid = system(from - 0.5 * h);
      const TransverseSystem stop = j + 1 == m ? end : system(from - h);
      const Eigen::Matrix3d k1 = riccati_rate(start, P, Q, r);
      const Eigen::Matrix3d k2 = riccati_rate(mid, P + 0.5 * h * k1, Q, r);
      const Eigen::Matrix3d k3 = riccati_rate(mid, P + 0.5 * h * k2, Q, r);
      const Eigen::Matrix3d k4 = riccati_rate(stop, P + h * k3, Q, r);
      P += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    at = end;
    store(i - 1, at);
  }
}

Eigen::RowVector3d TransverseController::gain(double tau) const {
  if (gains_.empty()) throw std::logic_error("TransverseController::gain before start");
  const double x = (tau - tau_begin_) / grid_h_;
  if (!(x > 0)) return gains_.front().K;
  const std::size_t last = gains_.size() - 1;
  if (x >= static_cast<double>(last)) return gains_.back().K;
  const std::size_t i = static_cast<std::size_t>(x);
  const double w = x - static_cast<double>(i);
  return (1.0 - w) * gains_[i].K + w * gains_[i + 1].K;
}

Eigen::Vector3d TransverseController::transverse_error(double theta, double theta_dot, double s_h,
                                                       double sdot_h, double& tau) const {
  if (!plan_) throw std::logic_error("TransverseController::transverse_error before start");
  tau = plan_->time_at(s_h);
  const sim::HandKinematics h = plan_->hand(tau);
  return {theta - h.angle, theta_dot - h.angular_velocity, sdot_h - plan_->sdot_h_at(tau)};
}

ControlOutput TransverseController::step(const ControlInput& input) {
  if (!plan_) throw std::logic_error("TransverseController::step before start");
  // The paper's stage machine decides the stage (and commands the dip, the finish and the hold);
  // in stage 2 its servo command is replaced by the transverse law.
  ControlOutput out = stages_.step(input);
  if (stages_.stage() != Stage::kServo) return out;
  double tau = 0;
  const Eigen::Vector3d e = transverse_error(input.joint.theta, input.joint.theta_dot,
                                             input.estimate.s_h, input.estimate.sdot_h, tau);
  const sim::HandKinematics planned = plan_->hand(tau);
  out.theta_ddot = planned.angular_acceleration - gain(tau).dot(e);
  out.theta_reference = planned.angle;
  return out;
}

}  // namespace flatland::control
