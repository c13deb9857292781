// The closed loop of one butterfly experiment (paper section 5), run against any Clock, Camera
// and Joint, with any controller and estimator (control/interfaces.hpp): each 1 kHz tick reads the
// joint, turns arrived frames into measurements of s_h (tracker -> pixel -> table -> hand -> s_h
// at the hand angle of the capture time), folds them into the estimator, asks the controller for
// an acceleration, commands the joint and propagates the estimator over the tick with what the
// joint did (control/hand_input.hpp). The same code runs synthetic, recorded and live experiments.
// The loop owns the safety monitor and the safe stop: a controller only asks for one.
#pragma once

#include "flatland/control/choice.hpp"
#include "flatland/control/controller.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/control/hand_input.hpp"
#include "flatland/drivers/interfaces.hpp"
#include "flatland/drivers/synthetic.hpp"
#include "flatland/model/model.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace flatland::drivers {

class Recorder;

/// The nominal plan of a scene: its motion (k as given, or solved for the period when
/// controller.plan is "solve"), simulated once on the nominal model.
struct PlanInfo {
  std::shared_ptr<const control::Plan> plan;
  double period = 0, k = 0;
  bool solved = false;
};
PlanInfo make_plan(const model::Model& nominal);
/// What make_plan needs of the scene, checked without planning (a command checks it before it
/// prints or writes anything): a butterfly motion, and a hand with the palm and back wells the
/// plan goes between (sim::require_palm_and_back). Throws std::invalid_argument, one line naming
/// the field.
void require_plannable(const model::Model& nominal);

/// One row of the 1 kHz log.
struct TickLog {
  double t = 0;
  double theta = 0, theta_dot = 0;  ///< as read
  double command = 0;               ///< rad/s^2
  /// The hand's angular acceleration the estimator propagates with over the tick that starts
  /// here (rad/s^2), and where it came from: the change of the read rate over the last tick, or
  /// the command where the readings give none (control/hand_input.hpp).
  double theta_ddot = 0;
  control::AccelerationSource theta_ddot_source = control::AccelerationSource::kCommand;
  /// A replay: the command the recorded run gave at this tick (Joint::recorded_command; NaN
  /// otherwise). Where it parts from `command` is where the changed code decided differently.
  double command_recorded = 0;
  /// The controller's mode ("dip", "servo", ...) or the loop's own: "safe-stop".
  std::string mode;
  double s_est = 0, sdot_est = 0, var_s = 0, var_sdot = 0;  ///< estimate at t (before the tick)
  bool estimating = false;
  bool measured = false;  ///< a measurement was folded in at this tick
  double s_meas = 0, nis = 0;
  double t_capture = 0;  ///< s, when the measured frame was exposed (t minus the latency)
  /// The angle the controller steered toward (ControlOutput::theta_reference; the paper's: the
  /// plan's angle for the estimated s_h in stage 2, else at the time); in a safe stop the plan's
  /// angle at the time.
  double theta_plan = 0;
  // Truth (synthetic runs only; NaN otherwise).
  double s_true = 0, sdot_true = 0, theta_true = 0, fn_ratio = 0, mu_required = 0, nees = 0;
  sim::ContactMode mode_true = sim::ContactMode::kRolling;  ///< the contact's mode (synthetic)
};

/// One camera frame as the loop received it (an experiment's frames.csv): what the reader said
/// of it, what the tracker found and the measurement it became, if any.
struct FrameLog {
  long index = 0;
  double t_capture = 0, t_arrival = 0;
  double t_received = 0;  ///< the tick at which the loop took it
  vision::FrameIntegrity integrity = vision::FrameIntegrity::kIntact;
  bool stale = false;              ///< captured no later than a frame before it: not used
  bool tracked = false;            ///< the tracker ran on it (intact and fresh)
  vision::TrackResult track;       ///< with `tracked`
  bool measured = false;           ///< it became a measurement of s_h
  double s_meas = 0, sigma_s = 0;  ///< with `measured`
};

