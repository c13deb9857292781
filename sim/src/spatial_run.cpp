// Spatial rolling in time: hand motions in SE(3), Dormand-Prince 5(4) on the 21 state values
// (position 3, orientation quaternion 4, velocity 3, angular velocity 3, s_o, s_h, sdot_o, sdot_h)
// with the projection onto the contact manifold after every accepted step, and the ball's chart
// turned away from its poles.
#include "flatland/sim/spatial_run.hpp"

#include "dopri5_tableau.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace flatland::sim {

// ---- motions
// -------------------------------------------------------------------------------------

FixedHand3::FixedHand3(Eigen::Matrix3d rotation, Vec3 position) {
  pose_.rotation = rotation;
  pose_.position = position;
}

HandPose3 FixedHand3::at(double) const { return pose_; }

SpinningHand3::SpinningHand3(Vec3 axis, double rate, Vec3 point, Eigen::Matrix3d rotation0)
    : axis_(axis.normalized()), point_(point), rate_(rate), rotation0_(rotation0) {
  if (!(axis.norm() > 0) || !axis.allFinite() || !std::isfinite(rate) || !point.allFinite())
    throw std::invalid_argument(
        "spinning hand: the axis must be a finite non-zero vector and "
        "the rate and point finite");
}

HandPose3 SpinningHand3::at(double t) const {
  HandPose3 p;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(rate_ * t, axis_).toRotationMatrix();
  p.rotation = R * rotation0_;
  // x(t) = point - R (point): the point on the axis stays put.
  p.position = point_ - R * point_;
  p.angular_velocity = rate_ * axis_;
  p.velocity = p.angular_velocity.cross(p.position - point_);
  p.acceleration = p.angular_velocity.cross(p.velocity);
  return p;
}

std::string SpinningHand3::describe() const {
  return "hand spinning at " + format_significant(rate_) + " rad/s";
}

std::string to_string(SpatialStop s) {
  switch (s) {
    case SpatialStop::kEndTime:
      return "end_time";
    case SpatialStop::kContactLost:
      return "contact_lost";
    case SpatialStop::kLeftPatch:
      return "left_patch";
  }
  return "?";
}

double spatial_energy(const SpatialRollingProblem& pb, const SpatialState& s) {
  const Eigen::Matrix3d R = s.orientation.normalized().toRotationMatrix();
  const double m = pb.object.mass;
  return 0.5 * m * s.velocity.squaredNorm() +
         0.5 * s.angular_velocity.dot(R * pb.object.inertia * R.transpose() * s.angular_velocity) -
         m * pb.gravity.dot(s.position);
}

namespace {

constexpr int kN = 21;
using Y = Eigen::Matrix<double, kN, 1>;

using namespace detail;  // the Dormand-Prince 5(4) tableau

/// The run's equations. The object's orientation in the state is its chart frame's, R_c = R_o C:
/// the frame in which its surface is parameterised. For a ball the chart can be turned (C changes,
/// the ball does not), which keeps the contact away from the chart's poles.
class SpatialIntegration {
 public:
  SpatialIntegration(const SpatialRollingProblem& pb, const HandMotion3& motion)
      : pb_(pb), chart_pb_(pb), motion_(motion) {
    const auto* e = dynamic_cast<const EllipsoidSurface*>(pb.object.surface.get());
    if (e) {
      const Vec3 ax = e->semi_axes();
      ball_radius_ = ax.x() == ax.y() && ax.y() == ax.z() ? ax.x() : 0.0;
    }
  }

  Y pack(const SpatialState& s) const {
    Y y;
    y.segment<3>(0) = s.position;
    const Eigen::Quaterniond q = s.orientation.normalized();
    y.segment<4>(3) << q.w(), q.x(), q.y(), q.z();
    y.segment<3>(7) = s.velocity;
    y.segment<3>(10) = s.angular_velocity;
    y.segment<2>(13) = s.s_o;
    y.segment<2>(15) = s.s_h;
    y.segment<2>(17) = s.sdot_o;
    y.segment<2>(19) = s.sdot_h;
    return y;
  }

