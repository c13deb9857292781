#include "flatland/sim/rolling.hpp"

#include <Eigen/QR>

#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace flatland::sim {

namespace {

Eigen::Matrix2d rotation(double angle) {
  const double c = std::cos(angle), s = std::sin(angle);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  return r;
}

double wrap_pi(double a) { return std::remainder(a, 2.0 * std::numbers::pi); }

double angle_of(const Vec2& v) { return std::atan2(v.y(), v.x()); }

// Contact forces on the object and their ratios to its weight in the table plane.
void fill_forces(Sample& s, const RollingProblem& pb, const Vec2& accel, const Vec2& normal_w,
                 const Vec2& tangent_w) {
  const Vec2 force = pb.object.mass * (accel - pb.gravity_vector());
  const double weight = pb.object.mass * pb.gravity;
  s.force_normal = force.dot(normal_w);
  s.force_tangential = force.dot(tangent_w);
  s.fn_ratio = s.force_normal / weight;
  s.ft_ratio = s.force_tangential / weight;
  s.mu_required = s.force_normal > 0 ? std::abs(s.force_tangential) / s.force_normal
                                     : std::numeric_limits<double>::infinity();
}

void fill_hand(Sample& s, double t, const HandKinematics& h) {
  s.t = t;
  s.theta = h.angle;
  s.theta_dot = h.angular_velocity;
  s.theta_ddot = h.angular_acceleration;
}

// Hand and object geometry in world axes at one state of the general formulation.
struct WorldContact {
  HandKinematics hand;
  CurveGeometry gh, go;
  Eigen::Matrix2d Rh, Ro;
  Vec2 rh, Jh, Jh_ds, nh, Kh, Kh_ds;  // hand: pivot->contact, J, dJ/ds, n, K, dK/ds (world axes)
  Vec2 ro, Jo, Jo_ds, no, Ko, Ko_ds;  // object: CoM->contact, ...
};

WorldContact world_contact(const RollingProblem& pb, double t, double theta_o, double s_o,
                           double s_h, const Pieces& p) {
  WorldContact w;
  w.hand = pb.motion->at(t, p.motion);
  w.gh = pb.hand->geometry(s_h, p.hand);
  w.go = pb.object.boundary->geometry(s_o, p.object);
  w.Rh = rotation(w.hand.angle);
  w.Ro = rotation(theta_o);
  w.rh = w.Rh * w.gh.point;
  w.Jh = w.Rh * w.gh.jacobian;
  w.Jh_ds = w.Rh * w.gh.jacobian_ds;
  w.nh = w.Rh * w.gh.normal;
  w.Kh = w.Rh * w.gh.normal_ds;
  w.Kh_ds = w.Rh * w.gh.normal_dss;
  w.ro = w.Ro * w.go.point;
  w.Jo = w.Ro * w.go.jacobian;
  w.Jo_ds = w.Ro * w.go.jacobian_ds;
  w.no = w.Ro * w.go.normal;
  w.Ko = w.Ro * w.go.normal_ds;
  w.Ko_ds = w.Ro * w.go.normal_dss;
  return w;
}

}  // namespace

// =============================================================================================
// General formulation
// =============================================================================================

GeneralRolling::GeneralRolling(std::shared_ptr<const RollingProblem> problem)
    : problem_(std::move(problem)) {
  if (!problem_ || !problem_->hand || !problem_->object.boundary || !problem_->motion)
    throw std::invalid_argument("rolling problem: hand, object and motion are required");
}

Pieces GeneralRolling::pieces_for(const State& y, int direction) const {
  // The object parameter moves with the hand parameter (equal arc length, sign from the
  // relative orientation); single-piece objects ignore it anyway.
  return {problem_->hand->piece_at(y[4], direction), problem_->object.boundary->piece_at(y[3], +1),
          0};
}

