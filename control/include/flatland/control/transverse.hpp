// Orbital stabilisation of the planned rolling motion by transverse linearisation (type
// `transverse`), after Surov, Shiriaev, Freidovich et al. (ICRA 2015, the butterfly robot).
//
// The planned motion is an orbit x*(tau) of the reduced dynamics x = (theta, theta_dot, s_h,
// sdot_h) with the hand's acceleration u = theta'' as input. Between dip_until and finish_after
// the planned s_h rises monotonically, so the hyperplanes s_h = s*(tau) are a moving transverse
// section: the projection of a state onto the orbit is tau = t_p(s_h) (the plan's inverse lookup,
// as the paper's stage 2 indexes the plan), and the transverse coordinates are
//   e = (theta - theta*(tau), theta_dot - theta_dot*(tau), sdot_h - sdot_h*(tau)).
// Linearised about e = 0 along the orbit they obey de/dtau = A(tau) e + B(tau) v, v = u - u*(tau)
// (derivation in docs/CLOSED_LOOP.md, "The transverse-linearisation controller"). start()
// solves the Riccati differential equation of a finite-horizon LQR backwards along the orbit
// once and stores the gains on a grid; each tick commands u = u*(tau) - K(tau) e with tau from the
// estimated s_h. Outside the servo range the law is the paper's (its open-loop dip, its finish
// and its hold): the transverse section does not exist there (s_h is not monotonic in the dip,
// and the finish brings the hand to rest on the plan's end, which the disk follows by itself).
#pragma once

#include "flatland/control/controller.hpp"
#include "flatland/control/interfaces.hpp"
#include "flatland/sim/rolling.hpp"

#include <Eigen/Core>

#include <array>
#include <memory>
#include <string>
#include <vector>

namespace flatland::control {

/// The transverse controller's parameters (scene section `controller.transverse`).
struct TransverseConfig {
  /// Diagonal of the running cost Q on e = (theta error rad, theta_dot error rad/s, sdot_h error
  /// 1/s): 1/rad^2, s^2/rad^2, s^2. Non-negative.
  std::array<double, 3> q{100.0, 1.0, 1.0};
  /// Weight R on the acceleration's deviation from the plan's, s^4/rad^2. Positive.
  double r = 0.1;
  /// Diagonal of the terminal cost P(tau_end) at finish_after, as q. Non-negative.
  std::array<double, 3> terminal{100.0, 1.0, 1.0};
  /// s of plan time between stored gains (the Riccati equation's RK4 step). In (0, 0.01].
  double grid_step = 1e-3;
};

/// A point of the planned orbit at plan time tau.
struct OrbitPoint {
  double tau = 0;
  double theta = 0, theta_dot = 0, theta_ddot = 0;  ///< the hand: rad, rad/s, rad/s^2 (u*)
  double s_h = 0, sdot_h = 0;                       ///< the disk
  double sddot_h = 0;                               ///< the model's sddot_h at this state and input
};

/// sddot_h = f(theta, theta_dot, u, s_h, sdot_h) of a disk rolling on a hand turning about a fixed
/// pivot, and its partial derivatives, from the curve's geometry in closed form (the lossless
/// rolling model, docs/DYNAMICS.md; derivation in docs/CLOSED_LOOP.md).
struct RollingPartials {
  double f = 0;
  double d_theta = 0, d_theta_dot = 0, d_u = 0, d_sdot = 0;
};
/// std::invalid_argument when the model has no disk or has losses (the closed form is lossless).
RollingPartials rolling_partials(const sim::RollingProblem& model, double theta, double theta_dot,
                                 double u, double s_h, double sdot_h);

/// The transverse linearisation at one orbit point: de/dtau = A e + B v.
struct TransverseSystem {
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d B = Eigen::Vector3d::Zero();
};
TransverseSystem transverse_linearisation(const sim::RollingProblem& model, const OrbitPoint& p);

/// The Riccati solution and the gain at one grid point.
struct TransverseGain {
  double tau = 0;
  Eigen::Matrix3d P = Eigen::Matrix3d::Zero();
  Eigen::RowVector3d K = Eigen::RowVector3d::Zero();  ///< R^-1 B^T P
};

/// The transverse-linearisation controller (type `transverse`). Its modes: those of the paper's
/// controller, whose dip, finish and hold it runs ("waiting", "dip", "servo", "finish", "done");
/// in "servo" the law is the transverse LQR's.
class TransverseController final : public Controller {
 public:
  /// `stages`: the paper's config for the dip, the finish and the hold (its kp, kd hold the hand
  /// after the motion; its servo law is not used). std::invalid_argument for a bad config field
  /// (the message names it: "controller.transverse.r: ...").
  TransverseController(TransverseConfig config, PaperConfig stages);
  /// Solves the Riccati equation along the plan's servo stretch (plan.s_from() .. s_to()).
  /// std::invalid_argument when the model is not the lossless disk, the planned sdot_h is not
  /// positive over the stretch, or the solution leaves the positive definite matrices.
  void start(const ControllerContext& context) override;
  ControlOutput step(const ControlInput& input) override;
  std::string name() const override { return "transverse"; }

  /// The planned orbit at plan time tau (after start).
  OrbitPoint orbit(double tau) const;
  /// The Riccati solution and gains on the grid, tau increasing (after start).
  const std::vector<TransverseGain>& gains() const { return gains_; }
  /// The gain at plan time tau, interpolated linearly on the grid (clamped to its ends).
  Eigen::RowVector3d gain(double tau) const;
  /// The transverse error of a state against the orbit point its s_h projects to, and that tau.
  Eigen::Vector3d transverse_error(double theta, double theta_dot, double s_h, double sdot_h,
                                   double& tau) const;

 private:
  void solve_riccati();
  TransverseConfig config_;
  PaperController stages_;
  std::shared_ptr<const Plan> plan_;
  std::shared_ptr<const sim::RollingProblem> model_;
  std::vector<TransverseGain> gains_;
  double tau_begin_ = 0, tau_end_ = 0, grid_h_ = 0;
};

}  // namespace flatland::control
