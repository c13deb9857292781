// Rolling dynamics of a planar object on a moving planar hand (paper section 3).
//
// Two formulations of the same physics:
//  * GeneralRolling: the paper's equations (1)-(4) assembled as A x = b (6 x 5) in the redundant
//    coordinates (object pose, s_o, s_h and their rates) and solved by column-pivoting Householder
//    QR (least squares; the residual of the redundant row is reported). After every accepted step
//    the state is projected back onto the contact manifold ("snapping"): the object pose and
//    velocities are rebuilt from (s_h, s_o, sdot_h).
//  * ReducedDiskRolling: a disk on a hand has one degree of freedom; its equation of motion in
//    s_h alone follows from d'Alembert's principle along the rolling direction (derivation in
//    docs/DYNAMICS.md). It is the fast path, used whenever the object is a disk.
// Both take the hand's motion (pose, velocity, acceleration) as input.
#pragma once

#include "flatland/sim/contact.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/energy.hpp"
#include "flatland/sim/motion.hpp"
#include "flatland/sim/object.hpp"

#include <Eigen/Core>

#include <memory>
#include <optional>

namespace flatland::sim {

/// Everything one run needs; immutable, shared between threads.
struct RollingProblem {
  CurvePtr hand;  ///< outline in the hand frame (pivot at origin)
  RigidObject object;
  std::shared_ptr<const HandMotion> motion;
  double gravity = 9.8;  ///< effective gravity in the table plane, m/s^2,
                         ///< acting along world -y (= g sin(tilt))
  /// Friction, restitution and losses. The rolling model uses only mu (as a stopping event);
  /// the losses enter every formulation's equations when set.
  ContactLaw contact;
  Vec2 gravity_vector() const { return {0.0, -gravity}; }
};

/// Which contact equations a formulation integrates over one segment of a run.
struct ContactPhase {
  ContactMode mode = ContactMode::kRolling;  ///< kRolling, kRest or kSliding
  /// kSliding: the sign of the slip velocity (+1 / -1), which the kinetic friction opposes.
  /// kRolling with rolling resistance: the sign of sdot_h, which the couple opposes (0: none).
  int sign = 0;
  /// kSliding with rolling resistance: the sign of the object's rotation relative to the hand,
  /// omega_o - omega_h, which the couple -delta f_n turn opposes (0: none yet).
  int turn = 0;
};

/// Where the object starts: hand contact parameter and its rate; the object's contact point s_o
/// (boundary parameter) or, for a disk, its angle.
struct InitialContact {
  double t0 = 0.0;
  double s_h = -1.0;
  double sdot_h = 0.0;
  /// Contact parameter on the object. Default: for a disk, chosen so the object angle is
  /// `object_angle`; for other objects -pi/2 (the bottom of its outline in its own frame).
  std::optional<double> s_o;
  double object_angle = 0.0;  ///< rad, used for disks when s_o is not given
};

/// Active smooth pieces of the hand and object outlines during one integration segment.
struct Pieces {
  int hand = 0;
  int object = 0;
  int motion = 0;  ///< segment of the hand motion
};

/// Everything known about the system at one instant.
struct Sample {
  double t = 0;
  double theta = 0, theta_dot = 0, theta_ddot = 0;  ///< hand angle, rad
  double s_h = 0, sdot_h = 0, sddot_h = 0;          ///< hand contact parameter
  double s_o = 0, sdot_o = 0;           ///< object contact parameter (wrapped to (-pi, pi])
  Vec2 object_position = Vec2::Zero();  ///< centre of mass, world, m
  double object_angle = 0;              ///< rad, unwrapped
  Vec2 object_velocity = Vec2::Zero();
  double object_angular_velocity = 0;
  double object_angular_acceleration = 0;
  double force_normal = 0;      ///< N, hand on object along the hand's outward normal (> 0 pushes)
  double force_tangential = 0;  ///< N, along the hand's tangent (direction of increasing s_h)
  double fn_ratio = 0;          ///< force_normal / (m g_eff)
  double ft_ratio = 0;          ///< force_tangential / (m g_eff)
  double mu_required = 0;       ///< |f_t| / f_n (infinite when f_n <= 0; NaN in flight)
  double constraint_residual = 0;  ///< max(|contact point gap| in m, |n_o + n_h|), 0 for reduced
  double redundant_residual = 0;   ///< |A x - b| of the 6 x 5 solve (general), 0 for reduced
  ContactMode mode = ContactMode::kRolling;
  /// m/s: velocity of the object's contact point relative to the hand's, along the hand's
  /// tangent (0 while rolling or at rest).
  double slip_velocity = 0;
  /// N m: the rolling-resistance couple on the object (rolling: -delta f_n against the rolling;
  /// at rest: the couple that holds it, whose bound is delta f_n).
  double rolling_couple = 0;
  /// m: distance from the object to the hand outline (flight; 0 in contact).
  double gap = 0;
};

/// The object's state in any contact mode, independent of the formulation: what the hybrid model
/// carries from one segment to the next (and a driver from one call to the next).
struct HybridState {
  double t = 0;
  ContactMode mode = ContactMode::kRolling;
  int sign = 0;  ///< the phase's sign (ContactPhase::sign)
  int turn = 0;  ///< the phase's turn (ContactPhase::turn)
  // In contact: the contact parameters and their rates (s_o for non-disk objects).
  double s_h = 0, sdot_h = 0;
  double s_o = 0, sdot_o = 0;
  int hand_piece = 0;  ///< the piece of the hand outline the contact is on
  // Always: the object's centre and rotation, world.
  Vec2 position = Vec2::Zero(), velocity = Vec2::Zero();
  double angle = 0, angular_velocity = 0;
};

/// The object's kinetic energy at a sample, J (translation and rotation in the table plane).
double kinetic_energy(const RollingProblem& problem, const Sample& s);
/// Kinetic plus potential energy (-m g . x, g in the table plane), J: what the energy audit
/// balances against the work done on the object (flatland/sim/energy.hpp).
double mechanical_energy(const RollingProblem& problem, const Sample& s);

/// The paper's A x = b formulation. State (10): object position (2), object angle, s_o, s_h,
/// object velocity (2), object angular velocity, sdot_o, sdot_h. The right-hand side is evaluated
/// at the state snapped onto the contact manifold, and accepted steps are snapped too.
class GeneralRolling {
 public:
  static constexpr int N = 10;
  using State = Eigen::Matrix<double, N, 1>;
  /// `phase`: rolling (the paper's equations), rest (the object moves with the hand) or sliding
  /// (row (3), equal tangential accelerations, becomes Coulomb's f_t = -mu_k sign f_n, and
  /// sdot_o is no longer tied to sdot_h).
  explicit GeneralRolling(std::shared_ptr<const RollingProblem> problem, ContactPhase phase = {});

