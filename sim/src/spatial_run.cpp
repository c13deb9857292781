// Spatial rolling in time: hand motions in SE(3), Runge-Kutta steps on the 21 state values
// (position 3, orientation quaternion 4, velocity 3, angular velocity 3, s_o, s_h, sdot_o, sdot_h)
// with the projection onto the contact manifold after every accepted step, and the contact
// carried into another chart of its surface when it nears a chart's poles (spatial_charts.hpp).
#include "flatland/sim/spatial_run.hpp"

#include "energy_ledger.hpp"
#include "runge_kutta.hpp"
#include "spatial_charts.hpp"
#include "step_budget.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/roots.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <utility>

namespace flatland::sim {

// ---- motions ----

int HandMotion3::segment_at(double t) const {
  const std::vector<double> b = breakpoints();
  return static_cast<int>(std::upper_bound(b.begin(), b.end(), t) - b.begin());
}

FixedHand3::FixedHand3(Eigen::Matrix3d rotation, Vec3 position) {
  pose_.rotation = rotation;
  pose_.position = position;
}

HandPose3 FixedHand3::at(double, int) const { return pose_; }

SpinningHand3::SpinningHand3(Vec3 axis, double rate, Vec3 point, Eigen::Matrix3d rotation0,
                             Vec3 position0)
    : axis_(axis.normalized()),
      point_(point),
      position0_(position0),
      rate_(rate),
      rotation0_(rotation0) {
  if (!(axis.norm() > 0) || !axis.allFinite() || !std::isfinite(rate) || !point.allFinite() ||
      !position0.allFinite())
    throw std::invalid_argument(
        "spinning hand: the axis must be a finite non-zero vector and "
        "the rate, point and position finite");
}

HandPose3 SpinningHand3::at(double t, int) const {
  HandPose3 p;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(rate_ * t, axis_).toRotationMatrix();
  p.rotation = R * rotation0_;
  // x(t) = point + R (x0 - point): the point on the axis stays put.
  p.position = point_ + R * (position0_ - point_);
  p.angular_velocity = rate_ * axis_;
  p.velocity = p.angular_velocity.cross(p.position - point_);
  p.acceleration = p.angular_velocity.cross(p.velocity);
  return p;
}

std::string SpinningHand3::describe() const {
  return "hand spinning at " + format_significant(rate_) + " rad/s";
}

namespace {
bool is_rotation(const Eigen::Matrix3d& m) {
  return m.allFinite() && (m.transpose() * m - Eigen::Matrix3d::Identity()).norm() < 1e-9 &&
         std::abs(m.determinant() - 1) < 1e-9;
}
}  // namespace

PlanarHand3::PlanarHand3(std::shared_ptr<const HandMotion> motion, Eigen::Matrix3d plane,
                         Vec3 origin)
    : motion_(std::move(motion)), plane_(plane), origin_(origin) {
  if (!motion_) throw std::invalid_argument("planar hand motion: no motion");
  if (!is_rotation(plane))
    throw std::invalid_argument("planar hand motion: the plane's axes must form a rotation");
  if (!origin.allFinite()) throw std::invalid_argument("planar hand motion: origin must be finite");
}

HandPose3 PlanarHand3::at(double t, int segment) const {
  const HandKinematics k = motion_->at(t, segment);
  const Vec3 axis = plane_.col(2);
  const auto in_space = [&](const Vec2& v) -> Vec3 { return plane_ * Vec3(v.x(), v.y(), 0); };
  HandPose3 p;
  p.rotation = plane_ * Eigen::AngleAxisd(k.angle, Vec3::UnitZ()).toRotationMatrix();
  p.position = origin_ + in_space(k.position);
  p.velocity = in_space(k.velocity);
  p.acceleration = in_space(k.acceleration);
  p.angular_velocity = k.angular_velocity * axis;
  p.angular_acceleration = k.angular_acceleration * axis;
  return p;
}

std::string PlanarHand3::describe() const { return "planar hand motion about a fixed axis"; }

TabulatedHand3::TabulatedHand3(std::vector<Row> rows, Vec3 axis, HandPose3 initial,
                               double angular_velocity)
    : rows_(std::move(rows)), rotation0_(initial.rotation) {
  if (rows_.size() < 2)
    throw std::invalid_argument("tabulated hand motion: needs at least two rows (times)");
  for (std::size_t i = 0; i < rows_.size(); ++i) {
    const Row& r = rows_[i];
    if (!std::isfinite(r.t) || !r.acceleration.allFinite() ||
        !std::isfinite(r.angular_acceleration))
      throw std::invalid_argument("tabulated hand motion: row " + std::to_string(i) +
                                  ": values must be finite");
    if (i > 0 && !(r.t > rows_[i - 1].t))
      throw std::invalid_argument("tabulated hand motion: row " + std::to_string(i) +
                                  ": times must increase strictly");
  }
  if (!(axis.norm() > 0) || !axis.allFinite())
    throw std::invalid_argument("tabulated hand motion: the axis must be a finite non-zero vector");
  if (!is_rotation(initial.rotation) || !initial.position.allFinite() ||
      !initial.velocity.allFinite() || !std::isfinite(angular_velocity))
    throw std::invalid_argument(
        "tabulated hand motion: the initial pose must be a rotation and finite");
  axis_ = axis.normalized();
  Knot k{rows_.front().t, 0.0, angular_velocity, initial.position, initial.velocity};
  knots_.push_back(k);
  for (std::size_t i = 0; i + 1 < rows_.size(); ++i) {
    const double h = rows_[i + 1].t - rows_[i].t;
    const Row& r = rows_[i];
    k.t = rows_[i + 1].t;
    k.position += h * k.velocity + 0.5 * h * h * r.acceleration;
    k.velocity += h * r.acceleration;
    k.angle += h * k.rate + 0.5 * h * h * r.angular_acceleration;
    k.rate += h * r.angular_acceleration;
    knots_.push_back(k);
  }
}

std::vector<double> TabulatedHand3::breakpoints() const {
  std::vector<double> b;
  for (const Row& r : rows_) b.push_back(r.t);
  return b;
}

HandPose3 TabulatedHand3::at(double t, int segment) const {
  // Segment 0 lies before the table, segment n after it: no acceleration there.
  const int n = static_cast<int>(knots_.size());
  const int i = std::clamp(segment - 1, 0, n - 1);
  const Knot& k = knots_[i];
  const bool before = segment <= 0, after = segment >= n;
  const double tau = t - k.t;
  const Vec3 a = (before || after) ? Vec3::Zero() : rows_[i].acceleration;
  const double alpha = (before || after) ? 0.0 : rows_[i].angular_acceleration;
  HandPose3 p;
  p.position = k.position + tau * k.velocity + 0.5 * tau * tau * a;
  p.velocity = k.velocity + tau * a;
  p.acceleration = a;
  const double angle = k.angle + tau * k.rate + 0.5 * tau * tau * alpha;
  p.rotation = Eigen::AngleAxisd(angle, axis_).toRotationMatrix() * rotation0_;
  p.angular_velocity = (k.rate + tau * alpha) * axis_;
  p.angular_acceleration = alpha * axis_;
  return p;
}

std::string TabulatedHand3::describe() const {
  return "tabulated hand accelerations (" + std::to_string(rows_.size() - 1) + " intervals)";
}

std::string to_string(SpatialStop s) {
  switch (s) {
    case SpatialStop::kEndTime:
      return "end_time";
    case SpatialStop::kContactLost:
      return "contact_lost";
    case SpatialStop::kSlip:
      return "slip";
    case SpatialStop::kLeftPatch:
      return "left_patch";
    case SpatialStop::kNumericalFailure:
      return "numerical_failure";
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

constexpr int kN = 22;  // the state's 21 values and, last, the contact force's work (the audit)
constexpr int kWork = 21;
using Y = Eigen::Matrix<double, kN, 1>;

using namespace detail;  // the Runge-Kutta steps

/// The contact's geometry in the world at a state: the contact points (hand's ph, object's po)
/// and their offsets from the hand frame's origin (rh) and the object's centre (ro), the normals,
/// the Jacobians and curvature forms. Ro: the object's orientation (body -> world).
struct ContactWorld {
  Vec3 ph, po, rh, ro, Nh, No;
  Mat32 Jh, Jo, Kh, Ko;
};

ContactWorld contact_world(const SpatialRollingProblem& pb, const HandPose3& hand,
                           const Eigen::Matrix3d& Ro, const SpatialState& s) {
  const SurfaceGeometry gh = pb.hand->geometry(s.s_h);
  const SurfaceGeometry go = pb.object.surface->geometry(s.s_o);
  ContactWorld w;
  w.rh = hand.rotation * gh.point;
  w.ro = Ro * go.point;
  w.ph = hand.position + w.rh;
  w.po = s.position + w.ro;
  w.Nh = hand.rotation * gh.normal;
  w.No = Ro * go.normal;
  w.Jh = hand.rotation * gh.jacobian;
  w.Jo = Ro * go.jacobian;
  w.Kh = hand.rotation * gh.curvature_form;
  w.Ko = Ro * go.curvature_form;
  return w;
}

/// The velocities y_v = (v, omega, sdot_o, sdot_h) of a rolling contact satisfy C y_v = d:
/// rolling (3), equal contact point rates along the tangent plane (2), normals staying opposite
/// along the tangent plane (2). `scale` makes every unknown a velocity in m/s: omega times the
/// lever |r_o|, each sdot times its column of J.
///
/// The normal components of the last two conditions are left out because they hold for every
/// y_v (J_o, J_h, K_o, K_h and n_o x omega are all tangent where n_o = -n_h): with them C had two
/// rows more than its rank, and the two singular values that should be zero were rounding noise
/// of ~eps |C| (5e-14 for a 2 cm ball). A rank-revealing solve then decided the rank by a
/// threshold that noise straddles: where it counted 8, the least-squares correction divided a
/// residual of ~1e-12 by that noise and changed the velocities by O(1) while leaving them
/// consistent (a ball on a tilted turntable jumped from 0.19 to 7.2 m/s, one in a bowl lost 29 %
/// of its energy in one step). With the seven independent rows C has full row rank, its smallest
/// singular value of the order of 1, and no rank has to be decided.
struct VelocityConstraints {
  static constexpr int kRows = 7;
  Eigen::Matrix<double, kRows, 10> C = Eigen::Matrix<double, kRows, 10>::Zero();
  Eigen::Matrix<double, kRows, 1> d = Eigen::Matrix<double, kRows, 1>::Zero();
  Eigen::Matrix<double, 10, 1> scale;
  /// C with its columns divided by `scale`: the constraints on the scaled unknowns.
  Eigen::Matrix<double, kRows, 10> scaled() const { return C * scale.cwiseInverse().asDiagonal(); }
};

/// An orthonormal basis (3 x 2) of the plane spanned by J's columns (Gram-Schmidt).
Mat32 tangent_basis(const Mat32& J) {
  Mat32 E;
  E.col(0) = J.col(0).normalized();
  E.col(1) = (J.col(1) - J.col(1).dot(E.col(0)) * E.col(0)).normalized();
  return E;
}

VelocityConstraints velocity_constraints(const ContactWorld& w, const HandPose3& hand) {
  const Eigen::Matrix<double, 2, 3> Et = tangent_basis(w.Jh).transpose();
  VelocityConstraints v;
  v.C.block<3, 3>(0, 0) = Eigen::Matrix3d::Identity();
  v.C.block<3, 3>(0, 3) = -cross_matrix(w.ro);
  v.d.segment<3>(0) = hand.velocity + hand.angular_velocity.cross(w.rh);
  v.C.block<2, 2>(3, 6) = -Et * w.Jo;
  v.C.block<2, 2>(3, 8) = Et * w.Jh;
  v.C.block<2, 3>(5, 3) = -Et * cross_matrix(w.No);
  v.C.block<2, 2>(5, 6) = Et * w.Ko;
  v.C.block<2, 2>(5, 8) = Et * w.Kh;
  v.d.segment<2>(5) = -Et * hand.angular_velocity.cross(w.Nh);
  const double lever = std::max(w.ro.norm(), 1e-12);
  v.scale << 1, 1, 1, lever, lever, lever, w.Jo.col(0).norm(), w.Jo.col(1).norm(),
      w.Jh.col(0).norm(), w.Jh.col(1).norm();
  return v;
}

/// Where each condition a run must keep stands: >= 0 while it holds. The forces in N, the patch
/// margin in the surfaces' parameters.
struct Guards {
  static constexpr int kCount = 3;
  std::array<double, kCount> value{};
  static constexpr std::array<SpatialStop, kCount> kStop = {
      SpatialStop::kContactLost, SpatialStop::kSlip, SpatialStop::kLeftPatch};
};

/// The run's equations. The contact coordinates s_o, s_h in the state are in the charts in use
/// (spatial_charts.hpp): `chart_pb_` is the problem with both surfaces in those charts, which
/// change (with s and sdot re-expressed) when the contact nears a chart's poles. The object's
/// orientation is its body's in every chart.
class SpatialIntegration {
 public:
  SpatialIntegration(const SpatialRollingProblem& pb, const HandMotion3& motion,
                     const SpatialRunOptions& o)
      : pb_(pb),
        chart_pb_(pb),
        motion_(motion),
        o_(o),
        hand_charts_(pb.hand, false),
        object_charts_(pb.object.surface, true) {}

  SpatialRunResult run(const SpatialState& initial, double t0);

 private:
  /// The state and the work done so far (which only the integrator changes).
  Y pack(const SpatialState& s, double work = 0) const {
    Y y;
    y[kWork] = work;
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
    const SpatialSolution x = solve_spatial_rolling(chart_pb_, motion_.at(t, segment_), s);
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
    dy[kWork] = x.power;
    return x;
  }

  /// The state back on the contact manifold: unit quaternion; (s_o, s_h) where the points
  /// coincide tangentially and the normals are opposite (Gauss-Newton), the object moved along
  /// the normal onto the hand; the velocities' smallest (scaled) change that makes them roll.
  /// Returns the constraint residual before.
  double project(double t, Y& y) {
    const double before = constraint_residual(t, y);
    const HandPose3 hand = motion_.at(t, segment_);
    SpatialState s = unpack(y);
    const Eigen::Matrix3d Ro = s.orientation.toRotationMatrix();
    for (int iteration = 0; iteration < 8; ++iteration) {
      const ContactWorld w = world(hand, Ro, s);
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
      const ContactWorld w = world(hand, Ro, s);
      s.position += w.ph - w.po;
    }
    const ContactWorld w = world(hand, Ro, s);
    const VelocityConstraints vc = velocity_constraints(w, hand);
    Eigen::Matrix<double, 10, 1> yv;
    yv << s.velocity, s.angular_velocity, s.sdot_o, s.sdot_h;
    // The smallest scaled change dz with Cs dz = d - C y_v: Cs has full row rank (7), so
    // dz = Cs^T (Cs Cs^T)^-1 (d - C y_v), with no rank to decide.
    const auto Cs = vc.scaled();
    const Eigen::Matrix<double, VelocityConstraints::kRows, 1> r = vc.d - vc.C * yv;
    const Eigen::Matrix<double, 10, 1> dz = Cs.transpose() * (Cs * Cs.transpose()).llt().solve(r);
    yv += dz.cwiseQuotient(vc.scale);
    s.velocity = yv.segment<3>(0);
    s.angular_velocity = yv.segment<3>(3);
    s.sdot_o = yv.segment<2>(6);
    s.sdot_h = yv.segment<2>(8);
    y = pack(s, y[kWork]);
    return before;
  }

  double constraint_residual(double t, const Y& y) const {
    const HandPose3 hand = motion_.at(t, segment_);
    const SpatialState s = unpack(y);
    return constraint_residual(hand, s, world(hand, s.orientation.toRotationMatrix(), s));
  }
  static double constraint_residual(const HandPose3& hand, const SpatialState& s,
                                    const ContactWorld& w) {
    const Vec3 Vo = s.velocity + s.angular_velocity.cross(w.ro);
    const Vec3 Vh = hand.velocity + hand.angular_velocity.cross(w.rh);
    return std::max({(w.ph - w.po).norm(), (w.No + w.Nh).norm(), (Vo - Vh).norm(),
                     (w.Jo * s.sdot_o - w.Jh * s.sdot_h).norm()});
  }

  /// Between steps: each surface's contact into another chart if it has come near its chart's
  /// poles (counted in stats.chart_changes), the longitudes wrapped. Returns whether a chart
  /// changed (the state's derivative is then to be evaluated again: the same motion, but s and
  /// sdot in other coordinates).
  bool rechart(Y& y) {
    SpatialState s = unpack(y);
    const int changes =
        int{object_charts_.update(s.s_o, s.sdot_o)} + int{hand_charts_.update(s.s_h, s.sdot_h)};
    object_charts_.wrap_longitude(s.s_o);
    hand_charts_.wrap_longitude(s.s_h);
    y.segment<2>(13) = s.s_o;
    y.segment<2>(15) = s.s_h;
    y.segment<2>(17) = s.sdot_o;
    y.segment<2>(19) = s.sdot_h;
    if (changes == 0) return false;
    chart_pb_.object.surface = object_charts_.chart();
    chart_pb_.hand = hand_charts_.chart();
    stats.chart_changes += changes;
    return true;
  }

  /// Everything at (t, y), from the solution rhs() found there.
  SpatialSample sample(double t, const Y& y, const SpatialSolution& x) const {
    SpatialSample out;
    out.t = t;
    const SpatialState s = unpack(y);
    out.state = s;
    const HandPose3 hand = motion_.at(t, segment_);
    const ContactWorld w = world(hand, s.orientation.toRotationMatrix(), s);
    out.contact = w.ph;
    out.force = x.force;
    out.force_normal = x.force_normal;
    out.mu_required = x.mu_required;
    out.energy = spatial_energy(pb_, s);
    out.constraint_residual = constraint_residual(hand, s, w);
    out.redundant_residual = x.residual;
    return out;
  }

  Guards guards(const Y& y, const SpatialSolution& x) const {
    Guards g;
    constexpr double kHolds = std::numeric_limits<double>::infinity();
    g.value[0] = o_.stop_on_contact_loss ? x.force_normal : kHolds;
    g.value[1] = pb_.mu ? *pb_.mu * x.force_normal - x.force_tangential.norm() : kHolds;
    g.value[2] = patch_margin(unpack(y));
    return g;
  }

  /// How far inside both surfaces' patches (in the charts in use) the contact is, in their
  /// parameters: < 0 outside.
  double patch_margin(const SpatialState& s) const {
    const auto margin = [](const SurfacePatch& p, const SurfaceParam& v) {
      return std::min({v.x() - p.lo.x(), p.hi.x() - v.x(), v.y() - p.lo.y(), p.hi.y() - v.y()});
    };
    return std::min(margin(chart_pb_.hand->patch(), s.s_h),
                    margin(chart_pb_.object.surface->patch(), s.s_o));
  }

  /// std::invalid_argument unless the object fits the hand at the contact: the relative curvature
  /// S_o + S_h (the shape operators on the common tangent plane, > 0 where a body bulges towards
  /// the other) must be positive definite, or the object touches the hand along more than a point
  /// (a ball larger than the bowl it sits in).
  void require_fit(double t, const Y& y) const {
    const SpatialState s = unpack(y);
    const ContactWorld w = world(motion_.at(t, segment_), s.orientation.toRotationMatrix(), s);
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
          chart_pb_.object.surface->describe() + " on " + chart_pb_.hand->describe() +
          ": relative curvature " + format_significant(eig.eigenvalues().minCoeff()) +
          " 1/m, must be > 0)");
  }

  /// One step of the chosen method; the error norm (0 for RK4). The dense output is complete in
  /// `rc` except for DOP853, whose interpolant dense() finishes from the stages in `k853_`.
  double attempt(double t, const Y& y, const Y& k1, double h, Y& y1, Y& k7,
                 DenseCoefficients<Y>& rc) {
    const auto f = [this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); };
    const IntegratorSettings& is = o_.integrator;
    switch (is.method) {
      case Method::kRungeKutta4:
        rk4_step(f, t, y, k1, h, y1, k7, rc);
        return 0.0;
      case Method::kDormandPrince853:
        return dop853_step(f, t, y, k1, h, is.rtol, is.atol, y1, k7, k853_, kWork);
      case Method::kDormandPrince54:
        break;
    }
    return dopri5_step(f, t, y, k1, h, is.rtol, is.atol, y1, k7, rc, kWork);
  }
  void dense(double t, const Y& y, const Y& y1, double h, DenseCoefficients<Y>& rc) {
    if (o_.integrator.method != Method::kDormandPrince853) return;
    dop853_dense([this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); }, t, y, y1, h, k853_,
                 rc);
  }
  int dense_terms() const { return o_.integrator.method == Method::kDormandPrince853 ? 8 : 5; }

