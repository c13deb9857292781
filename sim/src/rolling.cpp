#include "flatland/sim/rolling.hpp"
#include "rolling_terms.hpp"

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

// Contact forces on the object and their ratios to its weight in the table plane: what the hand
// exerts besides gravity and the drag on the centre (m a = m g + f - c v).
void fill_forces(Sample& s, const RollingProblem& pb, const Vec2& accel, const Vec2& normal_w,
                 const Vec2& tangent_w, const Vec2& velocity) {
  const Vec2 force =
      pb.object.mass * (accel - pb.gravity_vector()) + pb.contact.drag * velocity;
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

// The power of the hand's contact force `force` (on the object, at the contact) and couple
// `couple` (on the object), split into what the hand's motion puts in (through the velocity of
// its own material point at the contact and its rate) and what the contact and the table take
// out: friction on the slip of the object's point over the hand's, the couple on the rotation
// relative to the hand, drag on the centre and its couple. hand + losses = dE/dt exactly.
Power contact_power(const RollingProblem& pb, const Vec2& force, double couple,
                    const Vec2& hand_point_velocity, double hand_rate,
                    const Vec2& object_point_velocity, const Vec2& centre_velocity,
                    double object_rate) {
  Power p;
  p.hand = force.dot(hand_point_velocity) + couple * hand_rate;
  p.losses = force.dot(object_point_velocity - hand_point_velocity) +
             couple * (object_rate - hand_rate) - pb.contact.drag * centre_velocity.squaredNorm() -
             pb.contact.drag_angular * object_rate * object_rate;
  return p;
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

double kinetic_energy(const RollingProblem& pb, const Sample& s) {
  return 0.5 * pb.object.mass * s.object_velocity.squaredNorm() +
         0.5 * pb.object.inertia * s.object_angular_velocity * s.object_angular_velocity;
}

double mechanical_energy(const RollingProblem& pb, const Sample& s) {
  return kinetic_energy(pb, s) - pb.object.mass * pb.gravity_vector().dot(s.object_position);
}

// =============================================================================================
// General formulation
// =============================================================================================

GeneralRolling::GeneralRolling(std::shared_ptr<const RollingProblem> problem, ContactPhase phase)
    : problem_(std::move(problem)), phase_(phase) {
  if (!problem_ || !problem_->hand || !problem_->object.boundary || !problem_->motion)
    throw std::invalid_argument("rolling problem: hand, object and motion are required");
  if (phase_.mode == ContactMode::kFlight)
    throw std::logic_error("general formulation: flight has no contact equations");
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
  //  (sliding: only their sum is tied, v_o + omega_o z x r_o + R_o J_o sdot_o = v_h + ...;
  //   at rest: sdot_h = sdot_o = 0.)
  const bool sliding = phase_.mode == ContactMode::kSliding;
  const double sdot_h = phase_.mode == ContactMode::kRest ? 0.0 : y[9];
  const double sdot_o = sliding                               ? y[8]
                        : phase_.mode == ContactMode::kRest ? 0.0
                                                              : Jo.dot(Jh) * sdot_h / go.speed / go.speed;
  const double omega_o =
      h.angular_velocity + perp(nh).dot(Ro * go.normal_ds * sdot_o + Rh * gh.normal_ds * sdot_h);
  y[2] = theta_o;
  y.segment<2>(0) = h.position + rh - ro;
  y.segment<2>(5) = h.velocity + h.angular_velocity * perp(rh) - omega_o * perp(ro);
  if (sliding) y.segment<2>(5) += Jh * sdot_h - Jo * sdot_o;
  y[7] = omega_o;
  y[8] = sdot_o;
  y[9] = sdot_h;
}

namespace {

/// A x = b at a state whose world geometry is `w`, solved (GeneralRolling::assemble_and_solve).
GeneralRolling::Assembled assemble_general(const RollingProblem& pb, const ContactPhase& phase,
                                           double t, const GeneralRolling::State& y,
                                           const Pieces& p, const WorldContact& w) {
  const double wh = w.hand.angular_velocity, ah = w.hand.angular_acceleration;
  const double wo = y[7], sdo = y[8], sdh = y[9];
  const Vec2 a_h = w.hand.acceleration;
  GeneralRolling::Assembled s;
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
  const Vec2 th = w.Jh / w.gh.speed;
  const double m = pb.object.mass;
  // The contact force f = m (a_o - g) + c v_o (the drag c v_o acts on the centre); g_d is what
  // f is when a_o = 0, divided by m.
  const Vec2 v_o = y.segment<2>(5);
  const Vec2 g_d = -pb.gravity_vector() + pb.contact.drag / m * v_o;
  if (phase.mode == ContactMode::kSliding) {
    // (3') Coulomb: f . t_h = -mu_k sign f . n_h, i.e. f . (t_h + mu_k sign n_h) = 0.
    const Vec2 dir = th + pb.contact.kinetic() * phase.sign * w.nh;
    A.block<1, 2>(4, 0) = dir.transpose();
    b(4) = -g_d.dot(dir);
  } else {
    // (3) rolling: material contact points have equal tangential acceleration (row scaled by
    // |J_h|).
    A.block<1, 2>(4, 0) = -th.transpose();
    A(4, 2) = -th.dot(perp(w.ro));
    b(4) = -th.dot(a_h + ah * perp(w.rh) - wh * wh * w.rh + wo * wo * w.ro);
  }
  if (phase.mode == ContactMode::kRest) {
    // At rest the object does not roll (sddot_h = 0); the couple that holds it is what row (4)
    // would leave over (sample()).
    A(5, 4) = 1.0;
    b(5) = 0.0;
  } else {
    // (4) the contact force passes through the contact point: I alpha_o = r_o x f + tau, divided
    //     by m, with tau the drag couple -c_w omega_o and, when rolling, the rolling-resistance
    //     couple eps delta sign(sdot_h) f_n. (Gravity and drag act at the centre: no moment.)
    //     While sliding, the couple is -delta f_n turn (it opposes the relative rotation).
    const double rho2 = pb.object.inertia / m;
    const double rr = phase.mode == ContactMode::kRolling
                          ? pb.hand->normal_side() * pb.contact.rolling_resistance * phase.sign
                          : -pb.contact.rolling_resistance * phase.turn;
    A(5, 0) = w.ro.y() - rr * w.nh.x();
    A(5, 1) = -w.ro.x() - rr * w.nh.y();
    A(5, 2) = rho2;
    b(5) = cross2(w.ro, g_d) + rr * w.nh.dot(g_d) - pb.contact.drag_angular / m * wo;
  }
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

/// The contact force on the object (m (a_o - g) + c v_o) and the couple besides its moment.
std::pair<Vec2, double> general_force_and_couple(const RollingProblem& pb,
                                                 const GeneralRolling::State& y,
                                                 const GeneralRolling::Assembled& s,
                                                 const WorldContact& w) {
  const Vec2 force = pb.object.mass * (s.x.segment<2>(0) - pb.gravity_vector()) +
                     pb.contact.drag * y.segment<2>(5);
  const double couple =
      pb.object.inertia * s.x[2] - cross2(w.ro, force) + pb.contact.drag_angular * y[7];
  return {force, couple};
}

}  // namespace

GeneralRolling::Assembled GeneralRolling::assemble_and_solve(double t, const State& y,
                                                             const Pieces& p) const {
  return assemble_general(*problem_, phase_, t, y, p,
                          world_contact(*problem_, t, y[2], y[3], y[4], p));
}

void GeneralRolling::derivative(double t, const State& y, const Pieces& p, State& dy,
                                Power* power) const {
  // Runge-Kutta stage states lie slightly off the contact manifold; the equations are evaluated
  // at the snapped state so that A x = b is consistent at every stage (otherwise the least-squares
  // solve splits the inconsistency, which costs two orders of magnitude in accuracy).
  State ys = y;
  snap(t, ys, p);
  const RollingProblem& pb = *problem_;
  const WorldContact w = world_contact(pb, t, ys[2], ys[3], ys[4], p);
  const Assembled s = assemble_general(pb, phase_, t, ys, p, w);
  dy.segment<5>(0) = ys.segment<5>(5);  // positions' rates: v_o, omega_o, sdot_o, sdot_h
  dy.segment<5>(5) = s.x;
  if (power) {
    const auto [force, couple] = general_force_and_couple(pb, ys, s, w);
    const Vec2 v_o = ys.segment<2>(5);
    const double omega_h = w.hand.angular_velocity;
    *power = contact_power(pb, force, couple, w.hand.velocity + omega_h * perp(w.rh), omega_h,
                           v_o + ys[7] * perp(w.ro), v_o, ys[7]);
  }
}

Sample GeneralRolling::sample(double t, const State& y, const Pieces& p) const {
  const RollingProblem& pb = *problem_;
  const WorldContact w = world_contact(pb, t, y[2], y[3], y[4], p);
  const Assembled s = assemble_general(pb, phase_, t, y, p, w);
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
  out.object_angular_acceleration = s.x[2];
  const Vec2 th = w.Jh / w.gh.speed;
  fill_forces(out, pb, s.x.segment<2>(0), w.nh, th, y.segment<2>(5));
  const Vec2 gap = w.hand.position + w.rh - y.segment<2>(0) - w.ro;
  out.constraint_residual = std::max(gap.norm(), (w.no + w.nh).norm());
  out.redundant_residual = s.residual;
  out.mode = phase_.mode;
  // Velocity of the object's material contact point relative to the hand's.
  const Vec2 v_rel = y.segment<2>(5) + y[7] * perp(w.ro) - w.hand.velocity -
                     w.hand.angular_velocity * perp(w.rh);
  out.slip_velocity = phase_.mode == ContactMode::kSliding ? v_rel.dot(th) : 0.0;
  // The couple on the object besides the contact force's moment and the drag couple.
  out.rolling_couple = general_force_and_couple(pb, y, s, w).second;
  return out;
}

// =============================================================================================
// Reduced formulation (disk)
//
// Centre of the disk: p = x_h + R q(s), q = c + r n (offset curve). With q' = sigma t,
// sigma = |J| (1 + r kappa), the disk's angular velocity for rolling is
// omega_o = theta' - side sigma s' / r (side = the hand's normal_side). d'Alembert along the
// admissible direction (delta p = sigma R t delta s, delta theta_o = -side sigma/r delta s):
//   m (p'' - g) . R t - side (I / r) alpha_o = Q,
// Q the generalised force of the losses (drag on the centre and its couple, the rolling-resistance
// couple). Expanding p'' and alpha_o and solving for s'' gives sddot() below (docs/DYNAMICS.md).
// =============================================================================================

namespace {

/// What every contact mode of a disk needs at one state: the centre's kinematics on the offset
/// curve and the parts of (p'' - g) that do not involve s''.
struct DiskTerms {
  Eigen::Matrix2d R;
  Vec2 q;                  ///< centre, hand frame
  double sigma, sigma_ds;  ///< |q'| and its derivative
  Vec2 N, T;               ///< hand's outward normal and tangent, world
  Vec2 velocity;           ///< centre, world
  double along;   ///< (p'' - g) . T without sigma' s'^2 + sigma s''
  double normal;  ///< (p'' - g) . N (independent of s'')
};

DiskTerms disk_terms(const RollingProblem& pb, double r, double side, const HandKinematics& h,
                     const CurveGeometry& g, double sdot) {
  DiskTerms d;
  const double one_rk = 1.0 + r * g.curvature;
  d.sigma = g.speed * one_rk;
  d.sigma_ds = g.speed_ds * one_rk + g.speed * r * g.curvature_ds;
  d.q = g.point + r * g.normal;
  d.R = rotation(h.angle);
  d.N = d.R * g.normal;
  d.T = d.R * g.tangent;
  const Vec2 a_local = d.R.transpose() * (h.acceleration - pb.gravity_vector());  // R^T (a_h - g)
  const double w = h.angular_velocity, al = h.angular_acceleration;
  d.along = a_local.dot(g.tangent) + al * perp(d.q).dot(g.tangent) - w * w * d.q.dot(g.tangent);
  d.normal = a_local.dot(g.normal) + al * perp(d.q).dot(g.normal) - w * w * d.q.dot(g.normal) +
             2.0 * side * w * d.sigma * sdot - d.sigma * g.curvature * g.speed * sdot * sdot;
  d.velocity = h.velocity + w * perp(d.R * d.q) + d.sigma * sdot * d.T;
  return d;
}

/// p'' in world axes for a centre moving on the offset curve with s' and s''.
Vec2 centre_acceleration(const HandKinematics& h, const CurveGeometry& g, const DiskTerms& d,
                         double sd, double sdd) {
  const double w = h.angular_velocity;
  // p'' = a_h + R [theta'' z x q - theta'^2 q + 2 theta' sigma s' z x t
  //                + (sigma' t - sigma kappa |J| n) s'^2 + sigma s'' t]
  const Vec2 local = h.angular_acceleration * perp(d.q) - w * w * d.q +
                     2.0 * w * d.sigma * sd * perp(g.tangent) +
                     (d.sigma_ds * g.tangent - d.sigma * g.curvature * g.speed * g.normal) * sd * sd +
                     d.sigma * sdd * g.tangent;
  return h.acceleration + d.R * local;
}

/// Normal force f_n = m (p'' - g) . N + c v . N (independent of the tangential mode).
double normal_force(const RollingProblem& pb, const DiskTerms& d) {
  return pb.object.mass * d.normal + pb.contact.drag * d.velocity.dot(d.N);
}

void check_fits(const RollingProblem& pb, double r, double t, double s_h, double sigma,
                const Pieces& p, const char* who) {
  // sigma > 0 is the disk fitting the hand's concave parts (r kappa > -1); at sigma = 0 the
  // equation divides by zero (the contact point is not determined), so say so instead of
  // producing inf/NaN. validate_hand_for_disk rules this out for the paper's hands.
  // Only inside the active piece (stages may overshoot a junction onto the piece's extension,
  // where a non-finite value just makes the step fail and shrink).
  const PieceInterval iv = pb.hand->piece_interval(p.hand);
  if (!(sigma > 0) && s_h >= iv.lo && s_h <= iv.hi) {
    const CurveGeometry g = pb.hand->geometry(s_h, p.hand);
    std::ostringstream os;
    os.precision(8);
    os << who << ": the disk does not fit the hand at t=" << t << " s, s_h=" << s_h
       << " (r*kappa = " << r * g.curvature << ", needs > -1: curvature radius "
       << (g.curvature != 0 ? -1.0 / g.curvature : 0.0) << " m vs disk radius " << r << " m)";
    throw std::runtime_error(os.str());
  }
}

}  // namespace

ReducedDiskRolling::ReducedDiskRolling(std::shared_ptr<const RollingProblem> problem,
                                       ContactPhase phase)
    : problem_(std::move(problem)), phase_(phase) {
  if (!problem_ || !problem_->hand || !problem_->motion)
    throw std::invalid_argument("rolling problem: hand, object and motion are required");
  if (!problem_->object.disk_radius)
    throw std::invalid_argument(
        "integrator.formulation: 'reduced' needs a disk object; use 'general' for " +
        problem_->object.kind);
  if (phase_.mode != ContactMode::kRolling && phase_.mode != ContactMode::kRest)
    throw std::logic_error("reduced rolling: the phase must be rolling or rest");
  r_ = *problem_->object.disk_radius;
  rho2_ = problem_->object.inertia / problem_->object.mass;
  side_ = problem_->hand->normal_side();
  rest_ = phase_.mode == ContactMode::kRest;
  losses_ = problem_->contact.has_losses();
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

double ReducedDiskRolling::sddot(const HandKinematics& h, const CurveGeometry& g, double sdot,
                                 Power* power) const {
  if (rest_ && !power) return 0.0;
  const RollingProblem& pb = *problem_;
  const detail::RollingTerms<double> k = detail::rolling_terms(h, g, r_, pb.gravity_vector());
  const double sigma = k.sigma, c = k.cos_angle, s = k.sin_angle;
  const Vec2& q = k.q;
  double sdd = 0.0;
  if (!rest_) {
    double drive = detail::rolling_drive(h, g, k, r_, rho2_, side_);
    if (losses_) {
      // Q / m: drag on the centre along the rolling direction, the drag couple and the
      // rolling-resistance couple eps delta sign(s') f_n, through the lever -eps sigma / r.
      const DiskTerms d = disk_terms(pb, r_, side_, h, g, sdot);
      const double m = pb.object.mass;
      const double omega_o = h.angular_velocity - side_ * sigma * sdot / r_;
      const double couple =
          side_ * pb.contact.rolling_resistance * phase_.sign * normal_force(pb, d) -
          pb.contact.drag_angular * omega_o;
      drive += pb.contact.drag / m * d.velocity.dot(d.T) + side_ * couple / (m * r_);
    }
    sdd = detail::rolling_sddot(k, drive, sdot, r_, rho2_);
  }
  if (power) {
    // The energy audit's powers, in the hand's axes (dot products do not care), from the terms
    // above: no second rotation, the centre's acceleration as centre_acceleration() has it.
    const double w = h.angular_velocity;
    const Vec2& T = g.tangent;
    const Vec2 v_pivot(c * h.velocity.x() + s * h.velocity.y(),
                       -s * h.velocity.x() + c * h.velocity.y());  // R^T v_h
    const Vec2 v_hand = v_pivot + w * perp(g.point);  // the hand's point at the contact
    const double ssd = sigma * sdot;
    const Vec2 accel = detail::relative_acceleration(h, g, k, sdot, sdd);  // R^T (p'' - g)
    if (!losses_ && !rest_) {  // the paper's rolling: the contact force's work through the hand
      power->hand = pb.object.mass * accel.dot(v_hand);
      power->losses = 0.0;
      return sdd;
    }
    const Vec2 v_centre = v_pivot + w * perp(q) + ssd * T;
    const Vec2 force = pb.object.mass * accel + pb.contact.drag * v_centre;
    const double omega_o = w - side_ * ssd / r_;
    // Rolling: the rolling-resistance couple against the rolling; at rest, the couple that holds
    // the disk (as sample_with reports them).
    const double couple =
        rest_ ? pb.object.inertia * h.angular_acceleration - side_ * r_ * force.dot(T) +
                    pb.contact.drag_angular * omega_o
              : side_ * pb.contact.rolling_resistance * phase_.sign * force.dot(g.normal);
    // Rolling, the disk's contact point moves with the hand's.
    *power = contact_power(pb, force, couple, v_hand, w, v_hand, v_centre, omega_o);
  }
  return sdd;
}

void ReducedDiskRolling::derivative(double t, const State& y, const Pieces& p, State& dy,
                                    Power* power) const {
  const HandKinematics h = problem_->motion->at(t, p.motion);
  const CurveGeometry g = problem_->hand->geometry(y[0], p.hand);
  const double sigma = g.speed * (1.0 + r_ * g.curvature);
  if (!(sigma > 0)) check_fits(*problem_, r_, t, y[0], sigma, p, "reduced formulation");
  dy[0] = y[2];
  dy[1] = h.angular_velocity - side_ * sigma * y[2] / r_;
  dy[2] = sddot(h, g, y[2], power);
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
  const DiskTerms d = disk_terms(pb, r_, side_, h, g, sd);
  const double w = h.angular_velocity;
  Sample out;
  fill_hand(out, t, h);
  out.s_h = y[0];
  out.sdot_h = sd;
  out.sddot_h = sdd;
  out.object_angle = y[1];
  out.s_o = wrap_pi(angle_of(-d.N) - y[1]);
  out.sdot_o = side_ * g.speed * sd / r_;
  out.object_position = h.position + d.R * d.q;
  out.object_velocity = d.velocity;
  out.object_angular_velocity = w - side_ * d.sigma * sd / r_;
  out.object_angular_acceleration =
      h.angular_acceleration - side_ * (d.sigma_ds * sd * sd + d.sigma * sdd) / r_;
  fill_forces(out, pb, centre_acceleration(h, g, d, sd, sdd), d.N, d.T, d.velocity);
  out.mode = phase_.mode;
  if (phase_.mode == ContactMode::kRest) {
    // The couple that keeps the disk from rolling: I alpha_o - eps r f_t + c_w omega_o, with
    // alpha_o = theta'' (the disk turns with the hand).
    out.rolling_couple = pb.object.inertia * h.angular_acceleration -
                         side_ * r_ * out.force_tangential +
                         pb.contact.drag_angular * out.object_angular_velocity;
  } else {
    out.rolling_couple =
        side_ * pb.contact.rolling_resistance * phase_.sign * out.force_normal;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Sliding disk: the centre on the offset curve (f_n from the normal constraint, as in rolling),
// f_t = -mu_k sign f_n, and the disk's own rotation I omega' = eps r f_t - c_w omega.

ReducedDiskSliding::ReducedDiskSliding(std::shared_ptr<const RollingProblem> problem,
                                       int slip_sign, int turn)
    : problem_(std::move(problem)), phase_{ContactMode::kSliding, slip_sign, turn} {
  if (!problem_ || !problem_->hand || !problem_->motion)
    throw std::invalid_argument("rolling problem: hand, object and motion are required");
  if (!problem_->object.disk_radius)
    throw std::invalid_argument("sliding (reduced formulation): needs a disk object");
  if (slip_sign != 1 && slip_sign != -1)
    throw std::logic_error("sliding: the slip sign must be +1 or -1");
  r_ = *problem_->object.disk_radius;
  side_ = problem_->hand->normal_side();
}

Pieces ReducedDiskSliding::pieces_for(const State& y, int direction) const {
  return {problem_->hand->piece_at(y[0], direction), 0, 0};
}

namespace {

/// The sliding disk's contact forces and accelerations at one state (s', omega).
struct SlidingDynamics {
  DiskTerms terms;
  double f_n = 0, f_t = 0, couple = 0, sddot = 0, omega_dot = 0;
};

SlidingDynamics sliding_dynamics(const RollingProblem& pb, double r, double side,
                                 const ContactPhase& phase, const HandKinematics& h,
                                 const CurveGeometry& g, double sdot, double omega) {
  SlidingDynamics out{disk_terms(pb, r, side, h, g, sdot)};
  const DiskTerms& d = out.terms;
  out.f_n = normal_force(pb, d);
  out.f_t = -pb.contact.kinetic() * phase.sign * out.f_n;
  out.couple = -pb.contact.rolling_resistance * phase.turn * out.f_n;
  out.sddot = ((out.f_t - pb.contact.drag * d.velocity.dot(d.T)) / pb.object.mass - d.along -
               d.sigma_ds * sdot * sdot) /
              d.sigma;
  out.omega_dot =
      (side * r * out.f_t + out.couple - pb.contact.drag_angular * omega) / pb.object.inertia;
  return out;
}

}  // namespace

void ReducedDiskSliding::derivative(double t, const State& y, const Pieces& p, State& dy,
                                    Power* power) const {
  const RollingProblem& pb = *problem_;
  const HandKinematics h = pb.motion->at(t, p.motion);
  const CurveGeometry g = pb.hand->geometry(y[0], p.hand);
  const SlidingDynamics a = sliding_dynamics(pb, r_, side_, phase_, h, g, y[2], y[3]);
  if (!(a.terms.sigma > 0)) check_fits(pb, r_, t, y[0], a.terms.sigma, p, "sliding");
  dy[0] = y[2];
  dy[1] = y[3];
  dy[2] = a.sddot;
  dy[3] = a.omega_dot;
  if (power) {
    const DiskTerms& d = a.terms;
    const Vec2 force = a.f_n * d.N + a.f_t * d.T;
    // The disk's contact point lies r behind its centre along the hand's normal.
    const Vec2 v_object = d.velocity - r_ * y[3] * perp(d.N);
    const Vec2 v_hand = h.velocity + h.angular_velocity * perp(d.R * g.point);
    *power =
        contact_power(pb, force, a.couple, v_hand, h.angular_velocity, v_object, d.velocity, y[3]);
  }
}

Sample ReducedDiskSliding::sample(double t, const State& y, const Pieces& p) const {
  return sample_with(problem_->motion->at(t, p.motion), t, y, p.hand);
}

Sample ReducedDiskSliding::sample_with(const HandKinematics& h, double t, const State& y,
                                       int hand_piece) const {
  const RollingProblem& pb = *problem_;
  const CurveGeometry g = pb.hand->geometry(y[0], hand_piece);
  const SlidingDynamics a = sliding_dynamics(pb, r_, side_, phase_, h, g, y[2], y[3]);
  const DiskTerms& d = a.terms;
  Sample out;
  fill_hand(out, t, h);
  out.s_h = y[0];
  out.sdot_h = y[2];
  out.sddot_h = a.sddot;
  out.object_angle = y[1];
  out.s_o = wrap_pi(angle_of(-d.N) - y[1]);
  // The contact point moves over the disk at the rate the normal turns relative to it.
  out.sdot_o = h.angular_velocity - side_ * g.curvature * g.speed * y[2] - y[3];
  out.object_position = h.position + d.R * d.q;
  out.object_velocity = d.velocity;
  out.object_angular_velocity = y[3];
  out.object_angular_acceleration = a.omega_dot;
  fill_forces(out, pb, centre_acceleration(h, g, d, y[2], a.sddot), d.N, d.T, d.velocity);
  out.mode = ContactMode::kSliding;
  out.slip_velocity = d.sigma * y[2] + side_ * r_ * (y[3] - h.angular_velocity);
  out.rolling_couple = a.couple;
  return out;
}

}  // namespace flatland::sim
