#include "flatland/control/estimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace flatland::control {

Ekf::Ekf(std::shared_ptr<const sim::RollingProblem> model, EstimatorConfig config)
    : RollingFilter(std::move(model), config) {}

void Ekf::substep(double /*t*/, double h, const HandInput& u, Eigen::Vector2d& x,
                  Eigen::Matrix2d& P) const {
  const double q2 = config().process_noise * config().process_noise;
  if (config().model == EstimatorModel::kConstantVelocity) {
    // Exact: x+ = Phi x with Phi = [1 h; 0 1].
    x[0] += h * x[1];
    Eigen::Matrix2d Phi;
    Phi << 1.0, h, 0.0, 1.0;
    P = Phi * P * Phi.transpose() + process_covariance(q2, h);
    return;
  }
  const double s = x[0], v = x[1];
  const int piece = disk().piece_at(s, v);

  // F = df/dx at the sub-step's start, before the mean moves. d/ds by a forward difference (s is
  // O(1), so 1e-7 balances truncation against round-off to ~1e-8 relative); d/dsdot by a central
  // difference: sddot is quadratic in sdot (the Coriolis term drops out along the tangent), so
  // the central difference is exact up to round-off whatever its step. One hand piece for all.
  sim::HandKinematics hk;
  hk.angle = u.theta;
  hk.angular_velocity = u.theta_dot;
  hk.angular_acceleration = u.theta_ddot;
  constexpr double ds = 1e-7;
  const double dv = 1e-3 * std::max(1.0, std::abs(v));
  const double a0 = disk().acceleration(hk, s, v, piece);
  const double a_s = (disk().acceleration(hk, s + ds, v, piece) - a0) / ds;
  const double a_v =
      (disk().acceleration(hk, s, v + dv, piece) - disk().acceleration(hk, s, v - dv, piece)) /
      (2.0 * dv);

  // The mean: RK4 on the hand's piece, cut at a junction (DiskOnHand::step).
  disk().step(h, u, piece, x);

  Eigen::Matrix2d F;
  F << 0.0, 1.0, a_s, a_v;
  // Phi = exp(F h) to second order: the neglected h^3 F^3 / 6 is ~1e-9 at 1 ms even with the
  // fingertip's instability rate (a_s ~ 10 / s^2 on the air table).
  const Eigen::Matrix2d Fh = F * h;
  const Eigen::Matrix2d Phi = Eigen::Matrix2d::Identity() + Fh + 0.5 * Fh * Fh;
  P = Phi * P * Phi.transpose() + process_covariance(q2, h);
}

double nees(const Estimate& e, double s_h_true, double sdot_h_true) {
  const double e0 = s_h_true - e.s_h, e1 = sdot_h_true - e.sdot_h;
  const Eigen::Matrix2d& P = e.covariance;
  const double det = P(0, 0) * P(1, 1) - P(0, 1) * P(1, 0);
  if (!(det > 0)) return std::numeric_limits<double>::infinity();
  // e^T P^-1 e with the 2 x 2 inverse written out (P symmetric).
  return (e0 * e0 * P(1, 1) - e0 * e1 * (P(0, 1) + P(1, 0)) + e1 * e1 * P(0, 0)) / det;
}

}  // namespace flatland::control
