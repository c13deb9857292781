// The unscented Kalman filter on (s_h, sdot_h) (type `ukf`): the same rolling model, process
// noise, latency compensation and errors as the extended filter (estimator.hpp; both are
// RollingFilter, rolling_filter.hpp), but the belief crosses each step as a set of sigma points
// pushed through the model's step map instead of through its Jacobian at the mean. Each point
// takes the hand piece its own s_h is on, so a belief straddling a junction of the hand (where
// sddot_h jumps) is propagated on both sides of it, which a linearisation at the mean cannot do.
// The measurement (s_h itself) is linear, so the update is the Kalman update: the unscented
// transform of a linear map is exact.
//
// Sigma points: the scaled unscented transform (Julier 2002; Wan and van der Merwe 2000) with
// n = 2: lambda = alpha^2 (n + kappa) - n, points x and x +- sqrt(n + lambda) L_j (L the Cholesky
// factor of P), mean weights lambda / (n + lambda) and 1 / (2 (n + lambda)), the centre's
// covariance weight lambda / (n + lambda) + 1 - alpha^2 + beta. docs/ESTIMATOR.md compares it
// with the EKF.
#pragma once

#include "flatland/control/rolling_filter.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>

namespace flatland::control {

/// The sigma points' spread and weights (scene section `estimator.ukf`). The defaults put the
/// points at +-sqrt(3) sigma (n + kappa = 3 matches a Gaussian's fourth moment, Julier and
/// Uhlmann 1997) with every weight positive, so the predicted covariance stays positive
/// semidefinite; beta = 2 is optimal for a Gaussian prior.
struct UkfConfig {
  double alpha = 1.0;  ///< scales the spread, in [1e-4, 1]
  double beta = 2.0;   ///< prior knowledge of the distribution (2: Gaussian), >= 0
  double kappa = 1.0;  ///< secondary scaling, >= 0
};

/// The unscented Kalman filter (type `ukf`).
class Ukf final : public RollingFilter {
 public:
  /// As Ekf's constructor; also std::invalid_argument naming `estimator.ukf.FIELD` for a bad
  /// sigma-point parameter.
  Ukf(std::shared_ptr<const sim::RollingProblem> model, EstimatorConfig config,
      UkfConfig sigma_points = {});
  std::string name() const override { return "ukf"; }
  const UkfConfig& sigma_points() const { return sigma_points_; }

 private:
  /// The sigma points of (x, P) through the step map over h, recombined, plus Q. Throws
  /// std::runtime_error if P is not positive definite (no sigma points exist).
  void substep(double t, double h, const HandInput& u, Eigen::Vector2d& x,
               Eigen::Matrix2d& P) const override;

  UkfConfig sigma_points_;
  double spread_ = 0;                    ///< sqrt(n + lambda)
  double covariance_weight_centre_ = 0;  ///< lambda / (n + lambda) + 1 - alpha^2 + beta
  double weight_ = 0;                    ///< of every other point: 1 / (2 (n + lambda))
};

}  // namespace flatland::control