  /// The next step size after an accepted step with error norm `err` (Hairer's controllers: PI
  /// for DOPRI5, I for DOP853, no growth right after a rejection).
  double next_step(double h, double err, bool after_rejection) {
    if (o_.integrator.method == Method::kDormandPrince853) {
      const double fac = std::clamp(std::pow(std::max(err, 1e-30), 1.0 / 8.0) / 0.9, 1.0 / 6, 3.0);
      return after_rejection ? std::min(h / fac, h) : h / fac;
    }
    const double fac11 = std::pow(std::max(err, 1e-16), 0.17);
    const double fac = std::clamp(fac11 / std::pow(facold_, 0.04) / 0.9, 0.1, 5.0);
    facold_ = std::max(err, 1e-4);
    return after_rejection ? std::min(h / fac, h) : h / fac;
  }
  double shrink(double h, double err) const {
    if (!std::isfinite(err)) return 0.1 * h;
    return o_.integrator.method == Method::kDormandPrince853
               ? h * std::max(1.0 / 3.0, 0.9 * std::pow(err, -1.0 / 8.0))
               : h * std::max(0.2, 0.9 * std::pow(err, -0.2));
  }

  /// The first event within the step (t, t + h] from (y, k1), given the guards at both ends:
  /// located on the step map hh -> the projected step of size hh (so that the step redone up to
  /// the event lands on it), to the time tolerance. Returns the event's index and time, or -1.
  std::pair<int, double> first_event(double t, const Y& y, const Y& k1, double h, const Guards& g0,
                                     const Guards& g1) {
    int kind = -1;
    double t_event = t + h;
    for (int i = 0; i < Guards::kCount; ++i) {
      if (!(g1.value[i] < 0)) continue;
      const auto value_after = [&](double hh) {
        ++stats.event_evals;
        Y out, k7_unused;
        DenseCoefficients<Y> rc_unused;
        Stages853<Y> saved = k853_;
        attempt(t, y, k1, hh, out, k7_unused, rc_unused);
        k853_ = saved;
        project(t + hh, out);
        Y dy;
        const SpatialSolution x = rhs(t + hh, out, dy);
        return guards(out, x).value[i];
      };
      const double te =
          g0.value[i] < 0
              ? t
              : t + brent_root(value_after, 0.0, h, g0.value[i], g1.value[i], o_.time_tolerance).x;
      if (kind < 0 || te < t_event) kind = i, t_event = te;
    }
    return {kind, t_event};
  }