struct LoopOptions {
  double t_start = -0.25;         ///< s; the hand waits until t = 0 while the estimator locks on
  std::optional<long> max_ticks;  ///< replay: stop after the recorded number of ticks
  Recorder* recorder = nullptr;
  /// Synthetic runs: the world's truth and its failure (the disk dropped).
  const SimWorld* world = nullptr;
  /// Called for each frame the loop receives, with what the tracker made of it.
  std::function<void(const CameraFrame&, const vision::TrackResult&,
                     const std::optional<control::Measurement>&)>
      on_frame;
  std::function<void(double t, double t_end_estimate)> progress;
};

struct LoopResult {
  std::vector<TickLog> log;
  double duration_s = 0;  ///< from t = 0 until the hand stopped (NaN if it never finished)
  bool finished = false;  ///< the controller completed its motion
  bool safe_stop = false;
  std::optional<control::StopReason> stop_reason;  ///< why it stopped safely (with safe_stop)
  long frames = 0;                                 ///< frames received
  long frames_lost = 0;  ///< received but not usable (flagged, disk not found, stale, not mapped)
  /// Of the frames received, those the camera flagged (not intact; never measured), by kind.
  long frames_damaged = 0, frames_repeated = 0, frames_unreadable = 0;
  std::vector<FrameLog> frame_log;  ///< every frame received, in order
  long measurements = 0;
  /// When each of the controller's modes began (in order; a mode entered twice appears twice).
  std::vector<std::pair<double, std::string>> mode_starts;
  /// The paper controller's stage 2 and 3 (the first ticks in modes "servo" and "finish").
  std::optional<double> t_stage2, t_stage3;
  std::string controller, estimator;  ///< their names (Controller::name, Estimator::name)
  double k = 0, period = 0;           ///< the plan used
  long estimator_steps = 0, estimator_repropagated = 0, estimator_updates = 0;
  /// The estimator's propagations by where the hand's acceleration came from.
  long acceleration_from_readings = 0, acceleration_from_command = 0;
};

/// Makes a fresh controller for one run (called once per run; Monte Carlo calls it from its
/// worker threads, so it must be safe to call concurrently).
using ControllerFactory = std::function<std::unique_ptr<control::Controller>()>;
/// Makes a fresh estimator for one run, on the nominal model it is given (the paper's rolling
/// model: what the plan assumed). Called as ControllerFactory is.
using EstimatorFactory = std::function<std::unique_ptr<control::Estimator>(
    std::shared_ptr<const sim::RollingProblem> nominal)>;

/// What the loop assumes: the nominal compiled scene (its mapping, tracker, safety config), its
/// plan, simulated once, and how to make the controller and the estimator of a run (the scene's
/// choice unless the caller brings their own); shared read-only by experiments. Needs a camera
/// and a disk.
struct LoopSetup {
  explicit LoopSetup(std::shared_ptr<const model::Model> nominal);
  /// With the caller's own controller and/or estimator; an empty factory keeps the scene's.
  LoopSetup(std::shared_ptr<const model::Model> nominal, ControllerFactory controller,
            EstimatorFactory estimator = {});
  std::shared_ptr<const model::Model> model;
  PlanInfo plan;
  ControllerFactory make_controller;  ///< never empty
  EstimatorFactory make_estimator;    ///< never empty
  /// What a controller is started with in a loop whose first tick is at t_start.
  control::ControllerContext controller_context(double t_start) const;
};

/// One closed-loop experiment, a tick at a time. Each tick is sense() (read the joint, take the
/// arrived frames, fold in their measurements, check safety), the controller's step on the
/// returned input, then act() (command the joint, log, propagate, advance the clock). run_loop
/// runs it with the setup's controller; a step-by-step environment (Python's flatland.Env)
/// calls sense() and act() itself with its own commands.
class Loop {
 public:
  /// `controller` may be null when the caller drives the loop with act() alone.
  Loop(const LoopSetup& setup, Clock& clock, Camera& camera, Joint& joint,
       const LoopOptions& options, std::unique_ptr<control::Controller> controller,
       std::unique_ptr<control::Estimator> estimator);
  ~Loop();
  Loop(const Loop&) = delete;
  Loop& operator=(const Loop&) = delete;

