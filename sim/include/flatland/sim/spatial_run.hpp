// Spatial rolling in time (issue 16): hand motions in SE(3) and a run of the 11 x 10 equations
// with the planar path's integrators (Dormand-Prince 5(4) and 8(5,3), classical RK4), the state
// projected back onto the contact manifold after every accepted step (unit quaternion, coincident
// contact points with opposite normals, rolling velocities). The contact is carried into another
// chart of its surface whenever it nears a chart's poles (a ball's, an ellipsoid's, a bowl's or a
// dish's), so that it can roll for ever. Contact loss, slip at mu and a contact leaving a
// surface's patch are events located within the step to a time tolerance; the run stops there
// (the spatial path has no flight or sliding mode: a run that loses its contact or slips is not a
// success). Samples come from every step or, at a fixed spacing, from the steps' dense output.
#pragma once

#include "flatland/sim/energy.hpp"
#include "flatland/sim/motion.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial.hpp"

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace flatland::sim {

/// A rigid hand motion in SE(3), as a function of time. Like the planar HandMotion, it is smooth
/// between breakpoints (where its acceleration may jump) and evaluates each segment between two
/// breakpoints by its own formula, so that a step ending on a breakpoint sees its own segment.
class HandMotion3 {
 public:
  virtual ~HandMotion3() = default;
  /// The pose by the formula of `segment` (segment i lies between breakpoints i-1 and i).
  virtual HandPose3 at(double t, int segment) const = 0;
  /// Times where the acceleration is discontinuous (sorted): the run stops and restarts there.
  virtual std::vector<double> breakpoints() const { return {}; }
  virtual std::string describe() const = 0;
  /// The segment containing t: the number of breakpoints <= t (right-continuous).
  int segment_at(double t) const;
  /// The pose at t (the right limit on a breakpoint).
  HandPose3 at(double t) const { return at(t, segment_at(t)); }
};

/// The hand held still at a pose.
class FixedHand3 final : public HandMotion3 {
 public:
  explicit FixedHand3(Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity(),
                      Vec3 position = Vec3::Zero());
  using HandMotion3::at;
  HandPose3 at(double t, int segment) const override;
  std::string describe() const override { return "fixed hand"; }

 private:
  HandPose3 pose_;
};

/// The hand turning at a constant rate about a fixed axis through `point` (a turntable): its
/// orientation at t is AngleAxis(rate t, axis) times `rotation0`, its origin `position0` turned
/// about the axis, and `point` stays where it is.
class SpinningHand3 final : public HandMotion3 {
 public:
  SpinningHand3(Vec3 axis, double rate, Vec3 point = Vec3::Zero(),
                Eigen::Matrix3d rotation0 = Eigen::Matrix3d::Identity(),
                Vec3 position0 = Vec3::Zero());
  using HandMotion3::at;
  HandPose3 at(double t, int segment) const override;
  std::string describe() const override;

 private:
  Vec3 axis_, point_, position0_;
  double rate_;
  Eigen::Matrix3d rotation0_;
};

/// A planar hand motion (the paper's butterfly, a fixed angle, a held acceleration) carried out
/// in a plane of space: the planar world's x, y, z axes are the columns of `plane` (z the joint
/// axis) and its origin is `origin`. The hand frame's pose at t is R = plane Rz(theta(t)),
/// x = origin + plane (x(t), y(t), 0): the hand's surface, given in its own frame (its z along
/// the joint axis), turns and moves as the planar hand does, and the planar motion's breakpoints
/// are the motion's.
class PlanarHand3 final : public HandMotion3 {
 public:
  /// std::invalid_argument unless `plane` is a rotation (to 1e-9) and `origin` finite.
  PlanarHand3(std::shared_ptr<const HandMotion> motion,
              Eigen::Matrix3d plane = Eigen::Matrix3d::Identity(), Vec3 origin = Vec3::Zero());
  using HandMotion3::at;
  HandPose3 at(double t, int segment) const override;
  std::vector<double> breakpoints() const override { return motion_->breakpoints(); }
  std::string describe() const override;

 private:
  std::shared_ptr<const HandMotion> motion_;
  Eigen::Matrix3d plane_;
  Vec3 origin_;
};

/// A hand driven by tabulated accelerations, held constant between the table's times t_0 < ... <
/// t_n: the frame origin's linear acceleration (3, world) and the angular acceleration about a
/// fixed world axis through the origin (1). Position and angle are integrated in closed form from
/// the pose and velocities at t_0; before t_0 and after t_n the acceleration is zero (the hand
/// moves on at its velocities there). The angular part turns about one fixed
/// axis; a tumbling hand (angular acceleration off that axis) is not tabulated.
class TabulatedHand3 final : public HandMotion3 {
 public:
  struct Row {
    double t = 0;                      ///< s, where this row's accelerations start
    Vec3 acceleration = Vec3::Zero();  ///< m/s^2
    double angular_acceleration = 0;   ///< rad/s^2 about the axis
  };
  /// std::invalid_argument unless the times increase strictly, there are at least two rows (the
  /// last row's time ends the table; its accelerations are not used), the values are finite and
  /// the axis non-zero.
  TabulatedHand3(std::vector<Row> rows, Vec3 axis, HandPose3 initial = {},
                 double angular_velocity = 0);
  using HandMotion3::at;
  HandPose3 at(double t, int segment) const override;
  std::vector<double> breakpoints() const override;
  std::string describe() const override;

 private:
  struct Knot {  ///< the state where a row starts
    double t, angle, rate;
    Vec3 position, velocity;
  };
  std::vector<Row> rows_;
  std::vector<Knot> knots_;
  Vec3 axis_;
  Eigen::Matrix3d rotation0_;
};

struct SpatialRunOptions {
  double t_end = 1.0;  ///< s
  /// The planar path's settings: method, rtol, atol, fixed_step (RK4), max_step, max_steps.
  IntegratorSettings integrator;
  double time_tolerance = 1e-12;     ///< s, events are located to this
  bool stop_on_contact_loss = true;  ///< false: keep rolling (enforced) through f_n < 0
  /// s: > 0 samples at multiples of it from the dense output (and at the end); 0 every step.
  double sample_dt = 0;
  bool record = true;  ///< keep the samples (else only the final one)
  /// Called after every accepted step with the time reached (for a progress bar); may be empty.
  std::function<void(double t)> progress;
};

/// Everything known at one instant of a spatial run.
struct SpatialSample {
  double t = 0;
  /// The object's orientation is its body frame's; s_o, s_h and their rates are in the charts in
  /// use at t (SpatialRunStats::chart_changes), the longitudes in [-pi, pi].
  SpatialState state;
  Vec3 contact = Vec3::Zero();               ///< the contact point, world, m
  Vec3 force = Vec3::Zero();                 ///< N: the hand's contact force on the object, world
  double force_normal = 0, mu_required = 0;  ///< N; |f_t| / f_n
  double energy = 0;                         ///< J: kinetic + potential (-m g . x) of the object
  /// max(|contact gap| in m, |n_o + n_h|, rolling velocity in m/s, contact point rates in m/s)
  double constraint_residual = 0;
  double redundant_residual = 0;  ///< |A x - b|
};

enum class SpatialStop {
  kEndTime,      ///< reached t_end (the only success)
  kContactLost,  ///< f_n reached 0 (located)
  kSlip,         ///< |f_t| reached mu f_n (located)
  kLeftPatch,    ///< the contact left a surface's patch with no chart to move to (located)
  /// The energy balance broke its bound (SpatialRunResult::audit): never a success.
  kNumericalFailure,
};
std::string to_string(SpatialStop s);

struct SpatialRunStats {
  long steps = 0, rejected = 0, rhs_evals = 0;
  long event_evals = 0;  ///< guard evaluations while locating events
  int restarts = 0;      ///< at the motion's breakpoints
  /// Every move of the contact into another chart of its surface, made when it came within
  /// 0.57 rad of a chart's pole: of the object's surface (a ball's chart turned along the
  /// contact's path, an ellipsoid's three charts with their poles on its x, y, z axes) and of the
  /// hand's (a sphere's or an ellipsoid's three: a bowl, dish or dome). A step that moves both
  /// counts two. A plane, an extruded curve and a surface of revolution keep their one chart.
  int chart_changes = 0;
  double max_constraint_residual = 0;  ///< after projection, over the samples
  double max_redundant_residual = 0;
  double max_drift = 0;  ///< the largest constraint residual a projection removed
  double min_force_normal = std::numeric_limits<double>::infinity();  ///< N, over the samples
  double max_mu_required = 0;                                         ///< over the samples
};

struct SpatialRunResult {
  SpatialStop stop = SpatialStop::kEndTime;
  SpatialSample initial;               ///< where the run started (after projection)
  std::vector<SpatialSample> samples;  ///< the start, then every step or every sample_dt
  SpatialSample final;
  SpatialRunStats stats;
  /// The energy balance (flatland/sim/energy.hpp): the hand's work is the contact force's
  /// (no losses in space); broken only with stop kNumericalFailure.
  EnergyAudit audit;
};

/// Run from `initial` at t0 (projected onto the contact manifold first) to options.t_end or the
/// first event. std::invalid_argument for a bad problem or options, for an object that does not
/// fit the hand's curvature at the start (a ball larger than its bowl), for a start outside the
/// surfaces' patches or already beyond an event; std::runtime_error for an integrator failure
/// (step budget, step underflow, non-finite state).
SpatialRunResult simulate_spatial(const SpatialRollingProblem& problem, const HandMotion3& motion,
                                  const SpatialState& initial, double t0,
                                  const SpatialRunOptions& options);

/// Where and how an object starts in rolling contact (place_in_contact).
struct ContactPlacement {
  SurfaceParam s_h = SurfaceParam::Zero();  ///< the contact on the hand
  SurfaceParam s_o = SurfaceParam::Zero();  ///< the object's surface point on it
  /// rad, about the contact normal: 0 puts the object's u direction along the hand's.
  double twist = 0;
  Vec3 velocity = Vec3::Zero();  ///< m/s, world: the centre's velocity (its tangential part)
  double spin = 0;               ///< rad/s, about the hand's normal at the contact
};

/// The object placed on the hand (at `hand`) in rolling contact: its surface point s_o on the
/// hand's point s_h with the normals opposite, its centre moving at the tangential part of the
/// given velocity and spinning about the normal as asked, the rest of the velocities (the normal
/// component, the rolling rotation, the contact coordinates' rates) following from rolling.
/// std::invalid_argument for non-finite values, a singular chart or a degenerate contact.
SpatialState place_in_contact(const SpatialRollingProblem& problem, const HandPose3& hand,
                              const ContactPlacement& placement);

/// The object's mechanical energy: (1/2) m |v|^2 + (1/2) w^T I_w w - m g . x, J.
double spatial_energy(const SpatialRollingProblem& problem, const SpatialState& state);

}  // namespace flatland::sim
