#include "flatland/drivers/synthetic.hpp"
#include "flatland/sim/format.hpp"

#include "flatland/sim/spec.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace flatland::drivers {
namespace {

Eigen::Matrix2d rotation(double a) {
  Eigen::Matrix2d r;
  r << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  return r;
}

/// Cubic Hermite interpolation of a value with its derivative over [0, h] at fraction u.
double hermite(double y0, double d0, double y1, double d1, double h, double u) {
  const double u2 = u * u, u3 = u2 * u;
  return (2 * u3 - 3 * u2 + 1) * y0 + (u3 - 2 * u2 + u) * h * d0 + (-2 * u3 + 3 * u2) * y1 +
         (u3 - u2) * h * d1;
}

}  // namespace

void require_friction(const Scene& scene) {
  if (!scene.sim.contact.mu)
    throw std::invalid_argument(
        scene.origin +
        ": contact.mu: a synthetic experiment needs the friction coefficient between the disk and "
        "the hand (the world slides where the motion needs more); the bundled air-table scenes "
        "say which values they assume and why");
}

std::string to_string(Outcome o) {
  switch (o) {
    case Outcome::kSuccess:
      return "success";
    case Outcome::kDropped:
      return "dropped";
    case Outcome::kSlidOff:
      return "slid_off";
    case Outcome::kWrongWell:
      return "wrong_well";
    case Outcome::kNotSettled:
      return "not_settled";
    case Outcome::kSafeStop:
      return "safe_stop";
    case Outcome::kNotFinished:
      return "not_finished";
    case Outcome::kNumericalFailure:
      return "numerical_failure";
    case Outcome::kInvalidWorld:
      return "invalid_world";
  }
  return "?";
}

bool has_physical_outcome(Outcome o) {
  return o != Outcome::kNumericalFailure && o != Outcome::kInvalidWorld;
}

SimWorld::SimWorld(std::shared_ptr<const model::Model> truth_model, double t_start)
    : model_(std::move(truth_model)),
      scene_(model_->spec),
      dt_(1.0 / scene_.joint.rate),
      t_start_(t_start),
      t_(t_start) {
  const Scene& truth = scene_;
  if (!truth.sim.object.round())
    throw std::invalid_argument(truth.origin +
                                ": object.type: the closed loop rolls a disk, ring or ball");
  require_friction(truth);
  // The world is the hybrid model whatever the scene's contact.model: it slides, flies and is
  // caught again where the real table would.
  sim::SimulationSpec spec = truth.sim;
  spec.run.model = sim::ContactModel::kHybrid;
  problem_ = model_->plant;
  step_options_ = sim::run_options(spec);
  step_options_.formulation = sim::Formulation::kReduced;
  step_options_.record = false;
  step_options_.stop_at_transition = true;           // the joint's load changes there
  step_options_.hand_inertia = truth.joint.inertia;  // an impact kicks the hand too
  step_options_.events.s_h_bounds.reset();

  theta_ = problem_->motion->at(0.0).angle;
  theta_ref_ = theta_;
  sim::InitialContact init = truth.sim.initial;
  init.t0 = t_start;
  const auto resting = held(t_start, 0.0);
  disk_ = sim::hybrid_state(*resting, init);
  const sim::Sample s = sim::sample_state(resting, disk_);
  disk_.position = s.object_position;
  disk_.velocity = s.object_velocity;
  disk_.angular_velocity = s.object_angular_velocity;
  const double q = 2.0 * M_PI / static_cast<double>(truth.joint.encoder_counts);
  encoder_ = std::round(theta_ / q) * q;
  history_.reserve(8192);
  history_.push_back(sample_now(0.0, 0.0));
}

std::shared_ptr<const sim::RollingProblem> SimWorld::held(double t, double alpha) const {
  auto pb = std::make_shared<sim::RollingProblem>(*problem_);
  pb->motion = std::make_shared<sim::HeldAcceleration>(t, theta_, theta_dot_, alpha);
  return pb;
}

double SimWorld::reaction_torque(double t, double alpha) const {
  if (failure_ || disk_.mode == sim::ContactMode::kFlight) return 0.0;
  sim::HybridState x = disk_;
  x.t = t;
  const sim::Sample s = sim::sample_state(held(t, alpha), x);
  const sim::CurveGeometry g = problem_->hand->geometry(x.s_h, x.hand_piece);
  const Eigen::Matrix2d R = rotation(theta_);
  const sim::Vec2 force_on_disk =
      s.force_normal * (R * g.normal) + s.force_tangential * (R * g.tangent);
  const sim::Vec2 contact = R * g.point;  // from the pivot
  // The disk pushes back on the hand with -force_on_disk at the contact point.
  return -(contact.x() * force_on_disk.y() - contact.y() * force_on_disk.x());
}

