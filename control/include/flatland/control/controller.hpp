// The paper's vision-feedback controller for the butterfly (section 5) and the safe stop.
//
//  1. Open-loop dip: the plan's acceleration until the estimated s_h exceeds dip_until (-0.9).
//  2. Servo: theta'' = kp (theta_p(s_h) - theta) + kd (thetadot_p(s_h) - thetadot), the plan
//     indexed by the estimated s_h (monotonic in this stage), theta and thetadot as read.
//  3. Open-loop finish once s_h exceeds finish_after (0.9): the rest of the plan from the planned
//     time at which s_h = finish_after, plus a cubic that removes, by the plan's end, the angle and
//     rate offsets the hand had when stage 3 began (so it stops at rest on the plan's end).
// The commanded acceleration is integrated by the joint into a reference that its PD torque loop
// tracks. Open-loop mode plays the plan's acceleration from t = 0. The safe stop is the loop's
// (safe_stop_command): a controller only asks for one.
#pragma once

#include "flatland/control/interfaces.hpp"
#include "flatland/control/types.hpp"
#include "flatland/sim/motion.hpp"
#include "flatland/sim/simulate.hpp"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace flatland::control {

/// A planned hand motion over [0, duration] and the disk's planned s_h along it, with the inverse
/// lookup t_p(s_h) over the stretch where s_h rises monotonically.
class Plan {
 public:
  /// `run` is the recorded nominal simulation of `motion` (dense output over [0, duration]).
  /// The lookup covers s_h in [s_from, s_to]; throws std::invalid_argument when the planned s_h
  /// does not rise monotonically through that range.
  Plan(std::shared_ptr<const sim::HandMotion> motion, double duration, const sim::RunResult& run,
       double s_from, double s_to);
  double duration() const { return duration_; }
  sim::HandKinematics hand(double t) const { return motion_->at(t); }
  /// Planned time at which s_h reaches s (clamped to the lookup range).
  double time_at(double s_h) const;
  /// Planned s_h at time t.
  double s_h_at(double t) const;
  /// Planned rate of s_h at time t.
  double sdot_h_at(double t) const;
  double s_from() const { return s_.front(); }
  double s_to() const { return s_.back(); }

 private:
  std::shared_ptr<const sim::HandMotion> motion_;
  double duration_;
  std::vector<double> s_, t_;                        ///< lookup table, s increasing
  std::vector<double> plan_t_, plan_s_, plan_sdot_;  ///< s_h(t) and its rate at fine steps
};

/// Stage 2's control law.
enum class ServoLaw {
  /// The paper's: theta'' = kp (theta_p(s) - theta) + kd (thetadot_p(s) - thetadot).
  kPaper,
  /// The plan indexed by s as a time scaling: plan time tau = t_p(s), rate r = sdot / sdot_p(tau);
  /// theta'' = r^2 theta''_p(tau) + kp (theta_p(tau) - theta) + kd (r thetadot_p(tau) - thetadot).
  /// The feedforward removes the lag a pure PD needs to accelerate the hand, and the rate scales
  /// the hand with the disk (faster disk, faster hand) as the plan's geometry requires.
  kTimeScaled,
};
std::string to_string(ServoLaw law);  ///< "paper", "time-scaled"
ServoLaw parse_servo_law(const std::string& name);

/// The paper controller's parameters (scene section `controller`).
struct PaperConfig {
  bool feedback = true;  ///< false: open-loop playback of the plan
  ServoLaw law = ServoLaw::kPaper;
  double kp = 900.0, kd = 120.0;
  double dip_until = -0.9, finish_after = 0.9;
};

/// The paper's controller (type `paper`): section 5's three stages in feedback mode, the plan's
/// playback in open-loop mode. Its modes: "waiting", "dip", "servo", "finish", "open-loop", "done".
class PaperController final : public Controller {
 public:
  explicit PaperController(PaperConfig config);
  void start(const ControllerContext& context) override;
  ControlOutput step(const ControlInput& input) override;
  std::string name() const override { return "paper"; }
  Stage stage() const { return stage_; }

 private:
  double plan_acceleration(double tau) const;  ///< mid-tick value for a 2nd-order reference
  std::shared_ptr<const Plan> plan_;
  PaperConfig config_;
  double dt_ = 1e-3;
  Stage stage_ = Stage::kWaiting;
  std::optional<double> t_end_;
  // Stage 3: plan time at its start and the cubic correction's coefficients.
  double tau3_ = 0, t3_ = 0, c2_ = 0, c3_ = 0;
};

/// The safe stop: decelerate at most at `deceleration` (rad/s^2), and to exactly zero rate within
/// one tick at the end.
double safe_stop_command(double theta_dot, double deceleration, double dt);

/// Watches the loop's inputs for faults that call for a safe stop.
struct SafetyConfig {
  double lost_timeout = 0.25;       ///< s without a new measurement
  double innovation_gate = 50.0;    ///< NIS beyond this is implausible
  int innovation_strikes = 3;       ///< consecutive implausible innovations
  double max_joint_jump = 0.05;     ///< rad, reading vs. prediction from the previous reading
  double stop_deceleration = 20.0;  ///< rad/s^2, the safe stop's
};

class SafetyMonitor {
 public:
  SafetyMonitor(SafetyConfig config, double t_start);
  /// Per tick, with the joint reading. Returns a reason when the joint reading is implausible.
  std::optional<StopReason> check_joint(const JointReading& joint);
  /// A camera frame arrived: `fresh` if its capture time is newer than the last one, `tracked`
  /// if the disk was found and mapped to s_h.
  void frame(double t, bool fresh, bool tracked);
  /// A measurement was folded in with this NIS. Returns a reason after too many strikes.
  std::optional<StopReason> innovation(double nis);
  /// Per tick: a reason when nothing usable has been measured for too long.
  std::optional<StopReason> check_time(double t) const;

 private:
  SafetyConfig config_;
  std::optional<JointReading> last_joint_;
  double t_last_measurement_, t_last_frame_, t_last_fresh_;
  bool any_frame_ = false;
  int strikes_ = 0;
};

}  // namespace flatland::control