  State initial_state(const InitialContact& init) const;
  /// dy = f(t, y); with `power`, also the power of the forces on the object besides gravity
  /// (the energy audit's integrands; every model below does the same).
  void derivative(double t, const State& y, const Pieces& p, State& dy,
                  Power* power = nullptr) const;
  /// Rebuild the object pose and velocities from (s_h, s_o, sdot_h). Returns the constraint
  /// residual the state had before (the drift this projection removed).
  double project(double t, State& y, const Pieces& p) const;
  Sample sample(double t, const State& y, const Pieces& p) const;
  Pieces pieces_for(const State& y, int direction) const;
  static double s_h(const State& y) { return y[4]; }
  static double sdot_h(const State& y) { return y[9]; }
  const RollingProblem& problem() const { return *problem_; }

  /// The assembled system at a state, for inspection and tests.
  struct Assembled {
    Eigen::Matrix<double, 6, 5> A;
    Eigen::Matrix<double, 6, 1> b;
    Eigen::Matrix<double, 5, 1> x;  ///< a_o (2), alpha_o, sddot_o, sddot_h
    double residual;                ///< |A x - b|
  };
  Assembled assemble_and_solve(double t, const State& y, const Pieces& p) const;
  double constraint_residual(double t, const State& y, const Pieces& p) const;

