// The synthetic world behind the loop's interfaces: the simulated plant (the disk rolling on the
// hand by the exact rolling dynamics, the joint's reference integration, PD torque loop and motor
// model loaded by the disk's contact force), a camera that renders it, and a clock that advances
// it. Faults from the scene's `faults` section are injected here.
#pragma once

#include "flatland/drivers/interfaces.hpp"
#include "flatland/model/model.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/hybrid.hpp"

#include <array>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

namespace flatland::drivers {

/// The world's truth at one servo tick.
struct WorldSample {
  double t = 0;
  double theta = 0, theta_dot = 0, theta_ddot = 0;  ///< hand, rad
  /// Hand contact parameter and its rate; in flight those of the outline's point nearest to the
  /// disk.
  double s_h = 0, sdot_h = 0;
  sim::ContactMode mode = sim::ContactMode::kRolling;
  sim::Vec2 disk_position = sim::Vec2::Zero(), disk_velocity = sim::Vec2::Zero();  ///< m, m/s
  double disk_angle = 0, disk_rate = 0;  ///< rad, rad/s
  double fn_ratio = 0, ft_ratio = 0, mu_required = 0;
  double torque = 0;     ///< N m, the drive's torque
  double theta_ref = 0;  ///< rad, the drive's reference
};

/// Where the disk ended: in the goal well (the back well, s_h near +1) with too little energy to
/// leave it (its energy, kinetic + potential in the table plane, below the lower of the well's
/// rims), so that the losses settle it there.
struct GoalCheck {
  bool in_goal = false;
  double s_h = 0;
  double well_bottom = 0;              ///< s_h of the well's lowest point
  double rim_left = 0, rim_right = 0;  ///< s_h of its rims
  double energy_margin = 0;  ///< J: (lowest rim's potential) - (disk's energy); > 0 to stay
  bool well_faces_up = false;  ///< the hand faces up at the well's bottom (it can hold the disk)
  /// In contact in a well that holds it, below its rims: it cannot leave that well.
  bool trapped = false;
  sim::ContactMode mode = sim::ContactMode::kRolling;
  std::string reason;  ///< why not, when not
};

/// How a synthetic experiment ended.
enum class Outcome {
  kSuccess,      ///< the disk rests in the back well, the hand at pi
  kDropped,      ///< the disk lost contact and was not caught again
  kSlidOff,      ///< the disk slid off the hand (lost contact while sliding) and was not caught
  kWrongWell,    ///< the disk settled in another well
  kNotSettled,   ///< the disk can still leave the back well, or is still in flight
  kSafeStop,     ///< the controller stopped the hand (lost vision, implausible innovations, ...)
  kNotFinished,  ///< the motion did not finish
  /// The world's simulation failed (its energy balance broke, or its integrator gave up): not a
  /// physical outcome; what the disk would have done is unknown.
  kNumericalFailure,
  /// A Monte Carlo world whose drawn values the scene's rules refuse (a ball that falls between
  /// its rails, an inertia its drawn radius cannot hold, a disk too large for a well): it cannot
  /// exist, so it has no outcome, physical or numerical.
  kInvalidWorld,
};
std::string to_string(Outcome o);
/// False for the outcomes that say nothing about the controller (kNumericalFailure,
/// kInvalidWorld): rates and comparisons leave those worlds out.
bool has_physical_outcome(Outcome o);

/// std::invalid_argument naming contact.mu unless the scene sets it: a synthetic world counts
/// friction always (unlimited friction would hide slips).
void require_friction(const Scene& scene);

class SimWorld {
 public:
  /// `truth` is the compiled scene the world obeys (perhaps perturbed from what the controller
  /// assumes): its plant under the hybrid contact model with its friction, restitution and
  /// losses, whatever the scene's contact.model says. Needs a disk. The hand rests at its
  /// motion's angle at t = 0; time starts at t_start.
  SimWorld(std::shared_ptr<const model::Model> truth, double t_start);

  double t() const { return t_; }
  double servo_period() const { return dt_; }
  /// The acceleration the loop commands, held until the next command.
  void command(double theta_ddot) { command_ = theta_ddot; }
  /// Advance by whole servo periods to the last tick <= t (+ half a period of slack).
  void advance_to(double t);
  /// After the loop: run on (the joint holding its last command) until the disk is trapped in a
  /// well, has left the hand's reach, or `max_time` has passed. Returns the time run on.
  double settle(double max_time);
  /// The encoder's angle (quantised) and the drive's velocity estimate at the current tick.
  control::JointReading read_encoder() const;

  const std::vector<WorldSample>& history() const { return history_; }
  /// The truth at time t, Hermite-interpolated between ticks (clamped to what has been simulated).
  WorldSample state_at(double t) const;
  /// What the renderer needs at time t.
  render::SceneState scene_state_at(double t) const;