double SimWorld::joint_acceleration(double t, double t_end, double tau, bool& stops) const {
  const JointSpec& j = scene_.joint;
  stops = false;
  // The disk's reaction is affine in the hand's acceleration: tau_disk = r0 + r1 alpha (it adds
  // inertia while in contact; in flight, or once dropped, the joint moves alone).
  const double r0 = reaction_torque(t, 0.0);
  const double r1 = reaction_torque(t, 1.0) - r0;
  const double drive = tau - j.viscous * theta_dot_ + r0;
  if (theta_dot_ == 0.0 && std::abs(drive) <= j.coulomb) return 0.0;  // stiction holds
  const double direction =
      theta_dot_ != 0.0 ? (theta_dot_ > 0 ? 1.0 : -1.0) : (drive > 0 ? 1.0 : -1.0);
  const double alpha = (drive - j.coulomb * direction) / (j.inertia - r1);
  const double next_rate = theta_dot_ + alpha * (t_end - t);
  if (theta_dot_ != 0.0 && next_rate * theta_dot_ < 0 && std::abs(drive) <= j.coulomb) {
    // Dry friction brings the joint to rest within this period rather than reversing it.
    stops = true;
    return -theta_dot_ / (t_end - t);
  }
  return alpha;
}

double SimWorld::step_disk(double t, double t_end, double alpha) {
  if (failure_ == Outcome::kNumericalFailure) {
    disk_.t = t_end;  // the numbers stopped meaning anything: the disk stands where it was
    return t_end;
  }
  if (failure_) {
    // Out of the hand's reach for good: it flies on (and out of the camera's view).
    disk_ = sim::fly(*problem_, disk_, t_end);
    mode_time_[static_cast<int>(sim::ContactMode::kFlight)] += t_end - t;
    return t_end;
  }
  sim::RunOptions opt = step_options_;
  opt.t_end = t_end;
  disk_.t = t;
  if (disk_.mode != sim::ContactMode::kFlight) last_contact_mode_ = disk_.mode;
  sim::RunResult r;
  try {
    r = sim::simulate_hybrid(held(t, alpha), disk_, opt);
  } catch (const std::runtime_error& e) {
    // The integrator gave up (step budget, step underflow, a contact that keeps switching):
    // the world's numerical failure, which the experiment reports as its outcome.
    failure_ = Outcome::kNumericalFailure;
    failure_detail_ = std::string("the world's simulation failed at t = ") +
                      sim::format_significant(t, 8) + " s: " + e.what();
    return t_end;
  }
  if (std::abs(r.audit.balance) >= energy_worst_) {
    energy_worst_ = std::abs(r.audit.balance);
    energy_worst_bound_ = r.audit.bound();
  }
  if (r.reason == sim::StopReason::kNumericalFailure) {
    failure_ = Outcome::kNumericalFailure;
    failure_detail_ = "the world's simulation failed numerically: " + sim::breach_text(r.audit);
    disk_.t = t_end;
    return t_end;
  }
  for (int m = 0; m < 4; ++m) mode_time_[m] += r.stats.mode_time[m];
  impacts_ += r.stats.impacts;
  mode_changes_ += r.stats.mode_changes;
  disk_ = *r.final_state;
  for (const sim::RecordedEvent& e : r.events) {
    if (e.kind != sim::EventKind::kJunction && e.kind != sim::EventKind::kApex)
      events_.push_back(e);
    if (e.kind == sim::EventKind::kImpact) theta_dot_kick_ += e.hand_rate_change;
    if (e.kind == sim::EventKind::kSlipStart || e.kind == sim::EventKind::kStick ||
        e.kind == sim::EventKind::kRest || e.kind == sim::EventKind::kRelease)
      last_contact_mode_ = disk_.mode;
  }
  if (r.reason == sim::StopReason::kDropped) {
    failure_ =
        last_contact_mode_ == sim::ContactMode::kSliding ? Outcome::kSlidOff : Outcome::kDropped;
    failure_detail_ =
        std::string(last_contact_mode_ == sim::ContactMode::kSliding ? "the disk slid off the hand"
                                                                     : "the disk lost contact") +
        " and was not caught (out of the hand's reach at t = " +
        sim::format_significant(disk_.t, 6) + " s)";
  }
  return disk_.t;
}