  const ContactPhase& phase() const { return phase_; }

 private:
  /// The projection itself (project() without measuring the residual first).
  void snap(double t, State& y, const Pieces& p) const;
  std::shared_ptr<const RollingProblem> problem_;
  ContactPhase phase_;
};

/// One-coordinate formulation for a disk (radius r, inertia I about its centre). State (3):
/// s_h, object angle, sdot_h.
class ReducedDiskRolling {
 public:
  static constexpr int N = 3;
  using State = Eigen::Matrix<double, N, 1>;
  /// Throws std::invalid_argument if the object is not a disk. `phase`: rolling or rest (the
  /// disk moves with the hand, sdot_h = 0, held by the rolling-resistance couple).
  explicit ReducedDiskRolling(std::shared_ptr<const RollingProblem> problem,
                              ContactPhase phase = {});

  State initial_state(const InitialContact& init) const;
  void derivative(double t, const State& y, const Pieces& p, State& dy,
                  Power* power = nullptr) const;
  double project(double, State&, const Pieces&) const { return 0.0; }
  Sample sample(double t, const State& y, const Pieces& p) const;
  Pieces pieces_for(const State& y, int direction) const;
  static double s_h(const State& y) { return y[0]; }
  static double sdot_h(const State& y) { return y[2]; }
  const RollingProblem& problem() const { return *problem_; }

  /// The same physics with the hand's kinematics given explicitly instead of taken from the
  /// problem's motion: for hands driven step by step (a joint under control) and for estimators
  /// that propagate with measured hand kinematics. `hand_piece` as from pieces_for.
  double acceleration(const HandKinematics& h, double s_h, double sdot_h, int hand_piece) const;
  Sample sample_with(const HandKinematics& h, double t, const State& y, int hand_piece) const;
  const ContactPhase& phase() const { return phase_; }

 private:
  /// s'' and, with `power`, the energy audit's powers at the same state (sharing its terms).
  double sddot(const HandKinematics& h, const CurveGeometry& g, double sdot,
               Power* power = nullptr) const;
  std::shared_ptr<const RollingProblem> problem_;
  ContactPhase phase_;
  double r_, rho2_, side_;
  bool rest_ = false, losses_ = false;
};

/// A disk sliding on the hand (reduced formulation): the centre stays on the offset curve
/// q = c + r n, and the disk turns independently of s_h. State (4): s_h, object angle, sdot_h,
/// object angular velocity. The kinetic friction mu_k f_n opposes the slip velocity, whose sign
/// is the phase's (fixed over a segment; its change is an event), and the rolling-resistance
/// couple delta f_n the disk's rotation relative to the hand (the phase's turn).
class ReducedDiskSliding {
 public:
  static constexpr int N = 4;
  using State = Eigen::Matrix<double, N, 1>;
  ReducedDiskSliding(std::shared_ptr<const RollingProblem> problem, int slip_sign, int turn = 0);

  void derivative(double t, const State& y, const Pieces& p, State& dy,
                  Power* power = nullptr) const;
  double project(double, State&, const Pieces&) const { return 0.0; }
  Sample sample(double t, const State& y, const Pieces& p) const;
  Sample sample_with(const HandKinematics& h, double t, const State& y, int hand_piece) const;
  Pieces pieces_for(const State& y, int direction) const;
  static double s_h(const State& y) { return y[0]; }
  static double sdot_h(const State& y) { return y[2]; }
  const RollingProblem& problem() const { return *problem_; }
  const ContactPhase& phase() const { return phase_; }

 private:
  std::shared_ptr<const RollingProblem> problem_;
  ContactPhase phase_;
  double r_, side_;
};

}  // namespace flatland::sim