  static SpatialState unpack(const Y& y) {
    SpatialState s;
    s.position = y.segment<3>(0);
    s.orientation = Eigen::Quaterniond(y[3], y[4], y[5], y[6]).normalized();
    s.velocity = y.segment<3>(7);
    s.angular_velocity = y.segment<3>(10);
    s.s_o = y.segment<2>(13);
    s.s_h = y.segment<2>(15);
    s.sdot_o = y.segment<2>(17);
    s.sdot_h = y.segment<2>(19);
    return s;
  }

  /// dy = f(t, y); returns the solution it came from (its forces and residual, for the sample).
  SpatialSolution rhs(double t, const Y& y, Y& dy) {
    ++stats.rhs_evals;
    const SpatialState s = unpack(y);
    const SpatialSolution x = solve_spatial_rolling(chart_pb_, motion_.at(t), s);
    dy.segment<3>(0) = s.velocity;
    // q' = (1/2) (0, w) q, w in the world frame.
    const Eigen::Quaterniond q(y[3], y[4], y[5], y[6]);
    const Eigen::Quaterniond w(0, s.angular_velocity.x(), s.angular_velocity.y(),
                               s.angular_velocity.z());
    const Eigen::Quaterniond qd = w * q;
    dy.segment<4>(3) << 0.5 * qd.w(), 0.5 * qd.x(), 0.5 * qd.y(), 0.5 * qd.z();
    dy.segment<3>(7) = x.acceleration;
    dy.segment<3>(10) = x.angular_acceleration;
    dy.segment<2>(13) = s.sdot_o;
    dy.segment<2>(15) = s.sdot_h;
    dy.segment<2>(17) = x.sddot_o;
    dy.segment<2>(19) = x.sddot_h;
    return x;
  }

  /// The state back on the contact manifold: unit quaternion; (s_o, s_h) where the points
  /// coincide tangentially and the normals are opposite (Gauss-Newton), the object moved along
  /// the normal onto the hand; the velocities' smallest (scaled) change that makes them roll.
  /// Returns the constraint residual before.
  double project(double t, Y& y) {
    const double before = constraint_residual(t, y);
    const HandPose3 hand = motion_.at(t);
    SpatialState s = unpack(y);
    const Eigen::Matrix3d Rc = s.orientation.toRotationMatrix();
    for (int iteration = 0; iteration < 8; ++iteration) {
      const World w = world(hand, Rc, s);
      Eigen::Vector4d F;
      F.head<2>() = w.Jh.transpose() * (w.ph - w.po);
      F.tail<2>() = w.Jh.transpose() * (w.No + w.Nh);
      if (F.norm() < 1e-16 * (1 + w.Jh.norm())) break;
      Eigen::Matrix4d M;
      M.block<2, 2>(0, 0) = -w.Jh.transpose() * w.Jo;
      M.block<2, 2>(0, 2) = w.Jh.transpose() * w.Jh;
      M.block<2, 2>(2, 0) = w.Jh.transpose() * w.Ko;
      M.block<2, 2>(2, 2) = w.Jh.transpose() * w.Kh;
      const Eigen::Vector4d d = M.fullPivLu().solve(-F);
      s.s_o += d.head<2>();
      s.s_h += d.tail<2>();
    }
    {
      const World w = world(hand, Rc, s);
      s.position += w.ph - w.po;
    }
    const World w = world(hand, Rc, s);
    // Velocities y_v = (v, omega, sdot_o, sdot_h): rolling (3), equal contact point rates (3),
    // normals staying opposite (3); rank 7.
    Eigen::Matrix<double, 9, 10> C = Eigen::Matrix<double, 9, 10>::Zero();
    Eigen::Matrix<double, 9, 1> d = Eigen::Matrix<double, 9, 1>::Zero();
    C.block<3, 3>(0, 0) = Eigen::Matrix3d::Identity();
    C.block<3, 3>(0, 3) = -cross_matrix(w.ro);
    d.segment<3>(0) = hand.velocity + hand.angular_velocity.cross(w.rh);
    C.block<3, 2>(3, 6) = -w.Jo;
    C.block<3, 2>(3, 8) = w.Jh;
    C.block<3, 3>(6, 3) = -cross_matrix(w.No);
    C.block<3, 2>(6, 6) = w.Ko;
    C.block<3, 2>(6, 8) = w.Kh;
    d.segment<3>(6) = -hand.angular_velocity.cross(w.Nh);
    Eigen::Matrix<double, 10, 1> yv;
    yv << s.velocity, s.angular_velocity, s.sdot_o, s.sdot_h;
    // Scaled so that every unknown is a velocity in m/s: omega times the lever |r_o|, each sdot
    // times its column of J.
    Eigen::Matrix<double, 10, 1> scale;
    const double lever = std::max(w.ro.norm(), 1e-12);
    scale << 1, 1, 1, lever, lever, lever, w.Jo.col(0).norm(), w.Jo.col(1).norm(),
        w.Jh.col(0).norm(), w.Jh.col(1).norm();
    const Eigen::Matrix<double, 9, 10> Cs = C * scale.cwiseInverse().asDiagonal();
    const Eigen::Matrix<double, 10, 1> dz = Cs.completeOrthogonalDecomposition().solve(d - C * yv);
    yv += dz.cwiseQuotient(scale);
    s.velocity = yv.segment<3>(0);
    s.angular_velocity = yv.segment<3>(3);
    s.sdot_o = yv.segment<2>(6);
    s.sdot_h = yv.segment<2>(8);
    y = pack(s);
    return before;
  }

