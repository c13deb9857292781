// What the closed loop asks of a controller and of an estimator: the two places where a
// researcher brings their own law. The paper's three-stage controller (controller.hpp) and the
// transverse-linearisation controller (transverse.hpp) are controllers; the extended Kalman
// filter (estimator.hpp) and the unscented filter (ukf.hpp) are estimators. The loop
// (drivers/experiment.hpp) owns everything around them: the camera pipeline, the safety monitor
// and the safe stop, the hand input, the logs. Like MuJoCo's control callback, a controller is
// called once per control tick and returns the joint's command; unlike it, it sees only what a
// real loop sees (the joint's reading and the estimator's belief), never the simulator's state.
#pragma once

#include "flatland/control/types.hpp"
#include "flatland/sim/rolling.hpp"

#include <memory>
#include <optional>
#include <string>

namespace flatland::control {

class Plan;

/// What made the loop stop safely: a value to count and compare, with the sentence for people.
enum class StopCause {
  kJoint,       ///< an implausible joint reading (non-finite, an encoder glitch)
  kEstimator,   ///< too many implausible innovations in a row
  kCamera,      ///< no frames, or frames that stopped changing
  kTracking,    ///< frames, but no disk measured in them for too long
  kDisk,        ///< the world's disk failed (dropped, slid off)
  kTimeout,     ///< the motion did not finish in time
  kController,  ///< the controller asked for it (or failed: raised, returned non-finite)
};
/// "joint", "estimator", "camera", "tracking", "disk", "timeout", "controller".
const char* to_string(StopCause cause);

struct StopReason {
  StopCause cause = StopCause::kTimeout;
  std::string detail;  ///< one sentence, starting with to_string(cause) and a colon
};

/// What a controller is given once, before the first tick.
struct ControllerContext {
  /// The planned motion and the disk's planned s_h along it (nominal model, no losses).
  std::shared_ptr<const Plan> plan;
  /// The nominal model the plan was made with (the paper's rolling model, no losses): hand,
  /// disk and in-plane gravity, as the estimator assumes them.
  std::shared_ptr<const sim::RollingProblem> model;
  double dt = 1e-3;       ///< s, the control period (the loop's ticks are t_start + i dt)
  double t_start = 0;     ///< s, the first tick; the motion is planned to start at t = 0
  double s_h_start = -1;  ///< the s_h the scene starts the disk at (the palm well)
};

/// What a controller sees at one tick.
struct ControlInput {
  double t = 0;             ///< s, this tick
  JointReading joint;       ///< the joint as read at t
  Estimate estimate;        ///< the belief at t (before the tick's propagation)
  bool estimating = false;  ///< false until the first measurement: `estimate` is then s_h_start
  /// The latest measurement folded in at this tick, when one was.
  std::optional<Measurement> measurement;
};

/// What a controller commands for one tick.
struct ControlOutput {
  double theta_ddot = 0;  ///< rad/s^2, held over the tick
  /// The controller's mode for the log ("dip", "servo", ...): free text, one word.
  std::string mode;
  /// The hand angle the controller is steering toward at this tick, rad (the log's theta_plan);
  /// NaN when it has none.
  double theta_reference = 0;
  /// The motion is over: the loop settles and ends (the controller keeps being called, to hold
  /// the hand). Once set it stays set.
  bool done = false;
  /// With `done`: when the motion ended, s (the tick's time when not given).
  std::optional<double> t_done;
  /// A request to stop safely: the loop stops calling the controller and brings the hand to rest.
  std::optional<StopReason> stop;
};

/// A control law. One instance runs one experiment (a factory makes one per world, so that Monte
/// Carlo is deterministic whatever the thread count).
class Controller {
 public:
  virtual ~Controller() = default;
  /// Once, before the first tick. Throws std::invalid_argument when the plan or model does not
  /// suit the law (the message names the config field).
  virtual void start(const ControllerContext& context) = 0;
  /// The command for the tick at input.t. Called at every tick until the loop stops safely.
  virtual ControlOutput step(const ControlInput& input) = 0;
  /// The law's name as the scene spells its type ("paper", "transverse", or the user's).
  virtual std::string name() const = 0;
};

/// What one measurement update did (for logs, consistency tests and fault detection).
struct UpdateReport {
  bool applied = false;         ///< false if the capture time is older than the stored history
  double innovation = 0;        ///< z - predicted s_h at the capture time
  double innovation_sigma = 0;  ///< sqrt(H P H^T + R)
  double nis = 0;               ///< normalised innovation squared (chi-square, 1 dof)
  int repropagated_steps = 0;
};

/// The work an estimator did, for the run's report.
struct EstimatorCounts {
  long steps = 0;         ///< propagation steps taken
  long repropagated = 0;  ///< of which re-propagations after a late measurement
  long updates = 0;       ///< measurements folded in
};

/// A belief over (s_h, sdot_h): reset at the first measurement, propagated over every tick with
/// the hand input the loop derives from the joint's readings, corrected by each measurement at
/// its capture time (which may be in the past: camera latency).
class Estimator {
 public:
  virtual ~Estimator() = default;
  /// Start at time t from (s_h, sdot_h) with the configured initial uncertainty.
  virtual void reset(double t, double s_h, double sdot_h) = 0;
  /// Advance the belief from its current time to t_next with the hand input held over the
  /// interval. std::invalid_argument for t_next not after the current time or non-finite input;
  /// std::runtime_error if the belief becomes non-finite.
  virtual void propagate(double t_next, const HandInput& input) = 0;
  /// Fold in a measurement captured at z.t_capture (<= the current time).
  virtual UpdateReport update(const Measurement& z) = 0;
  /// The belief at the current time; the covariance is that of (s_h, sdot_h), so that NEES can be
  /// computed against the truth.
  virtual Estimate estimate() const = 0;
  virtual EstimatorCounts counts() const = 0;
  /// The estimator's name as the scene spells its type ("ekf", "ukf", or the user's).
  virtual std::string name() const = 0;
};

}  // namespace flatland::control
