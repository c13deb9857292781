// Spatial rolling: a rigid object rolling on a rigid hand surface in 3-D, the paper's equations
// (1)-(4) in their spatial form assembled as A x = b, 11 x 10, with the hand's linear and angular
// acceleration as input. This header has the instantaneous dynamics (assemble and solve at one
// state); spatial_run.hpp integrates them in time, spatial_spec.hpp builds them from a scene.
//
// Unknowns x = (a_o, alpha_o, sddot_o, sddot_h): the object's linear and angular acceleration
// (world frame) and the accelerations of the contact coordinates on the object and on the hand.
// Rows: (1) the contact points coincide (3), (2) the normals are opposite (3, one redundant: the
// normals are unit), (3) rolling: the tangential part of the time derivative of "the two material
// points at the contact have the same velocity" (2), (4) Newton-Euler about the centre of mass
// with the contact force through the contact point and gravity (3). The hard contact transmits
// no torque about the normal, so spin about the normal is free; slip is disallowed.
//
// Row (3) is the exact derivative of the rolling velocity constraint, which keeps the terms
// omega x w (w the contact point's velocity over each body's surface). The paper's printed row (3)
// leaves them out; they vanish in the plane (omega is normal to the plane and w lies in it, so
// their product is along the normal), but not with spin about the normal in space (a ball on a
// turntable, docs/DYNAMICS.md), whose closed form the tests check.
#pragma once

#include "flatland/sim/surface.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <optional>

namespace flatland::sim {

/// A rigid object: its surface in its own frame (centre of mass at the origin), mass and inertia.
struct SpatialObject {
  SurfacePtr surface;
  double mass = 1.0;                                      ///< kg
  Eigen::Matrix3d inertia = Eigen::Matrix3d::Identity();  ///< kg m^2, object frame, about the COM
};
/// A uniform ball: I = 2/5 m r^2. std::invalid_argument for a non-positive radius or mass.
SpatialObject uniform_ball(double radius, double mass = 1.0);
/// A uniform solid ellipsoid: I = m/5 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2).
SpatialObject uniform_ellipsoid(double a, double b, double c, double mass = 1.0);

/// What the spatial equations need besides the state: the hand's surface (in the hand frame), the
/// object, gravity (world frame, m/s^2) and the static friction coefficient (a run stops where
/// the contact would slip; absent: unlimited, the required coefficient is still reported).
struct SpatialRollingProblem {
  SurfacePtr hand;
  SpatialObject object;
  Vec3 gravity = Vec3(0, 0, -9.8);
  std::optional<double> mu;
};

/// The hand frame's pose and its derivatives at one instant, world frame: x_w = x + R x_hand.
struct HandPose3 {
  Vec3 position = Vec3::Zero(), velocity = Vec3::Zero(), acceleration = Vec3::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Vec3 angular_velocity = Vec3::Zero(), angular_acceleration = Vec3::Zero();
};

/// The object's state in contact: pose, velocities (world frame) and the contact coordinates on
/// the object's and the hand's surfaces with their rates.
struct SpatialState {
  Vec3 position = Vec3::Zero();                                     ///< centre of mass, m
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  ///< object -> world
  Vec3 velocity = Vec3::Zero(), angular_velocity = Vec3::Zero();
  SurfaceParam s_o = SurfaceParam::Zero(), s_h = SurfaceParam::Zero();
  SurfaceParam sdot_o = SurfaceParam::Zero(), sdot_h = SurfaceParam::Zero();
};

/// The assembled system at one state and its least-squares solution (Householder QR with column
/// pivoting): the accelerations, the residual of the redundant row, the contact force.
struct SpatialSolution {
  Eigen::Matrix<double, 11, 10> A;
  Eigen::Matrix<double, 11, 1> b;
  Eigen::Matrix<double, 10, 1> x;
  Vec3 acceleration, angular_acceleration;  ///< a_o, alpha_o (world)
  SurfaceParam sddot_o, sddot_h;
  double residual =
      0;         ///< |A x - b| (rows scaled to m/s^2): 0 up to rounding at a consistent state
  int rank = 0;  ///< of A (10 unless the contact is degenerate)
  Vec3 force;    ///< N: the hand's contact force on the object, m (a_o - g), world
  double force_normal = 0;  ///< N, along the hand's outward normal (> 0: pushes)
  Vec3 force_tangential;    ///< N, in the tangent plane
  double mu_required = 0;   ///< |f_t| / f_n (inf where f_n <= 0)
  /// W: the contact force's power on the object, f . (v + omega x r_o): all of it the hand's
  /// (rolling without losses), the energy audit's integrand (flatland/sim/energy.hpp).
  double power = 0;
};

/// Assemble A x = b at `state` with the hand at `hand` and solve it. std::invalid_argument (naming
/// the contact coordinates) when A is rank deficient: the object's and the hand's curvatures match
/// there (a conforming contact the rolling equations cannot resolve) or a chart is singular.
SpatialSolution solve_spatial_rolling(const SpatialRollingProblem& problem, const HandPose3& hand,
                                      const SpatialState& state);

/// (v x): the cross-product matrix.
inline Eigen::Matrix3d cross_matrix(const Vec3& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

}  // namespace flatland::sim
