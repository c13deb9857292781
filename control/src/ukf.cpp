#include "flatland/control/ukf.hpp"
#include "flatland/sim/format.hpp"

#include <Eigen/Cholesky>

#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace flatland::control {

namespace {

constexpr int kStateSize = 2;  // (s_h, sdot_h)

// Below this alpha the weights grow past 1e8 and the recombined covariance's rounding (the
// weights times the points' squared deviations) reaches the measurement's variance.
constexpr double kMinAlpha = 1e-4;

void require(bool ok, const char* field, const std::string& rule, double v) {
  if (!ok)
    throw std::invalid_argument(std::string("estimator.ukf.") + field + ": must be " + rule +
                                ", got " + sim::format_significant(v));
}

const UkfConfig& checked(const UkfConfig& c) {
  require(std::isfinite(c.alpha) && c.alpha >= kMinAlpha && c.alpha <= 1.0, "alpha",
          "in [" + sim::format_number(kMinAlpha) + ", 1]", c.alpha);
  require(std::isfinite(c.beta) && c.beta >= 0, "beta", "finite and >= 0", c.beta);
  require(std::isfinite(c.kappa) && c.kappa >= 0, "kappa", "finite and >= 0", c.kappa);
  return c;
}

}  // namespace

Ukf::Ukf(std::shared_ptr<const sim::RollingProblem> model, EstimatorConfig config,
         UkfConfig sigma_points)
    : RollingFilter(std::move(model), config), sigma_points_(checked(sigma_points)) {
  const double n = kStateSize;
  const double a2 = sigma_points_.alpha * sigma_points_.alpha;
  const double n_plus_lambda = a2 * (n + sigma_points_.kappa);
  const double lambda = n_plus_lambda - n;
  spread_ = std::sqrt(n_plus_lambda);
  // The centre's mean weight, lambda / (n + lambda), is 1 minus the others' (substep()).
  covariance_weight_centre_ = lambda / n_plus_lambda + 1.0 - a2 + sigma_points_.beta;
  weight_ = 1.0 / (2.0 * n_plus_lambda);
}

void Ukf::substep(double t, double h, const HandInput& u, Eigen::Vector2d& x,
                  Eigen::Matrix2d& P) const {
  const Eigen::LLT<Eigen::Matrix2d> llt(P);
  if (llt.info() != Eigen::Success) {
    std::ostringstream out;
    out << "estimator: covariance not positive definite at t = " << t << " (s_h = " << x[0]
        << "): the unscented filter has no sigma points";
    throw std::runtime_error(out.str());
  }
  const Eigen::Matrix2d L = spread_ * llt.matrixL().toDenseMatrix();
  constexpr int kPoints = 2 * kStateSize + 1;
  std::array<Eigen::Vector2d, kPoints> points;
  points[0] = x;
  for (int j = 0; j < kStateSize; ++j) {
    points[1 + j] = x + L.col(j);
    points[1 + kStateSize + j] = x - L.col(j);
  }
  const bool rolling = config().model == EstimatorModel::kRolling;
  for (Eigen::Vector2d& p : points) {
    if (rolling)
      disk().step(h, u, disk().piece_at(p[0], p[1]), p);  // each point on its own piece
    else
      p[0] += h * p[1];
  }
  // The mean as the centre plus the weighted deviations from it: the same sum (the weights add up
  // to 1), without the cancellation of a large negative centre weight against the others when
  // alpha is small.
  Eigen::Vector2d mean = points[0];
  for (int i = 1; i < kPoints; ++i) mean += weight_ * (points[i] - points[0]);
  Eigen::Matrix2d covariance =
      process_covariance(config().process_noise * config().process_noise, h);
  const Eigen::Vector2d d0 = points[0] - mean;
  covariance += covariance_weight_centre_ * d0 * d0.transpose();
  for (int i = 1; i < kPoints; ++i) {
    const Eigen::Vector2d d = points[i] - mean;
    covariance += weight_ * d * d.transpose();
  }
  x = mean;
  P = covariance;
}

}  // namespace flatland::control