  double constraint_residual(double t, const Y& y) const {
    const HandPose3 hand = motion_.at(t);
    const SpatialState s = unpack(y);
    const World w = world(hand, s.orientation.toRotationMatrix(), s);
    const Vec3 Vo = s.velocity + s.angular_velocity.cross(w.ro);
    const Vec3 Vh = hand.velocity + hand.angular_velocity.cross(w.rh);
    return std::max({(w.ph - w.po).norm(), (w.No + w.Nh).norm(), (Vo - Vh).norm(),
                     (w.Jo * s.sdot_o - w.Jh * s.sdot_h).norm()});
  }

  /// Turn the ball's chart so that the contact is at its (0, 0) when it has come within 0.57 rad
  /// of a pole. Returns whether it did.
  bool rechart(Y& y) {
    if (!(ball_radius_ > 0)) return false;
    SpatialState s = unpack(y);
    if (std::abs(s.s_o.y()) < 1.0) return false;
    const Surface& ball = *pb_.object.surface;
    const SurfaceGeometry g = ball.geometry(s.s_o);
    // D takes the new chart frame into the old one, with the new chart's (0, 0) point, body +x
    // times r, onto the contact.
    const Eigen::Matrix3d D =
        Eigen::Quaterniond::FromTwoVectors(Vec3::UnitX(), g.point.normalized()).toRotationMatrix();
    const SurfaceGeometry g0 = ball.geometry(SurfaceParam::Zero());
    const Vec3 w = D.transpose() * (g.jacobian * s.sdot_o);  // the contact point's rate, new frame
    s.sdot_o = (g0.jacobian.transpose() * g0.jacobian).ldlt().solve(g0.jacobian.transpose() * w);
    s.s_o = SurfaceParam::Zero();
    s.orientation = Eigen::Quaterniond(s.orientation.toRotationMatrix() * D).normalized();
    chart_ = chart_ * D;
    chart_pb_.object.inertia = chart_.transpose() * pb_.object.inertia * chart_;
    ++stats.chart_changes;
    y = pack(s);
    return true;
  }

  /// Everything at (t, y), from the solution rhs() found there.
  SpatialSample sample(double t, const Y& y, const SpatialSolution& x) const {
    SpatialSample out;
    out.t = t;
    const SpatialState s = unpack(y);
    out.state = s;
    // The body's orientation: R_o = R_c C^T.
    out.state.orientation =
        Eigen::Quaterniond(s.orientation.toRotationMatrix() * chart_.transpose()).normalized();
    out.force_normal = x.force_normal;
    out.mu_required = x.mu_required;
    out.energy = spatial_energy(chart_pb_, s);
    out.constraint_residual = constraint_residual(t, y);
    out.redundant_residual = x.residual;
    return out;
  }