GeneralRolling::State GeneralRolling::initial_state(const InitialContact& init) const {
  const RollingProblem& pb = *problem_;
  State y = State::Zero();
  y[4] = init.s_h;
  y[9] = init.sdot_h;
  const int dir = init.sdot_h < 0 ? -1 : +1;
  const HandKinematics h = pb.motion->at(init.t0);
  const Vec2 nh =
      rotation(h.angle) * pb.hand->geometry(init.s_h, pb.hand->piece_at(init.s_h, dir)).normal;
  if (init.s_o) {
    y[3] = *init.s_o;
    y[2] = 0.0;
  } else if (pb.object.disk_radius) {
    // A circle's outward normal at parameter s_o is (cos s_o, sin s_o) in the object frame.
    y[2] = init.object_angle;
    y[3] = angle_of(-nh) - init.object_angle;
  } else {
    y[3] = -0.5 * std::numbers::pi;
  }
  if (init.s_o || !pb.object.disk_radius) {
    const Vec2 no = pb.object.boundary->geometry(y[3]).normal;
    y[2] = angle_of(-nh) - angle_of(no);
  }
  project(init.t0, y, pieces_for(y, dir));
  return y;
}

double GeneralRolling::constraint_residual(double t, const State& y, const Pieces& p) const {
  const WorldContact w = world_contact(*problem_, t, y[2], y[3], y[4], p);
  const Vec2 gap = w.hand.position + w.rh - y.segment<2>(0) - w.ro;
  return std::max(gap.norm(), (w.no + w.nh).norm());
}

double GeneralRolling::project(double t, State& y, const Pieces& p) const {
  const double before = constraint_residual(t, y, p);
  snap(t, y, p);
  return before;
}

void GeneralRolling::snap(double t, State& y, const Pieces& p) const {
  const RollingProblem& pb = *problem_;
  const HandKinematics h = pb.motion->at(t, p.motion);
  const Eigen::Matrix2d Rh = rotation(h.angle);
  const CurveGeometry gh = pb.hand->geometry(y[4], p.hand);
  const CurveGeometry go = pb.object.boundary->geometry(y[3], p.object);
  const Vec2 nh = Rh * gh.normal;
  // Orientation: R_o n_o = -n_h, on the branch nearest the integrated angle.
  const double target = angle_of(-nh) - angle_of(go.normal);
  const double theta_o = y[2] + wrap_pi(target - y[2]);
  const Eigen::Matrix2d Ro = rotation(theta_o);
  const Vec2 rh = Rh * gh.point, ro = Ro * go.point;
  const Vec2 Jh = Rh * gh.jacobian, Jo = Ro * go.jacobian;
  // Velocities from the first derivatives of the contact constraints, given sdot_h:
  //  contact point moves at the same rate along both outlines: R_o J_o sdot_o = R_h J_h sdot_h;
  //  normals stay opposite: omega_o = omega_h + p . (R_o K_o sdot_o + R_h K_h sdot_h), p = z x n_h;
  //  rolling: v_o + omega_o z x r_o = v_h + omega_h z x r_h.
  const double sdot_h = y[9];
  const double sdot_o = Jo.dot(Jh) * sdot_h / go.speed / go.speed;
  const double omega_o =
      h.angular_velocity + perp(nh).dot(Ro * go.normal_ds * sdot_o + Rh * gh.normal_ds * sdot_h);
  y[2] = theta_o;
  y.segment<2>(0) = h.position + rh - ro;
  y.segment<2>(5) = h.velocity + h.angular_velocity * perp(rh) - omega_o * perp(ro);
  y[7] = omega_o;
  y[8] = sdot_o;
}

