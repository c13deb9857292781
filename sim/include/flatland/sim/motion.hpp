// Hand motions: the input to the rolling dynamics is the hand's pose, velocity and acceleration.
#pragma once

#include "flatland/sim/curve.hpp"

#include <vector>

namespace flatland::sim {

/// Pose of the hand frame in the world (pivot position, angle) and its derivatives (the scalar a
/// template parameter for sensitivities, as BasicCurveJet's).
template <class T>
struct BasicHandKinematics {
  using V = Eigen::Matrix<T, 2, 1>;
  V position = V::Zero();
  V velocity = V::Zero();
  V acceleration = V::Zero();
  T angle = T(0.0);                 ///< rad, 0 = palm up
  T angular_velocity = T(0.0);      ///< rad/s
  T angular_acceleration = T(0.0);  ///< rad/s^2
};
using HandKinematics = BasicHandKinematics<double>;

/// A prescribed hand motion. Implementations: the paper's quintic, a fixed hand; tabulated or
/// controller-driven motions plug in here.
///
/// A motion is smooth between its breakpoints. Like curve pieces, each segment between two
/// breakpoints is evaluated by its own formula (`at(t, segment)`), so that an integration step
/// that ends exactly on a breakpoint still sees the segment it belongs to.
class HandMotion {
 public:
  virtual ~HandMotion() = default;
  /// Kinematics by the formula of `segment` (segment i lies between breakpoints i-1 and i).
  virtual HandKinematics at(double t, int segment) const = 0;
  /// Times where the acceleration is discontinuous (sorted); the integrator stops and restarts.
  virtual std::vector<double> breakpoints() const { return {}; }
  /// Segment containing t: the number of breakpoints <= t (right-continuous).
  int segment_at(double t) const;
  /// Kinematics at t (right limit on a breakpoint).
  HandKinematics at(double t) const { return at(t, segment_at(t)); }
};

/// A hand held still at a fixed pose.
class FixedHand final : public HandMotion {
 public:
  explicit FixedHand(double angle, Vec2 position = Vec2::Zero());
  using HandMotion::at;
  HandKinematics at(double, int) const override { return pose_; }

 private:
  HandKinematics pose_;
};

/// A hand turning about a fixed pivot with its angular acceleration held from t0 on: the motion
/// between two ticks of a joint under digital control (zero-order hold).
class HeldAcceleration final : public HandMotion {
 public:
  HeldAcceleration(double t0, double angle, double angular_velocity, double angular_acceleration)
      : t0_(t0), angle_(angle), rate_(angular_velocity), accel_(angular_acceleration) {}
  using HandMotion::at;
  HandKinematics at(double t, int) const override {
    const double tau = t - t0_;
    HandKinematics h;
    h.angle = angle_ + tau * (rate_ + 0.5 * tau * accel_);
    h.angular_velocity = rate_ + tau * accel_;
    h.angular_acceleration = accel_;
    return h;
  }

 private:
  double t0_, angle_, rate_, accel_;
};

/// The paper's symmetric motion (section 4.2) in normalised time u = (t - T)/T, t in [0, 2T]:
///   theta(t) = pi P(u) / (2 P(1)) + pi/2,  P(u) = j u + k u^3 + l u^5,  j = 1,
/// with l = -(1 + 3k)/5 so that theta'(0) = theta'(2T) = 0. k = -2/3 gives no dip; the dip grows
/// as k decreases; k = -2 makes P(1) = 0 and is rejected. Before 0 the hand rests at 0, after 2T
/// at pi.
class ButterflyMotion final : public HandMotion {
 public:
  /// period = 2T in s. Throws std::invalid_argument on period <= 0 or k = -2 (or non-finite).
  ButterflyMotion(double period, double k);
  using HandMotion::at;
  /// Segment 0: resting palm up (t < 0); 1: the quintic; 2: resting at pi (t >= 2T).
  HandKinematics at(double t, int segment) const override;
  std::vector<double> breakpoints() const override { return {0.0, 2.0 * half_period_}; }
  double period() const { return 2.0 * half_period_; }
  double half_period() const { return half_period_; }
  double k() const { return k_; }
  double l() const { return l_; }

 private:
  double half_period_, k_, l_, scale_;
};

}  // namespace flatland::sim