  /// Set when the disk left the hand's reach for good (it flew off or slid off and was not
  /// caught; the joint keeps moving, unloaded, and the disk flies on), or when the world's
  /// simulation failed numerically (kNumericalFailure; the disk then stands still).
  std::optional<Outcome> failure() const { return failure_; }
  /// The largest |energy balance| of the world's simulation over its servo periods, J, and the
  /// bound of that period (each period's run is audited: sim/energy.hpp).
  double energy_worst() const { return energy_worst_; }
  double energy_worst_bound() const { return energy_worst_bound_; }
  /// The failure in words (time and place).
  const std::string& failure_detail() const { return failure_detail_; }
  double fn_min_ratio() const { return fn_min_; }   ///< smallest f_n / (m g sin tilt) in contact
  double mu_max() const { return mu_max_; }         ///< largest |f_t| / f_n needed while rolling
  /// Counts of what the contact did: seconds in each mode, impacts, changes of mode.
  const std::array<double, 4>& mode_time() const { return mode_time_; }
  int impacts() const { return impacts_; }
  /// What the contact did, in time order: lift-offs, slips, sticks, rests, impacts (with their
  /// impulses), the drop (junction crossings left out).
  const std::vector<sim::RecordedEvent>& events() const { return events_; }
  int mode_changes() const { return mode_changes_; }
  GoalCheck goal_check() const;
  const sim::RollingProblem& problem() const { return *problem_; }

 private:
  void servo_step();
  /// The disk's reaction torque on the hand at its current state, for a hand acceleration alpha.
  double reaction_torque(double t, double alpha) const;
  /// The hand's acceleration over the rest of the tick under the drive's torque, the disk's
  /// load and the joint's friction; `stops` when dry friction brings it to rest by `t_end`.
  double joint_acceleration(double t, double t_end, double tau, bool& stops) const;
  /// Advance the disk from t to at most t_end under the held acceleration alpha (one segment of
  /// the hybrid model: it stops at a change of mode). Returns the time reached.
  double step_disk(double t, double t_end, double alpha);
  WorldSample sample_now(double alpha, double torque) const;
  std::shared_ptr<const sim::RollingProblem> held(double t, double alpha) const;

  std::shared_ptr<const model::Model> model_;
  const Scene& scene_;  // model_->spec
  std::shared_ptr<const sim::RollingProblem> problem_;
  sim::RunOptions step_options_;
  double dt_ = 1e-3;
  long tick_ = 0;
  double t_start_ = 0, t_ = 0;
  double command_ = 0;
  // Plant state.
  double theta_ = 0, theta_dot_ = 0;
  sim::HybridState disk_;
  sim::ContactMode last_contact_mode_ = sim::ContactMode::kRolling;
  // Drive state.
  double theta_ref_ = 0, theta_dot_ref_ = 0;
  double encoder_ = 0, velocity_estimate_ = 0;
  std::vector<WorldSample> history_;
  std::optional<Outcome> failure_;
  std::string failure_detail_;
  double fn_min_ = 1e300, mu_max_ = 0;
  double theta_dot_kick_ = 0;  ///< the hand's rate change by an impact within a step
  double energy_worst_ = 0, energy_worst_bound_ = 0;
  std::array<double, 4> mode_time_{0, 0, 0, 0};
  int impacts_ = 0, mode_changes_ = 0;
  std::vector<sim::RecordedEvent> events_;
};

/// The clock of a synthetic experiment: simulated time; sleeping advances the world.
class SimClock final : public Clock {
 public:
  SimClock(SimWorld* world, double t_start) : world_(world), t_(t_start) {}
  double now() const override { return t_; }
  void sleep_until(double t) override {
    if (world_) world_->advance_to(t);
    t_ = t;
  }

 private:
  SimWorld* world_;
  double t_;
};

/// The simulated joint: reads the world's encoder, commands its drive. An encoder glitch from the
/// scene's faults corrupts one reading.
class SimJoint final : public Joint {
 public:
  SimJoint(SimWorld& world, const FaultSpec& faults) : world_(world), faults_(faults) {}
  control::JointReading read(double t) override;
  void command(double, double theta_ddot) override { world_.command(theta_ddot); }
  std::string describe() const override { return "simulated"; }

 private:
  SimWorld& world_;
  FaultSpec faults_;
  bool glitched_ = false;
};

/// Renders the world through the scene's camera and effects at camera.fps from t_start, and
/// delivers each frame camera.latency (+- latency_jitter, seeded) after its capture. Camera
/// faults (stop, stall, occlusion) from the scene's `faults` section.
class SyntheticCamera final : public Camera {
 public:
  SyntheticCamera(std::shared_ptr<const model::Model> model, const SimWorld& world, double t_start);
  std::optional<CameraFrame> poll(double now) override;
  std::string describe() const override { return "synthetic"; }
  const std::vector<render::FrameTruth>& truths() const { return truths_; }
  long rendered() const { return rendered_; }
  long dropped() const { return dropped_; }
  std::string gl_description() const { return renderer_.gl_description(); }

 private:
  const SimWorld& world_;
  CameraSpec camera_;
  FaultSpec faults_;
  render::Renderer renderer_;
  double t_start_;
  double capture_jitter_;  ///< s, effects.jitter_s
  long next_ = 0;  ///< next nominal frame number
  std::deque<CameraFrame> queue_;
  std::optional<CameraFrame> last_;
  double last_arrival_ = -1e300;
  std::mt19937_64 latency_rng_;
  std::vector<render::FrameTruth> truths_;
  long rendered_ = 0, dropped_ = 0;
};

}  // namespace flatland::drivers