  /// std::invalid_argument unless the object fits the hand at the contact: the relative curvature
  /// S_o + S_h (the shape operators on the common tangent plane, > 0 where a body bulges towards
  /// the other) must be positive definite, or the object touches the hand along more than a point
  /// (a ball larger than the bowl it sits in).
  void require_fit(double t, const Y& y) const {
    const SpatialState s = unpack(y);
    const World w = world(motion_.at(t), s.orientation.toRotationMatrix(), s);
    const Eigen::HouseholderQR<Mat32> qr(w.Jh);
    const Mat32 E = qr.householderQ() * Mat32::Identity();  // an orthonormal tangent basis
    const auto shape = [&](const Mat32& J, const Mat32& K) -> Eigen::Matrix2d {
      const Eigen::Matrix2d S =
          E.transpose() * K * (J.transpose() * J).inverse() * J.transpose() * E;
      return 0.5 * (S + S.transpose());
    };
    const Eigen::Matrix2d relative = shape(w.Jo, w.Ko) + shape(w.Jh, w.Kh);
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(relative);
    if (!(eig.eigenvalues().minCoeff() > 0))
      throw std::invalid_argument(
          "spatial run: the object does not fit the hand's curvature at the contact (" +
          pb_.object.surface->describe() + " on " + pb_.hand->describe() + ": relative curvature " +
          format_significant(eig.eigenvalues().minCoeff()) + " 1/m, must be > 0)");
  }

  bool inside_patches(const Y& y) const {
    const SpatialState s = unpack(y);
    return pb_.hand->patch().contains(s.s_h) && pb_.object.surface->patch().contains(s.s_o);
  }

  SpatialRunStats stats;

 private:
  struct World {
    Vec3 ph, po, rh, ro, Nh, No;
    Mat32 Jh, Jo, Kh, Ko;
  };
  World world(const HandPose3& hand, const Eigen::Matrix3d& Rc, const SpatialState& s) const {
    const SurfaceGeometry gh = pb_.hand->geometry(s.s_h);
    const SurfaceGeometry go = pb_.object.surface->geometry(s.s_o);
    World w;
    w.rh = hand.rotation * gh.point;
    w.ro = Rc * go.point;
    w.ph = hand.position + w.rh;
    w.po = s.position + w.ro;
    w.Nh = hand.rotation * gh.normal;
    w.No = Rc * go.normal;
    w.Jh = hand.rotation * gh.jacobian;
    w.Jo = Rc * go.jacobian;
    w.Kh = hand.rotation * gh.curvature_form;
    w.Ko = Rc * go.curvature_form;
    return w;
  }

  const SpatialRollingProblem& pb_;
  SpatialRollingProblem chart_pb_;  ///< the object's inertia in its chart frame
  const HandMotion3& motion_;
  Eigen::Matrix3d chart_ = Eigen::Matrix3d::Identity();  ///< C: chart frame -> body frame
  double ball_radius_ = 0;
};

void check(const SpatialRollingProblem& pb, const SpatialRunOptions& o, double t0) {
  if (!pb.hand) throw std::invalid_argument("spatial run: no hand surface");
  if (!pb.object.surface) throw std::invalid_argument("spatial run: no object surface");
  if (!(pb.object.mass > 0) || !std::isfinite(pb.object.mass))
    throw std::invalid_argument("spatial run: object mass must be positive and finite");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> inertia(pb.object.inertia);
  if (!pb.object.inertia.allFinite() || !(inertia.eigenvalues().minCoeff() > 0) ||
      (pb.object.inertia - pb.object.inertia.transpose()).norm() > 1e-12 * pb.object.inertia.norm())
    throw std::invalid_argument("spatial run: object inertia must be symmetric positive definite");
  if (!pb.gravity.allFinite()) throw std::invalid_argument("spatial run: gravity must be finite");
  if (!std::isfinite(t0) || !std::isfinite(o.t_end) || !(o.t_end > t0))
    throw std::invalid_argument("spatial run: t_end must be finite and after the start");
  if (!(o.rtol > 0) || !(o.atol > 0) || !(o.max_step > 0) || o.max_steps < 1)
    throw std::invalid_argument("spatial run: rtol, atol, max_step and max_steps must be positive");
}

}  // namespace