  void note(const SpatialSample& s, const SpatialSolution& x) {
    stats.max_constraint_residual = std::max(stats.max_constraint_residual, s.constraint_residual);
    stats.max_redundant_residual = std::max(stats.max_redundant_residual, s.redundant_residual);
    stats.min_force_normal = std::min(stats.min_force_normal, x.force_normal);
    if (std::isfinite(x.mu_required))
      stats.max_mu_required = std::max(stats.max_mu_required, x.mu_required);
    else
      stats.max_mu_required = std::numeric_limits<double>::infinity();
  }

  ContactWorld world(const HandPose3& hand, const Eigen::Matrix3d& Ro,
                     const SpatialState& s) const {
    return contact_world(chart_pb_, hand, Ro, s);
  }

  const SpatialRollingProblem& pb_;
  SpatialRollingProblem chart_pb_;  ///< pb_ with both surfaces in the charts in use
  const HandMotion3& motion_;
  const SpatialRunOptions& o_;
  SurfaceCharts hand_charts_, object_charts_;
  int segment_ = 0;  ///< the motion's segment the run is in
  Stages853<Y> k853_;
  double facold_ = 1e-4;  ///< PI step-size controller memory

 public:
  SpatialRunStats stats;
};

SpatialRunResult SpatialIntegration::run(const SpatialState& initial, double t0) {
  SpatialRunResult res;
  const IntegratorSettings& is = o_.integrator;
  const bool rk4 = is.method == Method::kRungeKutta4;
  double t = t0;
  segment_ = motion_.segment_at(t0);
  Y y = pack(initial);
  project(t, y);
  require_fit(t, y);
  // The start is given in the surfaces' own charts and must lie in their patches; only then may
  // the contact move into another chart (a start within 0.57 rad of a pole does).
  if (patch_margin(unpack(y)) < -1e-9)
    throw std::invalid_argument("spatial run: the contact starts outside the patch of " +
                                (pb_.object.surface->patch().contains(unpack(y).s_o)
                                     ? pb_.hand->describe()
                                     : pb_.object.surface->describe()));
  rechart(y);
  Y k1, k7, y1;
  SpatialSolution x = rhs(t, y, k1);
  Guards g_start = guards(y, x);
  const auto record = [&](double tt, const Y& yy, const SpatialSolution& xx) {
    const SpatialSample s = sample(tt, yy, xx);
    note(s, xx);
    if (o_.record) res.samples.push_back(s);
    return s;
  };
  SpatialSample last = record(t, y, x);
  res.initial = last;
  // The energy audit: the floor of its scale m |g| times the object's size (centre to contact).
  EnergyLedger ledger(
      res.audit, energy_tolerance(is.energy_tolerance, rk4, is.rtol),
      pb_.object.mass * pb_.gravity.norm() * (last.contact - last.state.position).norm());
  const auto kinetic = [&](const SpatialSample& ss) {
    return ss.energy + pb_.object.mass * pb_.gravity.dot(ss.state.position);
  };
  ledger.start(last.energy, kinetic(last));
  // A run may start on a boundary (a disk resting at the edge of the hand's piece): a value
  // within a rounding tolerance of it is taken as on it; one further beyond stops the run at once.
  const double weight = pb_.object.mass * std::max(pb_.gravity.norm(), 1.0);
  const std::array<double, Guards::kCount> start_tolerance = {1e-9 * weight, 1e-9 * weight, 1e-9};
  const auto stop_at_start = [&]() -> std::optional<SpatialStop> {
    for (int i = 0; i < Guards::kCount; ++i)
      if (g_start.value[i] < -start_tolerance[i]) return Guards::kStop[i];
    return std::nullopt;
  };
  std::optional<SpatialStop> stopped = stop_at_start();

  std::vector<double> stops;
  for (double b : motion_.breakpoints())
    if (b > t0 && b < o_.t_end) stops.push_back(b);
  stops.push_back(o_.t_end);
  long next_grid = 1;  // the sample_dt grid's next index (t0 is sampled)
  const auto grid_time = [&](long i) { return t0 + static_cast<double>(i) * o_.sample_dt; };
  double h = rk4 ? is.fixed_step : 0.0;
  bool last_rejected = false;
  DenseCoefficients<Y> rc;

  for (double t_stop : stops) {
    while (t < t_stop && !stopped) {
      if (h == 0.0)
        h = starting_step([this](double tt, const Y& yy, Y& dy) { rhs(tt, yy, dy); }, t, y, k1,
                          t_stop, is.rtol, is.atol, is.max_step,
                          is.method == Method::kDormandPrince853 ? 8.0 : 5.0, kWork);
      if (stats.steps + stats.rejected >= is.max_steps)
        throw std::runtime_error("spatial run: step budget (" + std::to_string(is.max_steps) +
                                 ") exhausted at t=" + format_significant(t, 10) + " s");
      forecast_step_budget(stats.steps + stats.rejected, is.max_steps, t0, t, o_.t_end);
      double h_try = rk4 ? is.fixed_step : std::min(h, is.max_step);
      if (t + 1.01 * h_try >= t_stop) h_try = t_stop - t;  // land exactly on the stop
      const double err = attempt(t, y, k1, h_try, y1, k7, rc);
      if (!rk4 && !(err <= 1.0)) {
        ++stats.rejected;
        last_rejected = true;
        h = shrink(h_try, err);
        if (!(h >= 1e-14 * std::max(1.0, std::abs(t))))  // NaN too
          throw std::runtime_error(
              "spatial run: step size underflow at t=" + format_significant(t, 10) + " s");
        continue;
      }
      if (!y1.allFinite())
        throw std::runtime_error("spatial run: non-finite state at t=" + format_significant(t, 10) +
                                 " s (reduce integrator.step)");
      double t1 = (h_try == t_stop - t) ? t_stop : t + h_try;
      Y y1p = y1;
      double drift = project(t1, y1p);
      Y k1_next;
      SpatialSolution x1 = rhs(t1, y1p, k1_next);
      const auto [event, t_event] = first_event(t, y, k1, h_try, g_start, guards(y1p, x1));
      if (event >= 0 && t_event < t1) {
        // Stop exactly at the event: redo the step up to it, so that no step straddles it.
        h_try = t_event - t;
        if (h_try > 0) {
          attempt(t, y, k1, h_try, y1, k7, rc);
          t1 = t_event;
          y1p = y1;
          drift = project(t1, y1p);
          x1 = rhs(t1, y1p, k1_next);
        } else {
          t1 = t, y1p = y, x1 = x, k1_next = k1, drift = 0;
        }
      }
      if (h_try > 0) {
        ++stats.steps;
        stats.max_drift = std::max(stats.max_drift, drift);
        if (o_.record && o_.sample_dt > 0 && grid_time(next_grid) < t1) {
          dense(t, y, y1, h_try, rc);
          for (; grid_time(next_grid) < t1; ++next_grid) {
            const double tg = grid_time(next_grid);
            Y yg = dense_value(rc, dense_terms(), (tg - t) / h_try);
            project(tg, yg);
            Y dy;
            const SpatialSolution xg = rhs(tg, yg, dy);
            record(tg, yg, xg);
          }
        }
        ledger.add_work(y1p[kWork] - y[kWork], 0.0);
        t = t1;
        y = y1p;
        x = x1;
        k1 = k1_next;
        if (rechart(y)) x = rhs(t, y, k1);  // the same state in the ball's new chart
        const SpatialSample s = sample(t, y, x);
        note(s, x);
        if (o_.record && o_.sample_dt == 0) res.samples.push_back(s);
        last = s;
        g_start = guards(y, x);
        if (o_.progress) o_.progress(t);
        if (!ledger.check(t, s.energy, kinetic(s))) {
          stopped = SpatialStop::kNumericalFailure;  // the numbers are wrong from here on
          break;
        }
      }
      if (!rk4 && event < 0) h = next_step(h_try, err, last_rejected);
      last_rejected = false;
      if (event >= 0) stopped = Guards::kStop[event];
    }
    if (stopped) break;
    if (t_stop < o_.t_end) {  // the acceleration jumps here: restart on the motion's next segment
      ++stats.restarts;
      ++segment_;
      x = rhs(t, y, k1);
      g_start = guards(y, x);  // the forces jump with the acceleration
      stopped = stop_at_start();
    }
  }
  if (o_.record && (res.samples.empty() || res.samples.back().t != t)) res.samples.push_back(last);
  res.stop = stopped.value_or(SpatialStop::kEndTime);
  res.final = last;
  res.stats = stats;
  return res;
}

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
  if (pb.mu && !(*pb.mu >= 0 && std::isfinite(*pb.mu)))
    throw std::invalid_argument("spatial run: mu must be >= 0 and finite");
  if (!std::isfinite(t0) || !std::isfinite(o.t_end) || !(o.t_end > t0))
    throw std::invalid_argument("spatial run: t_end must be finite and after the start");
  const IntegratorSettings& is = o.integrator;
  if (!(is.rtol > 0) || !(is.atol > 0) || !(is.max_step > 0) || is.max_steps < 1 ||
      !(is.fixed_step > 0) || !std::isfinite(is.fixed_step))
    throw std::invalid_argument(
        "spatial run: rtol, atol, step, max_step and max_steps must be positive");
  if (is.energy_tolerance && !(*is.energy_tolerance > 0 && std::isfinite(*is.energy_tolerance)))
    throw std::invalid_argument("spatial run: energy_tolerance must be positive and finite");
  check_fixed_step_budget(is, o.t_end - t0);  // (after t_end's own check: the span is finite)
  if (!(o.time_tolerance > 0) || !std::isfinite(o.time_tolerance))
    throw std::invalid_argument("spatial run: the event time tolerance must be positive");
  if (!(o.sample_dt >= 0) || !std::isfinite(o.sample_dt))
    throw std::invalid_argument("spatial run: sample_dt must be >= 0 and finite");
}

}  // namespace