  /// Begin the next tick: nullptr once the loop has ended (settled after the motion or a safe
  /// stop, or the replay's ticks used up), else what the controller sees at this tick.
  const control::ControlInput* sense();
  /// Ask the loop's controller for this tick's command (it must have one). A controller that
  /// throws std::runtime_error (or anything but std::invalid_argument) stops the loop safely
  /// with its message (cause "controller"); std::invalid_argument propagates.
  control::ControlOutput decide();
  /// Finish the tick sense() began with `output`: during a safe stop the loop's deceleration
  /// replaces it. std::invalid_argument for a non-finite acceleration.
  void act(const control::ControlOutput& output);
  /// sense(), decide(), act(); false once the loop has ended.
  bool tick();

  /// The loop is stopping safely (the controller is no longer asked).
  bool stopping() const;
  /// The controller has declared its motion done.
  bool done() const;
  double t() const;                  ///< the current tick's time
  const LoopResult& result() const;  ///< so far
  /// The result, with the counts of the run filled in; call once the loop has ended.
  LoopResult finish();

 private:
  struct State;
  std::unique_ptr<State> s_;
};

LoopResult run_loop(const LoopSetup& setup, Clock& clock, Camera& camera, Joint& joint,
                    const LoopOptions& options);

/// A whole synthetic experiment: the world obeys `truth`, the loop assumes `setup.model`.
struct SyntheticResult {
  LoopResult loop;
  /// Success: the disk rests in the back well with the hand at pi, judged in the hybrid world
  /// (it may have slipped, flown and been caught on the way).
  Outcome outcome = Outcome::kNotFinished;
  bool success = false;  ///< outcome == kSuccess
  std::string failure;   ///< why not, in words (empty on success)
  double s_end = 0;
  /// The smallest normal force ratio in contact, the largest friction coefficient needed while
  /// rolling (at most the world's mu: beyond it the disk slides).
  double fn_min_ratio = 0, mu_max = 0;
  std::array<double, 4> mode_time{0, 0, 0, 0};  ///< s in each sim::ContactMode
  int impacts = 0, mode_changes = 0;
  std::vector<sim::RecordedEvent> contact_events;  ///< SimWorld::events()
  /// The world's energy audit: the largest |balance| of a servo period's run, J, and that
  /// period's bound (SimWorld::energy_worst).
  double energy_worst = 0, energy_worst_bound = 0;
  /// s the world ran on after a finished motion (hand held) until the disk was trapped in a well
  /// or gone (at most 10 s): the outcome is where the disk ends up.
  double settle_s = 0;
  GoalCheck goal;
  long frames_rendered = 0, frames_dropped = 0;
  double nees_mean = 0;  ///< over frame-arrival ticks
  long nees_samples = 0;
  std::string gl;
};
struct SyntheticOptions {
  Recorder* recorder = nullptr;
  std::function<void(const CameraFrame&, const vision::TrackResult&,
                     const std::optional<control::Measurement>&)>
      on_frame;
  std::function<void(double t, double t_end_estimate)> progress;
};
SyntheticResult run_synthetic(const LoopSetup& setup, std::shared_ptr<const model::Model> truth,
                              const SyntheticOptions& options = {});

/// run_synthetic's verdict on a synthetic experiment whose loop has ended, for callers that drive
/// the Loop themselves (Python's flatland.Env): after a finished motion the world runs on, the
/// hand held, until the disk is trapped in a well or gone (at most 10 s); then the outcome, the
/// world's counts and the camera's. `world` and `camera` are those the loop ran with.
SyntheticResult judge_synthetic(LoopResult loop, SimWorld& world, const SyntheticCamera& camera);

}  // namespace flatland::drivers
