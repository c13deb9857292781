#include "flatland/drivers/experiment.hpp"
#include "flatland/sim/format.hpp"

#include "flatland/drivers/recorded.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/spec.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace flatland::drivers {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// s: how long the world runs on after the loop for the disk to be trapped in a well or gone.
constexpr double kSettleLimit = 10.0;

/// The hand angle at a past time from the joint readings of the last ticks (linear between
/// ticks: the frames' capture times fall between them).
class AngleHistory {
 public:
  void add(double t, double theta) {
    samples_.push_back({t, theta});
    while (samples_.size() > 1024) samples_.pop_front();
  }
  std::optional<double> at(double t) const {
    if (samples_.empty() || t < samples_.front().first) return std::nullopt;
    if (t >= samples_.back().first) return samples_.back().second;
    auto it = std::upper_bound(samples_.begin(), samples_.end(), t,
                               [](double v, const auto& s) { return v < s.first; });
    const auto& b = *it;
    const auto& a = *(it - 1);
    const double w = (t - a.first) / (b.first - a.first);
    return a.second + w * (b.second - a.second);
  }

 private:
  std::deque<std::pair<double, double>> samples_;
};

}  // namespace

void require_plannable(const model::Model& nominal_model) {
  const Scene& nominal = nominal_model.spec;
  const sim::SimulationSpec& spec = nominal.sim;
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw std::invalid_argument(nominal.origin +
                                ": motion: the closed loop follows a butterfly plan "
                                "(motion.type: butterfly)");
  try {  // the plan goes from the palm to the back
    sim::require_palm_and_back(spec.hand, *nominal_model.plant->hand, "the closed loop's plan");
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(nominal.origin + ": " + e.what());
  }
}

PlanInfo make_plan(const model::Model& nominal_model) {
  require_plannable(nominal_model);
  const Scene& nominal = nominal_model.spec;
  const sim::SimulationSpec& spec = nominal.sim;
  PlanInfo info;
  info.period = spec.motion.period;
  info.k = spec.motion.k;
  // The paper planned with its rolling simulation: no losses, rolling enforced.
  sim::SimulationSpec plan_spec = sim::paper_model(spec);
  plan_spec.duration = info.period;
  plan_spec.run.record = true;
  plan_spec.run.events.stop_on_contact_loss = false;  // the plan is followed whatever it does
  plan_spec.run.events.stop_on_slip = false;
  if (nominal.controller.plan == "solve") {
    const sim::SolveReport sol = sim::solve_k(spec, info.period);
    info.k = sol.k;
    info.solved = true;
  }
  plan_spec.motion.k = info.k;
  const sim::RunResult run = sim::run_spec(plan_spec);
  sim::require_no_numerical_failure(run, "plan");
  auto motion = std::make_shared<sim::ButterflyMotion>(info.period, info.k);
  info.plan = std::make_shared<control::Plan>(
      motion, info.period, run, nominal.controller.dip_until, nominal.controller.finish_after);
  return info;
}

LoopSetup::LoopSetup(std::shared_ptr<const model::Model> nominal)
    : LoopSetup(std::move(nominal), ControllerFactory{}, EstimatorFactory{}) {}

LoopSetup::LoopSetup(std::shared_ptr<const model::Model> nominal, ControllerFactory controller,
                     EstimatorFactory estimator)
    : model(std::move(nominal)),
      make_controller(std::move(controller)),
      make_estimator(std::move(estimator)) {
  const Scene& scene = model->spec;
  if (!model->camera)
    throw std::invalid_argument(scene.origin +
                                ": camera: the closed loop needs a camera section (its model "
                                "maps tracked pixels to the table)");
  if (const auto problem = model::tracking_problem(scene.sim.object))
    throw std::invalid_argument(scene.origin + ": " + *problem + " (the closed loop tracks it)");
  plan = make_plan(*model);
  if (!make_controller) {
    const control::ControllerChoice choice = model->controller;
    make_controller = [choice] { return control::make_controller(choice); };
  }
  if (!make_estimator) {
    const control::EstimatorChoice choice = model->estimator;
    make_estimator = [choice](std::shared_ptr<const sim::RollingProblem> nominal) {
      return control::make_estimator(choice, std::move(nominal));
    };
  }
}

control::ControllerContext LoopSetup::controller_context(double t_start) const {
  control::ControllerContext c;
  c.plan = plan.plan;
  c.model = model->paper_plant;
  c.dt = model->control_dt;
  c.t_start = t_start;
  c.s_h_start = model->spec.sim.initial.s_h;
  return c;
}