SpatialState place_in_contact(const SpatialRollingProblem& pb, const HandPose3& hand,
                              const ContactPlacement& at) {
  if (!pb.hand || !pb.object.surface)
    throw std::invalid_argument("contact placement: no hand or object surface");
  if (!at.s_h.allFinite() || !at.s_o.allFinite() || !std::isfinite(at.twist) ||
      !at.velocity.allFinite() || !std::isfinite(at.spin))
    throw std::invalid_argument("contact placement: values must be finite");
  const SurfaceGeometry gh = pb.hand->geometry(at.s_h);
  const SurfaceGeometry go = pb.object.surface->geometry(at.s_o);
  // The object's frame at its contact point, (t_o, n_o x t_o, n_o), onto the hand's turned by the
  // twist, (t', -n_h x t', -n_h): the normals opposite.
  const auto frame = [](const Vec3& tangent, const Vec3& normal) {
    const Vec3 t = (tangent - tangent.dot(normal) * normal).normalized();
    Eigen::Matrix3d f;
    f << t, normal.cross(t), normal;
    return f;
  };
  const Vec3 nh = hand.rotation * gh.normal;
  const Vec3 th = Eigen::AngleAxisd(at.twist, nh) * (hand.rotation * gh.jacobian.col(0));
  const Eigen::Matrix3d Ro = frame(th, -nh) * frame(go.jacobian.col(0), go.normal).transpose();
  SpatialState s;
  s.s_h = at.s_h;
  s.s_o = at.s_o;
  s.orientation = Eigen::Quaterniond(Ro).normalized();
  s.position = hand.position + hand.rotation * gh.point - Ro * go.point;
  // The velocities: the rolling constraints' solutions x_p + Z z (Z spans their null space, 3
  // dimensions), z chosen so that the centre's tangential velocity and the spin about the normal
  // are the ones asked for.
  const ContactWorld w = contact_world(pb, hand, Ro, s);
  const VelocityConstraints vc = velocity_constraints(w, hand);
  // C has full row rank (7): its SVD gives the smallest solution and the null space's basis.
  const Eigen::JacobiSVD<Eigen::Matrix<double, VelocityConstraints::kRows, 10>> svd(
      vc.scaled(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix<double, 10, 1> particular =
      svd.matrixV().leftCols<VelocityConstraints::kRows>() *
      (svd.matrixU().transpose() * vc.d).cwiseQuotient(svd.singularValues());
  const Eigen::Matrix<double, 10, 3> Z = svd.matrixV().rightCols<3>();
  const Mat32 E = frame(th, -nh).leftCols<2>();  // the tangent plane
  Eigen::Matrix<double, 3, 10> S = Eigen::Matrix<double, 3, 10>::Zero();
  S.block<2, 3>(0, 0) = E.transpose();
  S.block<1, 3>(2, 3) = nh.transpose() / vc.scale[3];  // spin in the scaled unknowns
  Eigen::Vector3d target;
  target << E.transpose() * at.velocity, at.spin;
  const Eigen::Matrix3d SZ = S * Z;
  const Eigen::FullPivLU<Eigen::Matrix3d> lu(SZ);
  if (lu.rank() < 3 || !particular.allFinite())
    throw std::invalid_argument(
        "contact placement: the centre's velocity and the spin do not fix the rolling motion "
        "here (a degenerate contact: the object's and the hand's curvatures match, or a "
        "chart is singular)");
  const Eigen::Matrix<double, 10, 1> z = particular + Z * lu.solve(target - S * particular);
  const Eigen::Matrix<double, 10, 1> yv = z.cwiseQuotient(vc.scale);
  s.velocity = yv.segment<3>(0);
  s.angular_velocity = yv.segment<3>(3);
  s.sdot_o = yv.segment<2>(6);
  s.sdot_h = yv.segment<2>(8);
  return s;
}

SpatialRunResult simulate_spatial(const SpatialRollingProblem& pb, const HandMotion3& motion,
                                  const SpatialState& initial, double t0,
                                  const SpatialRunOptions& o) {
  check(pb, o, t0);
  SpatialIntegration in(pb, motion, o);
  return in.run(initial, t0);
}

}  // namespace flatland::sim
