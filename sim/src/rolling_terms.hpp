// The formulas of a butterfly's rolling run with the scalar as a template parameter: the polynomial
// hand's outline, its differential geometry, the butterfly motion and the reduced disk's equation
// of motion. The simulator instantiates them with double (PolynomialHand::jet,
// geometry_from_jet, ButterflyMotion::at, ReducedDiskRolling), the sensitivities
// (sensitivity.cpp) with Ceres' Jets, so both differentiate the very arithmetic the run does.
// Internal to sim/.
#pragma once

#include "flatland/sim/curve.hpp"
#include "flatland/sim/motion.hpp"

#include <Eigen/Core>

#include <cmath>
#include <numbers>

namespace flatland::sim::detail {

template <class T>
using Vec2T = Eigen::Matrix<T, 2, 1>;

template <class T>
Vec2T<T> perp_t(const Vec2T<T>& v) {
  return {-v.y(), v.x()};
}

template <class T>
T cross2_t(const Vec2T<T>& a, const Vec2T<T>& b) {
  return a.x() * b.y() - a.y() * b.x();
}

/// The paper's polynomial hand (x = a + c u^2 + e u^4, y = b u + d u^3 + f u^5 with e and f fixed
/// by a, b, c, d), its piece `piece` at s: pieces alternate between the palm's half and its mirror
/// image (x -> -x), u = s - 2 piece or 2 piece - s.
template <class T>
struct PolynomialCoefficients {
  T a, b, c, d, e, f;
};

/// The coefficients with e and f from a, b, c, d (computed once per hand by PolynomialHand).
template <class T>
PolynomialCoefficients<T> polynomial_coefficients(const T& a, const T& b, const T& c, const T& d) {
  return {a, b, c, d, -(a + c), -(b + 3.0 * d) / 5.0};
}

template <class T>
BasicCurveJet<T> polynomial_hand_jet(const PolynomialCoefficients<T>& coefficients, const T& s,
                                     int piece) {
  const auto& [a, b, c, d, e, f] = coefficients;
  const bool mirrored = (piece % 2) != 0;
  const T u = mirrored ? 2.0 * piece - s : s - 2.0 * piece;
  const double du = mirrored ? -1.0 : 1.0;  // du/ds
  const double mx = mirrored ? -1.0 : 1.0;  // x -> -x on the mirrored half
  const T u2 = u * u, u3 = u2 * u, u4 = u2 * u2, u5 = u4 * u;
  const T x0 = a + c * u2 + e * u4;
  const T x1 = 2.0 * c * u + 4.0 * e * u3;
  const T x2 = 2.0 * c + 12.0 * e * u2;
  const T x3 = 24.0 * e * u;
  const T y0 = b * u + d * u3 + f * u5;
  const T y1 = b + 3.0 * d * u2 + 5.0 * f * u4;
  const T y2 = 6.0 * d * u + 20.0 * f * u3;
  const T y3 = 6.0 * d + 60.0 * f * u2;
  BasicCurveJet<T> j;
  j.c = {mx * x0, y0};
  j.d1 = Vec2T<T>(mx * x1, y1) * T(du);
  j.d2 = {mx * x2, y2};
  j.d3 = Vec2T<T>(mx * x3, y3) * T(du);
  return j;
}

/// Differential geometry from a jet; `normal_side` as in Curve::normal_side().
template <class T>
BasicCurveGeometry<T> geometry_of(const BasicCurveJet<T>& jet, int normal_side) {
  const double side = normal_side;
  BasicCurveGeometry<T> g;
  g.point = jet.c;
  g.jacobian = jet.d1;
  g.jacobian_ds = jet.d2;
  g.speed = jet.d1.norm();
  const T inv_speed = 1.0 / g.speed;
  g.tangent = jet.d1 * inv_speed;
  g.normal = perp_t<T>(g.tangent) * T(side);
  g.speed_ds = jet.d1.dot(jet.d2) * inv_speed;
  const T inv_speed3 = inv_speed * inv_speed * inv_speed;
  const T c12 = cross2_t<T>(jet.d1, jet.d2);
  // Signed curvature is positive for a left turn; a body traversed with its outside on the left
  // of travel (normal_side = -1) is convex where it turns left, hence the sign flip.
  g.curvature = -side * c12 * inv_speed3;
  g.curvature_ds = -side * (cross2_t<T>(jet.d1, jet.d3) * inv_speed3 -
                            3.0 * c12 * jet.d1.dot(jet.d2) * inv_speed3 * inv_speed * inv_speed);
  const T ks = g.curvature * g.speed;
  g.normal_ds = g.tangent * ks;
  const Vec2T<T> tangent_ds = (jet.d2 - g.tangent * g.speed_ds) * inv_speed;
  g.normal_dss =
      g.tangent * (g.curvature_ds * g.speed + g.curvature * g.speed_ds) + tangent_ds * ks;
  return g;
}

/// The butterfly motion's coefficients: T = half_period, k, and l and pi / (2 P(1)) from k.
template <class T>
struct ButterflyCoefficients {
  T half_period, k, l, scale;
};

/// Computed once per motion by ButterflyMotion.
template <class T>
ButterflyCoefficients<T> butterfly_coefficients(const T& half_period, const T& k) {
  const T l = -(1.0 + 3.0 * k) / 5.0;                                  // theta'(0) = theta'(2T) = 0
  const T scale = std::numbers::pi / (2.0 * ((4.0 + 2.0 * k) / 5.0));  // pi / (2 P(1))
  return {half_period, k, l, scale};
}

/// The paper's butterfly motion (ButterflyMotion) at t on `segment`: 0 resting palm up (t < 0),
/// 1 the quintic over [0, 2T], 2 resting at pi.
template <class T>
BasicHandKinematics<T> butterfly_kinematics(const ButterflyCoefficients<T>& coefficients,
                                            const T& t, int segment) {
  BasicHandKinematics<T> h;
  if (segment <= 0) return h;  // resting palm up
  if (segment >= 2) {
    h.angle = T(std::numbers::pi);
    return h;
  }
  const auto& [T_, k, l, scale] = coefficients;
  const T u = (t - T_) / T_, u2 = u * u;
  const T p = u * (1.0 + u2 * (k + l * u2));
  const T dp = 1.0 + u2 * (3.0 * k + 5.0 * l * u2);
  const T ddp = u * (6.0 * k + 20.0 * l * u2);
  h.angle = scale * p + 0.5 * std::numbers::pi;
  h.angular_velocity = scale * dp / T_;
  h.angular_acceleration = scale * ddp / (T_ * T_);
  return h;
}

/// The reduced disk's kinematic terms at a contact (docs/DYNAMICS.md): the rolling speed sigma =
/// |J| (1 + r kappa) and its s-derivative, the centre q = c + r n, and the hand's acceleration less
/// gravity in the hand's axes.
template <class T>
struct RollingTerms {
  T sigma, sigma_ds, cos_angle, sin_angle;
  Vec2T<T> q, a_local;
};

template <class T>
RollingTerms<T> rolling_terms(const BasicHandKinematics<T>& h, const BasicCurveGeometry<T>& g,
                              double r, const Eigen::Vector2d& gravity) {
  using std::cos;
  using std::sin;
  RollingTerms<T> k;
  const T one_rk = 1.0 + r * g.curvature;
  k.sigma = g.speed * one_rk;
  k.sigma_ds = g.speed_ds * one_rk + g.speed * r * g.curvature_ds;
  k.q = g.point + g.normal * T(r);
  k.cos_angle = cos(h.angle);
  k.sin_angle = sin(h.angle);
  const T& c = k.cos_angle;
  const T& s = k.sin_angle;
  const Vec2T<T> a = h.acceleration - gravity.template cast<T>();
  k.a_local = {c * a.x() + s * a.y(), -s * a.x() + c * a.y()};  // R^T (a_h - g)
  return k;
}

/// The generalised force of the lossless rolling along the contact parameter, per unit mass:
/// the hand's acceleration, its angular acceleration and its centripetal term, and the disk's own
/// inertia (rho2 = I / m, side = the side of the hand the disk rolls on).
template <class T>
T rolling_drive(const BasicHandKinematics<T>& h, const BasicCurveGeometry<T>& g,
                const RollingTerms<T>& k, double r, double rho2, double side) {
  const T th2 = h.angular_velocity * h.angular_velocity;
  return k.a_local.dot(g.tangent) + h.angular_acceleration * perp_t<T>(k.q).dot(g.tangent) -
         th2 * k.q.dot(g.tangent) - side * rho2 / r * h.angular_acceleration;
}

/// s_h'' from the terms and the drive (with the losses' part added by the caller when set).
template <class T>
T rolling_sddot(const RollingTerms<T>& k, const T& drive, const T& sdot, double r, double rho2) {
  return -(k.sigma_ds * sdot * sdot + drive / (1.0 + rho2 / (r * r))) / k.sigma;
}

/// R^T (p'' - g): the disk centre's acceleration less gravity, in the hand's axes, for a centre
/// moving on the offset curve with s_h' = sdot and s_h'' = sdd (docs/DYNAMICS.md). Times the mass
/// it is the hand's contact force on the rolling disk without drag: its normal and tangential
/// components are the force's.
template <class T>
Vec2T<T> relative_acceleration(const BasicHandKinematics<T>& h, const BasicCurveGeometry<T>& g,
                               const RollingTerms<T>& k, const T& sdot, const T& sdd) {
  const T& w = h.angular_velocity;
  const T ssd = k.sigma * sdot;
  return k.a_local + perp_t<T>(k.q) * h.angular_acceleration - k.q * (w * w) +
         perp_t<T>(g.tangent) * (2.0 * w * ssd) +
         (g.tangent * k.sigma_ds - g.normal * (k.sigma * g.curvature * g.speed)) * sdot * sdot +
         g.tangent * (k.sigma * sdd);
}

}  // namespace flatland::sim::detail