namespace {

void count_flagged(vision::FrameIntegrity integrity, LoopResult& out) {
  switch (integrity) {
    case vision::FrameIntegrity::kIntact:
      return;
    case vision::FrameIntegrity::kDamaged:
      ++out.frames_damaged;
      return;
    case vision::FrameIntegrity::kRepeated:
      ++out.frames_repeated;
      return;
    case vision::FrameIntegrity::kUnreadable:
      ++out.frames_unreadable;
      return;
  }
}

// What an intact, fresh frame measures: the tracked centre mapped to s_h at the hand angle of its
// capture time, with the tracker's 1-sigma carried through the mapping; none when the disk is
// not found or not mapped. What happened goes into `tr` and `flog`.
std::optional<control::Measurement> measure_frame(const CameraFrame& frame,
                                                  const vision::HandMapping& mapping,
                                                  vision::Tracker& tracker,
                                                  const AngleHistory& angles, double guess,
                                                  vision::TrackResult& tr, FrameLog& flog) {
  tr = tracker.track(frame.image);
  flog.tracked = true;
  flog.track = tr;
  const std::optional<double> theta = angles.at(frame.t_capture);
  if (!tr.ok() || !theta) return std::nullopt;
  const auto c = vision::pixel_to_contact(mapping, tr.center, *theta, guess, 0.5);
  if (!c) return std::nullopt;
  const double sigma = vision::contact_sigma(mapping, tr.center, tr.sigma_px, *theta, c->s_h);
  flog.measured = true;
  flog.s_meas = c->s_h;
  flog.sigma_s = sigma;
  return control::Measurement{frame.t_capture, frame.t_arrival, c->s_h, sigma};
}

// The tick's log columns of the belief.
void fill_estimate(TickLog& row, const control::Estimate& est, bool estimating) {
  row.estimating = estimating;
  row.s_est = est.s_h;
  row.sdot_est = est.sdot_h;
  row.var_s = est.covariance(0, 0);
  row.var_sdot = est.covariance(1, 1);
}

// The tick's truth columns: the synthetic world's state (NEES with an estimate), NaN otherwise.
void fill_truth(TickLog& row, const SimWorld* world, double t, const control::Estimate* est) {
  if (!world) {
    row.s_true = row.sdot_true = row.theta_true = row.fn_ratio = row.mu_required = row.nees = kNaN;
    return;
  }
  const WorldSample w = world->state_at(t);
  row.s_true = w.s_h;
  row.sdot_true = w.sdot_h;
  row.theta_true = w.theta;
  row.fn_ratio = w.fn_ratio;
  row.mu_required = w.mu_required;
  row.mode_true = w.mode;
  row.nees = est ? control::nees(*est, w.s_h, w.sdot_h) : kNaN;
}

}  // namespace

struct Loop::State {
  State(const LoopSetup& setup_, Clock& clock_, Camera& camera_, Joint& joint_,
        const LoopOptions& options_, std::unique_ptr<control::Controller> controller_,
        std::unique_ptr<control::Estimator> estimator_)
      : setup(setup_),
        model(*setup_.model),
        scene(model.spec),
        plan(*setup_.plan.plan),
        clock(clock_),
        camera(camera_),
        joint(joint_),
        options(options_),
        controller(std::move(controller_)),
        estimator(std::move(estimator_)),
        safety(model.safety, options_.t_start),
        tracker(model.tracker),
        dt(1.0 / scene.joint.rate),
        t_limit(2.0 * plan.duration() + 2.0),  // a stalled stage 2 ends in a safe stop
        settle(scene.controller.settle) {}

  const LoopSetup& setup;
  const model::Model& model;
  const Scene& scene;
  const control::Plan& plan;
  Clock& clock;
  Camera& camera;
  Joint& joint;
  const LoopOptions& options;
  std::unique_ptr<control::Controller> controller;
  std::unique_ptr<control::Estimator> estimator;
  control::SafetyMonitor safety;
  vision::Tracker tracker;
  // The estimator is driven by what the joint did (its readings), not by what was commanded: a
  // replayed joint moves as it moved in the recording, and a real one lags its command.
  control::HandInputFromJoint hand_input;
  AngleHistory angles;
  const double dt, t_limit, settle;

  LoopResult out;
  long tick = -1;
  bool in_tick = false, ended = false, estimating = false;
  // The estimator threw (its belief became non-finite, a user's estimator raised): the belief is
  // gone, the loop stops safely and does not ask it again.
  bool estimator_failed = false;
  double last_capture = -std::numeric_limits<double>::infinity();
  std::optional<double> t_rest;  // when the hand came to rest after finishing or stopping
  std::optional<control::StopReason> stop;
  bool done = false;
  std::optional<double> t_done;
  control::ControlInput input;
  TickLog row;