WorldSample SimWorld::sample_now(double alpha, double torque) const {
  WorldSample w;
  w.t = t_;
  w.theta = theta_;
  w.theta_dot = theta_dot_;
  w.theta_ddot = alpha;
  w.theta_ref = theta_ref_;
  w.torque = torque;
  sim::HybridState x = disk_;
  x.t = t_;
  const sim::Sample s = sim::sample_state(held(t_, alpha), x);
  w.mode = disk_.mode;
  w.s_h = s.s_h;
  w.sdot_h = s.sdot_h;
  w.disk_position = s.object_position;
  w.disk_velocity = s.object_velocity;
  w.disk_angle = s.object_angle;
  w.disk_rate = s.object_angular_velocity;
  w.fn_ratio = s.fn_ratio;
  w.ft_ratio = s.ft_ratio;
  w.mu_required = s.mu_required;
  return w;
}

void SimWorld::servo_step() {
  const JointSpec& j = scene_.joint;
  // The drive: feedforward of the commanded acceleration on the nominal inertia, PD on the
  // reference, saturated; held over the period.
  const double tau_cmd = j.inertia * command_ + j.kp * (theta_ref_ - encoder_) +
                         j.kd * (theta_dot_ref_ - velocity_estimate_);
  const double tau = std::clamp(tau_cmd, -j.torque_limit, j.torque_limit);
  const double t_end = t_start_ + static_cast<double>(tick_ + 1) * dt_;
  double t = t_, alpha = 0;
  // The period in pieces: where the contact changes mode, the disk's load on the joint changes,
  // and so does the hand's acceleration; an impact changes the hand's rate at once.
  for (int piece = 0; t < t_end; ++piece) {
    if (piece > 1000)
      throw std::runtime_error(
          "world: the contact changes mode more than 1000 times within one "
          "servo period at t = " +
          sim::format_significant(t, 6) + " s");
    bool stops = false;
    alpha = joint_acceleration(t, t_end, tau, stops);
    if (!failure_ && disk_.mode != sim::ContactMode::kFlight) {
      // The forces right after the acceleration was set (it jumps at ticks and at changes of
      // mode, and the forces with it).
      sim::HybridState x = disk_;
      x.t = t;
      const sim::Sample s = sim::sample_state(held(t, alpha), x);
      fn_min_ = std::min(fn_min_, s.fn_ratio);
      // The friction needed while rolling: beyond mu the disk slides from this instant on.
      if (disk_.mode != sim::ContactMode::kSliding && std::isfinite(s.mu_required) &&
          s.mu_required <= problem_->contact.mu_static())
        mu_max_ = std::max(mu_max_, s.mu_required);
    }
    theta_dot_kick_ = 0;
    const double t1 = step_disk(t, t_end, alpha);
    const double tau_step = t1 - t;
    theta_ += tau_step * (theta_dot_ + 0.5 * tau_step * alpha);
    theta_dot_ = stops && t1 >= t_end ? 0.0 : theta_dot_ + alpha * tau_step;
    theta_dot_ += theta_dot_kick_;
    t = t1;
  }
  theta_ref_ += dt_ * (theta_dot_ref_ + 0.5 * dt_ * command_);
  theta_dot_ref_ += dt_ * command_;
  t_ = t_end;
  ++tick_;

  // The encoder and the drive's velocity estimate (filtered difference of encoder readings).
  const double q = 2.0 * M_PI / static_cast<double>(j.encoder_counts);
  const double previous = encoder_;
  encoder_ = std::round(theta_ / q) * q;
  const double raw = (encoder_ - previous) / dt_;
  velocity_estimate_ += (raw - velocity_estimate_) * dt_ / (j.velocity_filter + dt_);
  // The state at the new tick (forces with the acceleration held up to it).
  history_.push_back(sample_now(alpha, tau));
}

void SimWorld::advance_to(double t) {
  while (t_ + 0.5 * dt_ <= t) servo_step();
}

double SimWorld::settle(double max_time) {
  const double t0 = t_;
  // Checked every 10 ms: trapped (the losses settle it in that well) or gone.
  const long per_check = std::max(1L, std::lround(0.01 / dt_));
  while (t_ - t0 < max_time && !failure_ && !goal_check().trapped)
    for (long i = 0; i < per_check; ++i) servo_step();
  return t_ - t0;
}

control::JointReading SimWorld::read_encoder() const {
  control::JointReading r;
  r.t = t_;
  r.theta = encoder_;
  r.theta_dot = velocity_estimate_;
  return r;
}

