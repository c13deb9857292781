#include "flatland/sim/motion.hpp"

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
  half_period_ = 0.5 * period;
  k_ = k;
  l_ = -(1.0 + 3.0 * k) / 5.0;
  scale_ = std::numbers::pi / (2.0 * p1);
}

HandKinematics ButterflyMotion::at(double t, int segment) const {
  HandKinematics h;
  const double T = half_period_;
  if (segment <= 0) return h;  // resting palm up
  if (segment >= 2) {
    h.angle = std::numbers::pi;
    return h;
  }
  const double u = (t - T) / T, u2 = u * u;
  const double p = u * (1.0 + u2 * (k_ + l_ * u2));
  const double dp = 1.0 + u2 * (3.0 * k_ + 5.0 * l_ * u2);
  const double ddp = u * (6.0 * k_ + 20.0 * l_ * u2);
  h.angle = scale_ * p + 0.5 * std::numbers::pi;
  h.angular_velocity = scale_ * dp / T;
  h.angular_acceleration = scale_ * ddp / (T * T);
  return h;
}

}  // namespace flatland::sim