GeneralRolling::Assembled GeneralRolling::assemble_and_solve(double t, const State& y,
                                                             const Pieces& p) const {
  const RollingProblem& pb = *problem_;
  const WorldContact w = world_contact(pb, t, y[2], y[3], y[4], p);
  const double wh = w.hand.angular_velocity, ah = w.hand.angular_acceleration;
  const double wo = y[7], sdo = y[8], sdh = y[9];
  const Vec2 a_h = w.hand.acceleration;
  Assembled s;
  auto& A = s.A;
  auto& b = s.b;
  A.setZero();
  // (1) contact position, twice differentiated (2 rows).
  A.block<2, 2>(0, 0) = -Eigen::Matrix2d::Identity();
  A.block<2, 1>(0, 2) = -perp(w.ro);
  A.block<2, 1>(0, 3) = -w.Jo;
  A.block<2, 1>(0, 4) = w.Jh;
  b.segment<2>(0) =
      -(a_h + ah * perp(w.rh) - wh * wh * w.rh + 2.0 * wh * sdh * perp(w.Jh) + w.Jh_ds * sdh * sdh +
        wo * wo * w.ro - 2.0 * wo * sdo * perp(w.Jo) - w.Jo_ds * sdo * sdo);
  // (2) opposite unit normals, twice differentiated (2 rows; the one along n is redundant).
  A.block<2, 1>(2, 2) = perp(w.no);
  A.block<2, 1>(2, 3) = w.Ko;
  A.block<2, 1>(2, 4) = w.Kh;
  b.segment<2>(2) =
      -(-wo * wo * w.no + 2.0 * wo * sdo * perp(w.Ko) + w.Ko_ds * sdo * sdo + ah * perp(w.nh) -
        wh * wh * w.nh + 2.0 * wh * sdh * perp(w.Kh) + w.Kh_ds * sdh * sdh);
  // (3) rolling: material contact points have equal tangential acceleration (row scaled by |J_h|).
  const Vec2 th = w.Jh / w.gh.speed;
  A.block<1, 2>(4, 0) = -th.transpose();
  A(4, 2) = -th.dot(perp(w.ro));
  b(4) = -th.dot(a_h + ah * perp(w.rh) - wh * wh * w.rh + wo * wo * w.ro);
  // (4) the contact force passes through the contact point: I alpha_o = r_o x m (a_o - g),
  //     divided by m. (Gravity acts at the centre of mass and has no moment about it.)
  const double rho2 = pb.object.inertia / pb.object.mass;
  A(5, 0) = w.ro.y();
  A(5, 1) = -w.ro.x();
  A(5, 2) = rho2;
  b(5) = -cross2(w.ro, pb.gravity_vector());
  Eigen::ColPivHouseholderQR<Eigen::Matrix<double, 6, 5>> qr(A);
  // A loses rank when the contact is degenerate, e.g. conforming curvatures (kappa_h + kappa_o = 0:
  // a disk lying in a well of its own radius), where s_o'' and s_h'' are not determined; the
  // least-squares solve would then return one arbitrary split of them, so refuse instead. Pivots
  // below 1e-10 of the largest are zero: a genuine contact (r kappa = -0.99) is at ~1e-2.
  // Only inside the active piece: Runge-Kutta stages and event trials may evaluate a piece's
  // polynomial extension past its junction, whose curvature means nothing physical.
  qr.setThreshold(1e-10);
  const PieceInterval iv = pb.hand->piece_interval(p.hand);
  if (qr.rank() < 5 && y[4] >= iv.lo && y[4] <= iv.hi) {
    std::ostringstream os;
    os.precision(8);
    os << "general formulation: A is rank-deficient (rank " << qr.rank() << " of 5) at t=" << t
       << " s, s_h=" << y[4] << ", s_o=" << y[3] << ": degenerate contact (hand curvature "
       << w.gh.curvature << " 1/m, object curvature " << w.go.curvature
       << " 1/m; conforming when they cancel)";
    throw std::runtime_error(os.str());
  }
  s.x = qr.solve(b);
  s.residual = (A * s.x - b).norm();
  return s;
}

void GeneralRolling::derivative(double t, const State& y, const Pieces& p, State& dy) const {
  // Runge-Kutta stage states lie slightly off the contact manifold; the equations are evaluated
  // at the snapped state so that A x = b is consistent at every stage (otherwise the least-squares
  // solve splits the inconsistency, which costs two orders of magnitude in accuracy).
  State ys = y;
  snap(t, ys, p);
  const Assembled s = assemble_and_solve(t, ys, p);
  dy.segment<5>(0) = ys.segment<5>(5);  // positions' rates: v_o, omega_o, sdot_o, sdot_h
  dy.segment<5>(5) = s.x;
}