  double time_of(long i) const {
    // Integer tick arithmetic: a replay computes the very same times.
    return options.t_start + static_cast<double>(i) * dt;
  }
  void safe_stop(control::StopReason why) {
    if (!stop) stop = std::move(why);
  }
  /// Runs one call of the estimator; a failure (anything but std::invalid_argument, which is the
  /// caller's bad input and propagates) ends the estimation and stops the loop safely.
  template <typename Call>
  void with_estimator(Call&& call) {
    try {
      call();
    } catch (const std::invalid_argument&) {
      throw;
    } catch (const std::exception& e) {
      estimator_failed = true;
      estimating = false;
      safe_stop({control::StopCause::kEstimator, std::string("estimator: ") + e.what()});
    }
  }
  void take_frames(double t);
};

// Frames that have arrived by t: track, map to s_h, fold in.
void Loop::State::take_frames(double t) {
  while (auto frame = camera.poll(t)) {
    ++out.frames;
    const bool intact = frame->integrity == vision::FrameIntegrity::kIntact;
    // A flagged frame is not recorded: a recording's frames are replayed as intact (lossless,
    // bit-exact), so it would be measured there; its missing index reads as a dropped frame.
    if (options.recorder && intact) options.recorder->add_frame(*frame);
    count_flagged(frame->integrity, out);
    const bool fresh = frame->t_capture > last_capture;
    vision::TrackResult tr;
    std::optional<control::Measurement> z;
    FrameLog flog;
    flog.index = frame->index;
    flog.t_capture = frame->t_capture;
    flog.t_arrival = frame->t_arrival;
    flog.t_received = t;
    flog.integrity = frame->integrity;
    flog.stale = !fresh;
    if (fresh) last_capture = frame->t_capture;
    if (fresh && intact) {
      double guess = scene.sim.initial.s_h;
      if (estimating) with_estimator([&] { guess = estimator->estimate().s_h; });
      z = measure_frame(*frame, *model.mapping, tracker, angles, guess, tr, flog);
    }
    out.frame_log.push_back(flog);
    safety.frame(t, fresh, z.has_value());
    if (z) {
      ++out.measurements;
      if (!estimating && !estimator_failed) {
        with_estimator([&] {
          estimator->reset(t, z->s_h, 0.0);
          estimating = true;
        });
      } else if (estimating) {
        with_estimator([&] {
          const control::UpdateReport u = estimator->update(*z);
          row.nis = u.nis;
          if (auto why = safety.innovation(u.nis)) safe_stop(*why);
        });
      }
      row.measured = true;
      row.s_meas = z->s_h;
      row.t_capture = z->t_capture;
      input.measurement = z;
    } else {
      ++out.frames_lost;
    }
    if (options.on_frame) options.on_frame(*frame, tr, z);
  }
}

Loop::Loop(const LoopSetup& setup, Clock& clock, Camera& camera, Joint& joint,
           const LoopOptions& options, std::unique_ptr<control::Controller> controller,
           std::unique_ptr<control::Estimator> estimator)
    : s_(std::make_unique<State>(setup, clock, camera, joint, options, std::move(controller),
                                 std::move(estimator))) {
  if (!s_->estimator) throw std::invalid_argument("loop: no estimator");
  State& s = *s_;
  s.out.k = setup.plan.k;
  s.out.period = setup.plan.period;
  s.out.duration_s = kNaN;
  s.out.estimator = s.estimator->name();
  if (s.controller) {
    s.out.controller = s.controller->name();
    s.controller->start(setup.controller_context(options.t_start));
  }
  s.out.log.reserve(
      static_cast<std::size_t>((s.t_limit - options.t_start + s.settle) * s.scene.joint.rate) + 16);
}

Loop::~Loop() = default;

