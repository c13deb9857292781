#include "flatland/sim/motion.hpp"

#include "rolling_terms.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace flatland::sim {

int HandMotion::segment_at(double t) const {
  int n = 0;
  for (double b : breakpoints())
    if (b <= t) ++n;
  return n;
}

FixedHand::FixedHand(double angle, Vec2 position) {
  if (!std::isfinite(angle) || !position.allFinite())
    throw std::invalid_argument("motion.angle: must be finite");
  pose_.angle = angle;
  pose_.position = position;
}

ButterflyMotion::ButterflyMotion(double period, double k) {
  if (!std::isfinite(period) || !(period > 0))
    throw std::invalid_argument("motion.period: must be positive and finite (2T in s), got " +
                                std::to_string(period));
  if (!std::isfinite(k)) throw std::invalid_argument("motion.k: must be finite");
  const double p1 = (4.0 + 2.0 * k) / 5.0;  // P(1) with l = -(1 + 3k)/5
  if (std::abs(p1) < 1e-9)
    throw std::invalid_argument("motion.k: k = -2 makes P(1) = 0 (the motion is undefined)");
  const auto coefficients = detail::butterfly_coefficients(0.5 * period, k);
  half_period_ = coefficients.half_period;
  k_ = k;
  l_ = coefficients.l;
  scale_ = coefficients.scale;
}

HandKinematics ButterflyMotion::at(double t, int segment) const {
  return detail::butterfly_kinematics(
      detail::ButterflyCoefficients<double>{half_period_, k_, l_, scale_}, t, segment);
}

}  // namespace flatland::sim