WorldSample SimWorld::state_at(double t) const {
  if (t <= history_.front().t) return history_.front();
  if (t >= history_.back().t) return history_.back();
  std::size_t i = static_cast<std::size_t>((t - history_.front().t) / dt_);
  i = std::min(i, history_.size() - 2);
  while (i > 0 && history_[i].t > t) --i;
  while (i + 2 < history_.size() && history_[i + 1].t <= t) ++i;
  const WorldSample& a = history_[i];
  const WorldSample& b = history_[i + 1];
  const double h = b.t - a.t;
  const double u = (t - a.t) / h;
  WorldSample w = a;
  w.t = t;
  w.theta = hermite(a.theta, a.theta_dot, b.theta, b.theta_dot, h, u);
  w.theta_dot = a.theta_dot + u * (b.theta_dot - a.theta_dot);
  w.s_h = hermite(a.s_h, a.sdot_h, b.s_h, b.sdot_h, h, u);
  w.sdot_h = a.sdot_h + u * (b.sdot_h - a.sdot_h);
  for (int k = 0; k < 2; ++k)
    w.disk_position[k] = hermite(a.disk_position[k], a.disk_velocity[k], b.disk_position[k],
                                 b.disk_velocity[k], h, u);
  w.disk_velocity = a.disk_velocity + u * (b.disk_velocity - a.disk_velocity);
  w.disk_angle = hermite(a.disk_angle, a.disk_rate, b.disk_angle, b.disk_rate, h, u);
  w.fn_ratio = a.fn_ratio + u * (b.fn_ratio - a.fn_ratio);
  w.ft_ratio = a.ft_ratio + u * (b.ft_ratio - a.ft_ratio);
  return w;
}

render::SceneState SimWorld::scene_state_at(double t) const {
  const WorldSample w = state_at(t);
  render::SceneState s;
  s.t = t;
  s.hand_angle = w.theta;
  s.disk_center = {w.disk_position.x(), w.disk_position.y()};
  s.disk_angle = w.disk_angle;
  s.s_h = w.s_h;
  s.force_normal_ratio = w.fn_ratio;
  s.force_tangential_ratio = w.ft_ratio;
  s.mode = w.mode;
  return s;
}