const control::ControlInput* Loop::sense() {
  State& s = *s_;
  if (s.in_tick) throw std::logic_error("Loop::sense: the tick before was not finished (act)");
  if (s.ended) return nullptr;
  const long tick = s.tick + 1;
  if (s.options.max_ticks && tick >= *s.options.max_ticks) {
    s.ended = true;
    return nullptr;
  }
  s.tick = tick;
  s.in_tick = true;
  const double t = s.time_of(tick);
  s.row = TickLog{};
  s.row.t = t;
  s.input = control::ControlInput{};
  s.input.t = t;
  const control::JointReading reading = s.joint.read(t);
  s.input.joint = reading;
  s.row.theta = reading.theta;
  s.row.theta_dot = reading.theta_dot;
  s.angles.add(t, reading.theta);
  if (auto why = s.safety.check_joint(reading)) s.safe_stop(*why);
  s.take_frames(t);
  if (auto why = s.safety.check_time(t)) s.safe_stop(*why);
  // Synthetic runs: the disk has left the hand's reach for good; stop the hand safely.
  if (s.options.world && s.options.world->failure())
    s.safe_stop({control::StopCause::kDisk, "disk: " + s.options.world->failure_detail()});
  if (t > s.t_limit)
    s.safe_stop({control::StopCause::kTimeout, "timeout: the motion did not finish by t = " +
                                                   sim::format_significant(s.t_limit, 5) + " s"});
  control::Estimate est;
  if (s.estimating) s.with_estimator([&] { est = s.estimator->estimate(); });
  if (!s.estimating) {
    est = control::Estimate{};
    est.s_h = s.scene.sim.initial.s_h;
  }
  fill_estimate(s.row, est, s.estimating);
  s.input.estimate = est;
  s.input.estimating = s.estimating;
  return &s.input;
}

control::ControlOutput Loop::decide() {
  State& s = *s_;
  if (!s.in_tick) throw std::logic_error("Loop::decide: no tick begun (sense)");
  if (!s.controller) throw std::logic_error("Loop::decide: the loop has no controller");
  if (s.stop) return {};
  try {
    control::ControlOutput out = s.controller->step(s.input);
    if (out.stop) s.safe_stop({control::StopCause::kController, out.stop->detail});
    return out;
  } catch (const std::invalid_argument&) {
    throw;
  } catch (const std::exception& e) {
    s.safe_stop({control::StopCause::kController, std::string("controller: ") + e.what()});
    return {};
  }
}

void Loop::act(const control::ControlOutput& output) {
  State& s = *s_;
  if (!s.in_tick) throw std::logic_error("Loop::act: no tick begun (sense)");
  const double t = s.input.t;
  const control::JointReading& reading = s.input.joint;
  TickLog& row = s.row;
  double command;
  if (s.stop) {
    command = control::safe_stop_command(reading.theta_dot, s.model.safety.stop_deceleration, s.dt);
    row.mode = "safe-stop";
    row.theta_plan = s.plan.hand(std::max(t, 0.0)).angle;
  } else {
    if (!std::isfinite(output.theta_ddot))
      throw std::invalid_argument(
          "controller" + (s.out.controller.empty() ? "" : " '" + s.out.controller + "'") +
          ": returned a non-finite acceleration (" + sim::format_significant(output.theta_ddot) +
          ") at t = " + sim::format_significant(t, 6) + " s");
    command = output.theta_ddot;
    row.mode = output.mode;
    row.theta_plan = output.theta_reference;
    if (output.done && !s.done) {
      s.done = true;
      s.t_done = output.t_done ? *output.t_done : t;
    }
  }
  if (s.out.mode_starts.empty() || s.out.mode_starts.back().second != row.mode)
    s.out.mode_starts.emplace_back(t, row.mode);
  row.command = command;
  s.joint.command(t, command);
  row.command_recorded = s.joint.recorded_command();
  if (s.options.recorder) s.options.recorder->add_tick(reading, command);
  const control::HandInputChoice hand = s.hand_input.next(reading, command);
  row.theta_ddot = hand.input.theta_ddot;
  row.theta_ddot_source = hand.source;
  fill_truth(row, s.options.world, t, s.estimating ? &s.input.estimate : nullptr);
  s.out.log.push_back(row);
  s.in_tick = false;

  // Ending: settle after the hand has stopped (finished or safe-stopped).
  if ((s.done || s.stop) && !s.t_rest && std::abs(reading.theta_dot) < 1e-3) s.t_rest = t;
  if (s.t_rest && t >= *s.t_rest + s.settle) {
    s.ended = true;
    return;
  }
  const double t_next = s.time_of(s.tick + 1);
  if (s.estimating) s.with_estimator([&] { s.estimator->propagate(t_next, hand.input); });
  if (s.estimating) {
    ++(hand.source == control::AccelerationSource::kReadings ? s.out.acceleration_from_readings
                                                             : s.out.acceleration_from_command);
  }
  if (s.options.progress && s.tick % 100 == 0) s.options.progress(t, s.plan.duration() + s.settle);
  s.clock.sleep_until(t_next);
}

bool Loop::tick() {
  if (!sense()) return false;
  act(decide());
  return !s_->ended;
}

