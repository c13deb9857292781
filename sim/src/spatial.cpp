// Spatial rolling: A x = b (11 x 10) at one state (spatial.hpp has the equations' layout).
#include "flatland/sim/spatial.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace flatland::sim {

SpatialObject uniform_ball(double radius, double mass) {
  if (!std::isfinite(radius) || !(radius > 0))
    throw std::invalid_argument("ball: radius must be positive and finite");
  if (!std::isfinite(mass) || !(mass > 0))
    throw std::invalid_argument("ball: mass must be positive and finite");
  SpatialObject o;
  o.surface = std::make_shared<EllipsoidSurface>(
      EllipsoidSurface::sphere(radius, EllipsoidSurface::Side::kConvexBody));
  o.mass = mass;
  o.inertia = Eigen::Matrix3d::Identity() * (0.4 * mass * radius * radius);
  return o;
}

SpatialObject uniform_ellipsoid(double a, double b, double c, double mass) {
  if (!std::isfinite(mass) || !(mass > 0))
    throw std::invalid_argument("ellipsoid: mass must be positive and finite");
  SpatialObject o;
  o.surface = std::make_shared<EllipsoidSurface>(a, b, c, EllipsoidSurface::Side::kConvexBody);
  o.mass = mass;
  o.inertia = Eigen::Vector3d(b * b + c * c, a * a + c * c, a * a + b * b).asDiagonal();
  o.inertia *= mass / 5;
  return o;
}

namespace {

/// A surface's geometry turned into the world by R: position (relative to the body's origin), J,
/// normal, K, and J-dot sdot, K-dot sdot.
struct WorldGeometry {
  Vec3 r, n;
  Mat32 J, K;
  Vec3 Jdot_sdot, Kdot_sdot;
};

WorldGeometry to_world(const SurfaceGeometry& g, const Eigen::Matrix3d& R,
                       const SurfaceParam& sdot) {
  WorldGeometry w;
  w.r = R * g.point;
  w.n = R * g.normal;
  w.J = R * g.jacobian;
  w.K = R * g.curvature_form;
  const Mat32 Jdot = g.jacobian_ds[0] * sdot.x() + g.jacobian_ds[1] * sdot.y();
  const Mat32 Kdot = g.curvature_form_ds[0] * sdot.x() + g.curvature_form_ds[1] * sdot.y();
  w.Jdot_sdot = R * (Jdot * sdot);
  w.Kdot_sdot = R * (Kdot * sdot);
  return w;
}

}  // namespace

