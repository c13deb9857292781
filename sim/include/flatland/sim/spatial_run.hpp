// Spatial rolling in time (issue 16, in progress): hand motions in SE(3) and a run of the 11 x 10
// equations with Dormand-Prince 5(4), the state projected back onto the contact manifold after
// every accepted step (unit quaternion, coincident contact points with opposite normals, rolling
// velocities). A ball's chart is turned whenever the contact nears its poles, so that it can roll
// for ever; any other surface whose patch the contact leaves ends the run there.
//
// Not built yet (the remaining items): DOP853 and RK4 here, dense output, contact loss
// and slip located to a tolerance (the run stops at the first step end where f_n < 0), charts of
// ellipsoids and hand surfaces, tabulated and butterfly hand motions, scenes, the CLI and the
// renderer.
#pragma once

#include "flatland/sim/spatial.hpp"

#include <memory>
#include <string>
#include <vector>

namespace flatland::sim {

/// A rigid hand motion in SE(3), as a function of time.
class HandMotion3 {
 public:
  virtual ~HandMotion3() = default;
  virtual HandPose3 at(double t) const = 0;
  virtual std::string describe() const = 0;
};

/// The hand held still at a pose.
class FixedHand3 final : public HandMotion3 {
 public:
  explicit FixedHand3(Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity(),
                      Vec3 position = Vec3::Zero());
  HandPose3 at(double t) const override;
  std::string describe() const override { return "fixed hand"; }

 private:
  HandPose3 pose_;
};

/// The hand turning at a constant rate about a fixed axis through `point` (a turntable): its
/// orientation at t is AngleAxis(rate t, axis) times `rotation0`, and `point` stays where it is.
class SpinningHand3 final : public HandMotion3 {
 public:
  SpinningHand3(Vec3 axis, double rate, Vec3 point = Vec3::Zero(),
                Eigen::Matrix3d rotation0 = Eigen::Matrix3d::Identity());
  HandPose3 at(double t) const override;
  std::string describe() const override;

 private:
  Vec3 axis_, point_;
  double rate_;
  Eigen::Matrix3d rotation0_;
};

struct SpatialRunOptions {
  double t_end = 1.0;  ///< s
  double rtol = 1e-10, atol = 1e-12;
  double max_step = 1e-2;  ///< s
  long max_steps = 5'000'000;
  bool record = true;  ///< keep every step's sample
};

/// Everything known at one instant of a spatial run.
struct SpatialSample {
  double t = 0;
  SpatialState state;  ///< the object's orientation is its body frame's (not its chart's)
  double force_normal = 0, mu_required = 0;  ///< N; |f_t| / f_n
  double energy = 0;                         ///< J: kinetic + potential (-m g . x) of the object
  double constraint_residual =
      0;                          ///< max(|contact gap| in m, |n_o + n_h|, rolling velocity in m/s)
  double redundant_residual = 0;  ///< |A x - b|
};

enum class SpatialStop {
  kEndTime,
  kContactLost,  ///< f_n < 0 at a step's end (not located within the step yet)
  kLeftPatch,    ///< the contact left a surface's patch that cannot be recharted
};
std::string to_string(SpatialStop s);

struct SpatialRunStats {
  long steps = 0, rejected = 0, rhs_evals = 0;
  int chart_changes = 0;               ///< the ball's chart turned (the contact neared its poles)
  double max_constraint_residual = 0;  ///< after projection, over the steps
  double max_redundant_residual = 0;
  double max_drift = 0;  ///< the largest constraint residual a projection removed
};

struct SpatialRunResult {
  SpatialStop stop = SpatialStop::kEndTime;
  std::vector<SpatialSample> steps;  ///< the start and every accepted step (when recorded)
  SpatialSample final;
  SpatialRunStats stats;
};

/// Run from `initial` at t0 (projected onto the contact manifold first) to options.t_end.
/// std::invalid_argument for a bad problem or options, and for an object that does not fit the
/// hand's curvature at the start (a ball larger than its bowl); std::runtime_error for an
/// integrator failure (step budget, step underflow, non-finite state).
SpatialRunResult simulate_spatial(const SpatialRollingProblem& problem, const HandMotion3& motion,
                                  const SpatialState& initial, double t0,
                                  const SpatialRunOptions& options);

/// The object's mechanical energy: (1/2) m |v|^2 + (1/2) w^T I_w w - m g . x, J.
double spatial_energy(const SpatialRollingProblem& problem, const SpatialState& state);

}  // namespace flatland::sim