Sample GeneralRolling::sample(double t, const State& y, const Pieces& p) const {
  const RollingProblem& pb = *problem_;
  const Assembled s = assemble_and_solve(t, y, p);
  const WorldContact w = world_contact(pb, t, y[2], y[3], y[4], p);
  Sample out;
  fill_hand(out, t, w.hand);
  out.s_h = y[4];
  out.sdot_h = y[9];
  out.sddot_h = s.x[4];
  out.s_o = wrap_pi(y[3]);
  out.sdot_o = y[8];
  out.object_position = y.segment<2>(0);
  out.object_angle = y[2];
  out.object_velocity = y.segment<2>(5);
  out.object_angular_velocity = y[7];
  fill_forces(out, pb, s.x.segment<2>(0), w.nh, w.Jh / w.gh.speed);
  const Vec2 gap = w.hand.position + w.rh - y.segment<2>(0) - w.ro;
  out.constraint_residual = std::max(gap.norm(), (w.no + w.nh).norm());
  out.redundant_residual = s.residual;
  return out;
}

// =============================================================================================
// Reduced formulation (disk)
//
// Centre of the disk: p = x_h + R q(s), q = c + r n (offset curve). With q' = sigma t,
// sigma = |J| (1 + r kappa), the disk's angular velocity for rolling is
// omega_o = theta' - side sigma s' / r (side = the hand's normal_side). d'Alembert along the
// admissible direction (delta p = sigma R t delta s, delta theta_o = -side sigma/r delta s):
//   m (p'' - g) . R t - side (I / r) alpha_o = 0.
// Expanding p'' and alpha_o and solving for s'' gives sddot() below (docs/DYNAMICS.md).
// =============================================================================================

ReducedDiskRolling::ReducedDiskRolling(std::shared_ptr<const RollingProblem> problem)
    : problem_(std::move(problem)) {
  if (!problem_ || !problem_->hand || !problem_->motion)
    throw std::invalid_argument("rolling problem: hand, object and motion are required");
  if (!problem_->object.disk_radius)
    throw std::invalid_argument(
        "integrator.formulation: 'reduced' needs a disk object; use 'general' for " +
        problem_->object.kind);
  r_ = *problem_->object.disk_radius;
  rho2_ = problem_->object.inertia / problem_->object.mass;
  side_ = problem_->hand->normal_side();
}

Pieces ReducedDiskRolling::pieces_for(const State& y, int direction) const {
  return {problem_->hand->piece_at(y[0], direction), 0, 0};
}

ReducedDiskRolling::State ReducedDiskRolling::initial_state(const InitialContact& init) const {
  State y;
  y[0] = init.s_h;
  y[2] = init.sdot_h;
  if (init.s_o) {
    const int dir = init.sdot_h < 0 ? -1 : +1;
    const HandKinematics h = problem_->motion->at(init.t0);
    const Vec2 nh =
        rotation(h.angle) *
        problem_->hand->geometry(init.s_h, problem_->hand->piece_at(init.s_h, dir)).normal;
    y[1] = angle_of(-nh) - *init.s_o;
  } else {
    y[1] = init.object_angle;
  }
  return y;
}

double ReducedDiskRolling::sddot(const HandKinematics& h, const CurveGeometry& g,
                                 double sdot) const {
  const double one_rk = 1.0 + r_ * g.curvature;
  const double sigma = g.speed * one_rk;
  const double sigma_ds = g.speed_ds * one_rk + g.speed * r_ * g.curvature_ds;
  const Vec2 q = g.point + r_ * g.normal;
  const double c = std::cos(h.angle), s = std::sin(h.angle);
  const Vec2 a = h.acceleration - problem_->gravity_vector();
  const Vec2 a_local(c * a.x() + s * a.y(), -s * a.x() + c * a.y());  // R^T (a_h - g)
  const double th2 = h.angular_velocity * h.angular_velocity;
  const double drive = a_local.dot(g.tangent) + h.angular_acceleration * perp(q).dot(g.tangent) -
                       th2 * q.dot(g.tangent) - side_ * rho2_ / r_ * h.angular_acceleration;
  return -(sigma_ds * sdot * sdot + drive / (1.0 + rho2_ / (r_ * r_))) / sigma;
}