SpatialRunResult simulate_spatial(const SpatialRollingProblem& pb, const HandMotion3& motion,
                                  const SpatialState& initial, double t0,
                                  const SpatialRunOptions& o) {
  check(pb, o, t0);
  SpatialIntegration in(pb, motion);
  SpatialRunResult res;
  double t = t0;
  Y y = in.pack(initial);
  in.rechart(y);
  in.project(t, y);
  in.require_fit(t, y);
  // Each sample reuses the evaluation that starts the next step (k1): one solve per state.
  const auto record = [&](double tt, const Y& yy, const SpatialSolution& x) {
    SpatialSample s = in.sample(tt, yy, x);
    in.stats.max_constraint_residual =
        std::max(in.stats.max_constraint_residual, s.constraint_residual);
    in.stats.max_redundant_residual =
        std::max(in.stats.max_redundant_residual, s.redundant_residual);
    if (o.record) res.steps.push_back(s);
    return s;
  };
  Y k1, k2, k3, k4, k5, k6, k7, y1;
  SpatialSample last = record(t, y, in.rhs(t, y, k1));
  double h = std::min(o.max_step, 1e-4);
  while (t < o.t_end) {
    if (in.stats.steps + in.stats.rejected >= o.max_steps)
      throw std::runtime_error("spatial run: step budget (" + std::to_string(o.max_steps) +
                               ") exhausted at t=" + format_significant(t, 10) + " s");
    const double hh = std::min({h, o.max_step, o.t_end - t});
    in.rhs(t + c2 * hh, y + hh * a21 * k1, k2);
    in.rhs(t + c3 * hh, y + hh * (a31 * k1 + a32 * k2), k3);
    in.rhs(t + c4 * hh, y + hh * (a41 * k1 + a42 * k2 + a43 * k3), k4);
    in.rhs(t + c5 * hh, y + hh * (a51 * k1 + a52 * k2 + a53 * k3 + a54 * k4), k5);
    in.rhs(t + hh, y + hh * (a61 * k1 + a62 * k2 + a63 * k3 + a64 * k4 + a65 * k5), k6);
    y1 = y + hh * (a71 * k1 + a73 * k3 + a74 * k4 + a75 * k5 + a76 * k6);
    in.rhs(t + hh, y1, k7);
    const Y err = hh * (e1 * k1 + e3 * k3 + e4 * k4 + e5 * k5 + e6 * k6 + e7 * k7);
    double norm = 0;
    for (int i = 0; i < kN; ++i) {
      const double sc = o.atol + o.rtol * std::max(std::abs(y[i]), std::abs(y1[i]));
      norm += (err[i] / sc) * (err[i] / sc);
    }
    norm = std::sqrt(norm / kN);
    if (!std::isfinite(norm) || norm > 1.0) {
      ++in.stats.rejected;
      h = hh * (std::isfinite(norm) ? std::max(0.2, 0.9 * std::pow(norm, -0.2)) : 0.1);
      if (h < 1e-14 * std::max(1.0, std::abs(t)))
        throw std::runtime_error(
            "spatial run: step size underflow at t=" + format_significant(t, 10) + " s");
      continue;
    }
    ++in.stats.steps;
    t = (hh == o.t_end - t) ? o.t_end : t + hh;
    y = y1;
    in.stats.max_drift = std::max(in.stats.max_drift, in.project(t, y));
    in.rechart(y);
    // The projection moved y: no first-same-as-last, k1 is evaluated anew.
    last = record(t, y, in.rhs(t, y, k1));
    if (!in.inside_patches(y)) {
      res.stop = SpatialStop::kLeftPatch;
      break;
    }
    if (last.force_normal < 0) {
      res.stop = SpatialStop::kContactLost;
      break;
    }
    h = hh * (norm > 0 ? std::min(5.0, std::max(0.2, 0.9 * std::pow(norm, -0.2))) : 5.0);
  }
  res.final = last;
  res.stats = in.stats;
  return res;
}

}  // namespace flatland::sim