bool Loop::stopping() const { return s_->stop.has_value(); }
bool Loop::done() const { return s_->done; }
double Loop::t() const { return s_->time_of(std::max(s_->tick, 0L)); }
const LoopResult& Loop::result() const { return s_->out; }

LoopResult Loop::finish() {
  State& s = *s_;
  LoopResult out = s.out;
  out.finished = s.done && !s.stop;
  out.safe_stop = s.stop.has_value();
  out.stop_reason = s.stop;
  if (out.finished && s.t_done) out.duration_s = *s.t_done;
  for (const auto& [t, mode] : out.mode_starts) {
    if (mode == "servo" && !out.t_stage2) out.t_stage2 = t;
    if (mode == "finish" && !out.t_stage3) out.t_stage3 = t;
  }
  const control::EstimatorCounts counts = s.estimator->counts();
  out.estimator_steps = counts.steps;
  out.estimator_repropagated = counts.repropagated;
  out.estimator_updates = counts.updates;
  return out;
}

LoopResult run_loop(const LoopSetup& setup, Clock& clock, Camera& camera, Joint& joint,
                    const LoopOptions& options) {
  Loop loop(setup, clock, camera, joint, options, setup.make_controller(),
            setup.make_estimator(setup.model->paper_plant));
  while (loop.tick()) {
  }
  return loop.finish();
}

SyntheticResult run_synthetic(const LoopSetup& setup, std::shared_ptr<const model::Model> truth,
                              const SyntheticOptions& options) {
  LoopOptions lo;
  SimWorld world(truth, lo.t_start);
  SimClock clock(&world, lo.t_start);
  SimJoint joint(world, truth->spec.faults);
  SyntheticCamera camera(truth, world, lo.t_start);
  lo.world = &world;
  lo.recorder = options.recorder;
  lo.on_frame = options.on_frame;
  lo.progress = options.progress;

  return judge_synthetic(run_loop(setup, clock, camera, joint, lo), world, camera);
}

SyntheticResult judge_synthetic(LoopResult loop, SimWorld& world, const SyntheticCamera& camera) {
  SyntheticResult r;
  r.loop = std::move(loop);
  const std::optional<Outcome> failed_in_loop = world.failure();
  // After a finished motion the outcome is where the disk ends up: the world runs on, the hand
  // held, until the disk is trapped in a well (the losses then settle it there) or gone.
  if (r.loop.finished && !failed_in_loop) r.settle_s = world.settle(kSettleLimit);
  r.gl = camera.gl_description();
  r.frames_rendered = camera.rendered();
  r.frames_dropped = camera.dropped();
  r.goal = world.goal_check();
  r.s_end = r.goal.s_h;
  r.fn_min_ratio = world.fn_min_ratio();
  r.mu_max = world.mu_max();
  double nees_sum = 0;
  for (const TickLog& row : r.loop.log)
    if (row.measured && std::isfinite(row.nees)) {
      nees_sum += row.nees;
      ++r.nees_samples;
    }
  r.nees_mean = r.nees_samples ? nees_sum / static_cast<double>(r.nees_samples) : kNaN;
  r.mode_time = world.mode_time();
  r.impacts = world.impacts();
  r.mode_changes = world.mode_changes();
  r.contact_events = world.events();
  r.energy_worst = world.energy_worst();
  r.energy_worst_bound = world.energy_worst_bound();
  // The first thing that went wrong: the disk lost during the loop (the loop then stops
  // safely), a safe stop of the loop's own, an unfinished motion, the disk lost afterwards.
  if (failed_in_loop) {
    r.outcome = *failed_in_loop;
    r.failure = world.failure_detail();
  } else if (r.loop.safe_stop) {
    r.outcome = Outcome::kSafeStop;
    r.failure = "safe stop: " + r.loop.stop_reason->detail;
  } else if (!r.loop.finished) {
    r.outcome = Outcome::kNotFinished;
    r.failure = "the motion did not finish";
  } else if (world.failure()) {
    r.outcome = *world.failure();
    r.failure = world.failure_detail();
  } else if (!r.goal.in_goal) {
    const bool other_well =
        !(r.goal.well_bottom > 0.5 && r.goal.well_bottom < 1.5) && r.goal.trapped;
    r.outcome = other_well ? Outcome::kWrongWell : Outcome::kNotSettled;
    r.failure = r.goal.reason;
  } else {
    r.outcome = Outcome::kSuccess;
  }
  r.success = r.outcome == Outcome::kSuccess;
  return r;
}

}  // namespace flatland::drivers