void ReducedDiskRolling::derivative(double t, const State& y, const Pieces& p, State& dy) const {
  const HandKinematics h = problem_->motion->at(t, p.motion);
  const CurveGeometry g = problem_->hand->geometry(y[0], p.hand);
  const double sigma = g.speed * (1.0 + r_ * g.curvature);
  // sigma > 0 is the disk fitting the hand's concave parts (r kappa > -1); at sigma = 0 the
  // equation divides by zero (the contact point is not determined), so say so instead of
  // producing inf/NaN. validate_hand_for_disk rules this out for the paper's hands.
  // Only inside the active piece (stages may overshoot a junction onto the piece's extension,
  // where a non-finite value just makes the step fail and shrink).
  const PieceInterval iv = problem_->hand->piece_interval(p.hand);
  if (!(sigma > 0) && y[0] >= iv.lo && y[0] <= iv.hi) {
    std::ostringstream os;
    os.precision(8);
    os << "reduced formulation: the disk does not fit the hand at t=" << t << " s, s_h=" << y[0]
       << " (r*kappa = " << r_ * g.curvature << ", needs > -1: curvature radius "
       << (g.curvature != 0 ? -1.0 / g.curvature : 0.0) << " m vs disk radius " << r_ << " m)";
    throw std::runtime_error(os.str());
  }
  dy[0] = y[2];
  dy[1] = h.angular_velocity - side_ * sigma * y[2] / r_;
  dy[2] = sddot(h, g, y[2]);
}

double ReducedDiskRolling::acceleration(const HandKinematics& h, double s_h, double sdot_h,
                                        int hand_piece) const {
  return sddot(h, problem_->hand->geometry(s_h, hand_piece), sdot_h);
}

Sample ReducedDiskRolling::sample(double t, const State& y, const Pieces& p) const {
  return sample_with(problem_->motion->at(t, p.motion), t, y, p.hand);
}

Sample ReducedDiskRolling::sample_with(const HandKinematics& h, double t, const State& y,
                                       int hand_piece) const {
  const RollingProblem& pb = *problem_;
  const CurveGeometry g = pb.hand->geometry(y[0], hand_piece);
  const double sd = y[2];
  const double sdd = sddot(h, g, sd);
  const double one_rk = 1.0 + r_ * g.curvature;
  const double sigma = g.speed * one_rk;
  const double sigma_ds = g.speed_ds * one_rk + g.speed * r_ * g.curvature_ds;
  const Vec2 q = g.point + r_ * g.normal;
  const Eigen::Matrix2d R = rotation(h.angle);
  const double w = h.angular_velocity;
  // p'' = a_h + R [theta'' z x q - theta'^2 q + 2 theta' sigma s' z x t
  //                + (sigma' t - sigma kappa |J| n) s'^2 + sigma s'' t]
  const Vec2 local = h.angular_acceleration * perp(q) - w * w * q +
                     2.0 * w * sigma * sd * perp(g.tangent) +
                     (sigma_ds * g.tangent - sigma * g.curvature * g.speed * g.normal) * sd * sd +
                     sigma * sdd * g.tangent;
  Sample out;
  fill_hand(out, t, h);
  out.s_h = y[0];
  out.sdot_h = sd;
  out.sddot_h = sdd;
  const Vec2 nw = R * g.normal;
  out.object_angle = y[1];
  out.s_o = wrap_pi(angle_of(-nw) - y[1]);
  out.sdot_o = side_ * g.speed * sd / r_;
  out.object_position = h.position + R * q;
  out.object_velocity = h.velocity + w * perp(R * q) + sigma * sd * (R * g.tangent);
  out.object_angular_velocity = w - side_ * sigma * sd / r_;
  fill_forces(out, pb, h.acceleration + R * local, nw, R * g.tangent);
  return out;
}

}  // namespace flatland::sim