GoalCheck SimWorld::goal_check() const {
  GoalCheck out;
  out.mode = disk_.mode;
  const sim::HandKinematics h = [&] {
    sim::HandKinematics k;
    k.angle = theta_;
    return k;
  }();
  const sim::Curve& hand = *problem_->hand;
  const double r = *problem_->object.disk_radius;
  out.s_h = disk_.mode == sim::ContactMode::kFlight
                ? sim::disk_gap(*problem_, h, disk_.position).s_h
                : disk_.s_h;
  const Eigen::Matrix2d R = rotation(theta_);
  const auto height = [&](double s) {
    const sim::CurveGeometry g = hand.geometry(s, hand.piece_at(s, +1));
    return (R * (g.point + r * g.normal)).y();
  };
  // Walk downhill from the disk to the bottom of its well, then uphill both ways to the rims.
  constexpr double kStep = 1e-3, kPeriod = 4.0;
  double s = std::remainder(out.s_h - 1.0, kPeriod) + 1.0;  // into [-1, 3): the closed outline
  const double dir = height(s + kStep) < height(s - kStep) ? +kStep : -kStep;
  for (int i = 0; i < 4000 && height(s + dir) < height(s); ++i) s += dir;
  out.well_bottom = std::remainder(s - 1.0, kPeriod) + 1.0;
  double left = s, right = s;
  for (int i = 0; i < 4000 && height(left - kStep) >= height(left); ++i) left -= kStep;
  for (int i = 0; i < 4000 && height(right + kStep) >= height(right); ++i) right += kStep;
  out.rim_left = left;
  out.rim_right = right;
  // The disk's energy in the table plane.
  const double m = problem_->object.mass, g = problem_->gravity;
  const double energy =
      0.5 * m * disk_.velocity.squaredNorm() +
      0.5 * problem_->object.inertia * disk_.angular_velocity * disk_.angular_velocity +
      m * g * disk_.position.y();
  const double rim = std::min(height(left), height(right));
  out.energy_margin = m * g * rim - energy;
  // A well holds the disk only where the hand faces up at its bottom (elsewhere the lowest point
  // of the outline is where the disk falls off).
  const sim::CurveGeometry bottom = hand.geometry(s, hand.piece_at(s, +1));
  out.well_faces_up = (R * bottom.normal).y() > 0;
  out.trapped = disk_.mode != sim::ContactMode::kFlight && !failure_ && out.well_faces_up &&
                out.energy_margin > 0;
  const double theta_goal = problem_->motion->at(1e9).angle;
  if (failure_) {
    out.reason = failure_detail_;
  } else if (disk_.mode == sim::ContactMode::kFlight) {
    out.reason = "the disk is still in flight";
  } else if (!out.well_faces_up) {
    out.reason = "the disk at s_h = " + sim::format_significant(out.s_h, 6) +
                 " is rolling off the hand (the hand faces down where it is heading)";
  } else if (!(out.well_bottom > 0.5 && out.well_bottom < 1.5)) {
    out.reason = "disk at s_h = " + sim::format_significant(out.s_h, 6) +
                 " settles in the well whose bottom is at s_h = " +
                 sim::format_significant(out.well_bottom, 6) +
                 ", not the goal well (bottom near s_h = +1)";
  } else if (!(out.energy_margin > 0)) {
    out.reason = "disk can still leave the goal well (energy " +
                 sim::format_significant(-out.energy_margin, 6) + " J above its lower rim)";
  } else if (!(std::abs(theta_ - theta_goal) < 0.05)) {
    out.reason = "the hand is at " + sim::format_significant(theta_, 6) + " rad, not at its goal " +
                 sim::format_significant(theta_goal, 6) + " rad";
  } else {
    out.in_goal = true;
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

control::JointReading SimJoint::read(double t) {
  control::JointReading r = world_.read_encoder();
  r.t = t;
  if (faults_.encoder_glitch && !glitched_ && t >= *faults_.encoder_glitch) {
    r.theta += faults_.encoder_glitch_size;
    glitched_ = true;
  }
  return r;
}

// ---------------------------------------------------------------------------------------------

SyntheticCamera::SyntheticCamera(std::shared_ptr<const model::Model> model, const SimWorld& world,
                                 double t_start)
    : world_(world),
      camera_(model->spec.camera ? *model->spec.camera
                                 : throw std::invalid_argument(
                                       model->spec.origin +
                                       ": camera: a synthetic camera needs a camera section in "
                                       "the scene")),
      faults_(model->spec.faults),
      renderer_(model::render_setup(*model)),
      t_start_(t_start),
      capture_jitter_(model->spec.effects.jitter_s),
      latency_rng_(model->spec.effects.seed ^ 0x9e3779b97f4a7c15ULL) {}

std::optional<CameraFrame> SyntheticCamera::poll(double now) {
  // A frame is rendered once the world has been simulated past its exposure, allowing for the
  // capture-time jitter (4 sigma) and the last servo period; an interlaced or rolling readout
  // takes its last rows later than its time stamp (its first row's time).
  const double margin = 2.0 * world_.servo_period() + 4.0 * capture_jitter_;
  const double readout = renderer_.readout_duration();
  for (;;) {
    const double tn = t_start_ + static_cast<double>(next_) / camera_.fps;
    if (tn + readout + 0.5 * camera_.exposure + margin > now) break;
    if (faults_.camera_stop && tn >= *faults_.camera_stop) break;
    if (faults_.camera_stall && tn >= *faults_.camera_stall) {
      // A stalled camera keeps delivering its last image with its old stamp.
      if (last_) {
        CameraFrame again = *last_;
        again.t_arrival = std::max(tn + camera_.latency, last_arrival_);
        last_arrival_ = again.t_arrival;
        queue_.push_back(again);
      }
      ++next_;
      continue;
    }
    const auto state_at = [&](double t) {
      render::SceneState s = world_.scene_state_at(t);
      if (faults_.occlusion && t >= *faults_.occlusion &&
          t < *faults_.occlusion + faults_.occlusion_duration)
        s.disk_center = {1e3, 1e3};  // hidden: out of every view
      return s;
    };
    render::Frame f = renderer_.capture(state_at, tn);
    truths_.push_back(f.truth);
    const long index = next_++;
    if (f.truth.dropped) {
      ++dropped_;
      continue;
    }
    ++rendered_;
    std::uniform_real_distribution<double> spread(-camera_.latency_jitter, camera_.latency_jitter);
    const double latency =
        camera_.latency + (camera_.latency_jitter > 0 ? spread(latency_rng_) : 0);
    CameraFrame frame;
    frame.index = index;
    frame.t_capture = f.truth.t;
    // A camera delivers in order.
    frame.t_arrival = std::max(f.truth.t + latency, last_arrival_);
    last_arrival_ = frame.t_arrival;
    if (f.image.depth() != CV_8U)
      f.image.convertTo(frame.image, CV_8U);
    else
      frame.image = f.image;
    last_ = frame;
    queue_.push_back(frame);
  }
  if (!queue_.empty() && queue_.front().t_arrival <= now) {
    CameraFrame f = std::move(queue_.front());
    queue_.pop_front();
    return f;
  }
  return std::nullopt;
}

}  // namespace flatland::drivers