SpatialSolution solve_spatial_rolling(const SpatialRollingProblem& pb, const HandPose3& hand,
                                      const SpatialState& st) {
  const Eigen::Matrix3d Ro = st.orientation.normalized().toRotationMatrix();
  const Eigen::Matrix3d& Rh = hand.rotation;
  const WorldGeometry h = to_world(pb.hand->geometry(st.s_h), Rh, st.sdot_h);
  const WorldGeometry o = to_world(pb.object.surface->geometry(st.s_o), Ro, st.sdot_o);
  const Vec3& wh_ = hand.angular_velocity;
  const Vec3& ah_ = hand.angular_acceleration;
  const Vec3& wo = st.angular_velocity;
  const Vec3 w_h = h.J * st.sdot_h;  // the contact point's velocity over the hand's surface
  const Vec3 w_o = o.J * st.sdot_o;  // ... and over the object's
  // The hand's material point at the contact: its acceleration.
  const Vec3 A_h = hand.acceleration + ah_.cross(h.r) + wh_.cross(wh_.cross(h.r));
  const Eigen::Matrix3d Iw = Ro * pb.object.inertia * Ro.transpose();
  const double m = pb.object.mass;

  SpatialSolution s;
  s.A.setZero();
  s.b.setZero();
  // Columns: a_o 0-2, alpha_o 3-5, sddot_o 6-7, sddot_h 8-9.
  // (1) the contact points coincide, differentiated twice.
  s.A.block<3, 3>(0, 0) = -Eigen::Matrix3d::Identity();
  s.A.block<3, 3>(0, 3) = cross_matrix(o.r);  // -alpha_o x r_o = r_o x alpha_o
  s.A.block<3, 2>(0, 6) = -o.J;
  s.A.block<3, 2>(0, 8) = h.J;
  s.b.segment<3>(0) = -(A_h + 2 * wh_.cross(w_h) + h.Jdot_sdot) +
                      (wo.cross(wo.cross(o.r)) + 2 * wo.cross(w_o) + o.Jdot_sdot);
  // (2) the normals are opposite, differentiated twice.
  s.A.block<3, 3>(3, 3) = -cross_matrix(o.n);  // alpha_o x n_o = -n_o x alpha_o
  s.A.block<3, 2>(3, 6) = o.K;
  s.A.block<3, 2>(3, 8) = h.K;
  s.b.segment<3>(3) =
      -(wo.cross(wo.cross(o.n)) + 2 * wo.cross(o.K * st.sdot_o) + o.Kdot_sdot + ah_.cross(h.n) +
        wh_.cross(wh_.cross(h.n)) + 2 * wh_.cross(h.K * st.sdot_h) + h.Kdot_sdot);
  // (3) rolling: the material points' velocities stay equal; the tangential part of
  // a_o + alpha_o x r_o + w_o x (w_o x r_o) + w_o x w_o' = A_h + w_h x w_h' (w' the contact
  // point's velocity over each surface).
  const Eigen::Matrix<double, 2, 3> T = h.J.transpose();
  s.A.block<2, 3>(6, 0) = -T;
  s.A.block<2, 3>(6, 3) = T * cross_matrix(o.r);
  s.b.segment<2>(6) = -T * (A_h + wh_.cross(w_h) - wo.cross(wo.cross(o.r)) - wo.cross(w_o));
  // (4) Newton-Euler about the centre of mass: I alpha + w x I w = r_o x m (a_o - g), scaled by
  // 1 / (m |r_o|) to m/s^2 like the other rows.
  const double scale = 1 / (m * std::max(o.r.norm(), 1e-12));
  s.A.block<3, 3>(8, 0) = -m * cross_matrix(o.r) * scale;
  s.A.block<3, 3>(8, 3) = Iw * scale;
  s.b.segment<3>(8) = (-wo.cross(Iw * wo) - m * o.r.cross(pb.gravity)) * scale;

  const Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 11, 10>> qr(s.A);
  s.rank = static_cast<int>(qr.rank());
  if (s.rank < 10)
    throw std::invalid_argument(
        "spatial rolling: A x = b is rank deficient (rank " + std::to_string(s.rank) +
        " of 10) at s_h = (" + format_significant(st.s_h.x()) + ", " +
        format_significant(st.s_h.y()) + "), s_o = (" + format_significant(st.s_o.x()) + ", " +
        format_significant(st.s_o.y()) +
        "): the object's and the hand's curvatures match there, or a chart is singular");
  s.x = qr.solve(s.b);
  s.residual = (s.A * s.x - s.b).norm();
  s.acceleration = s.x.segment<3>(0);
  s.angular_acceleration = s.x.segment<3>(3);
  s.sddot_o = s.x.segment<2>(6);
  s.sddot_h = s.x.segment<2>(8);
  s.force = m * (s.acceleration - pb.gravity);
  s.force_normal = s.force.dot(h.n);
  s.force_tangential = s.force - s.force_normal * h.n;
  s.mu_required = s.force_normal > 0 ? s.force_tangential.norm() / s.force_normal
                                     : std::numeric_limits<double>::infinity();
  // d/dt (m |v|^2 / 2 + omega . I omega / 2) = f . v + omega . (r_o x f) by rows (4).
  s.power = s.force.dot(st.velocity + wo.cross(o.r));
  return s;
}

}  // namespace flatland::sim
