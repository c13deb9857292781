#include "flatland/drivers/synthetic.hpp"

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

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(6);
  s << v;
  return s.str();
}

/// Cubic Hermite interpolation of a value with its derivative over [0, h] at fraction u.
double hermite(double y0, double d0, double y1, double d1, double h, double u) {
  const double u2 = u * u, u3 = u2 * u;
  return (2 * u3 - 3 * u2 + 1) * y0 + (u3 - 2 * u2 + u) * h * d0 + (-2 * u3 + 3 * u2) * y1 +
         (u3 - u2) * h * d1;
}

}  // namespace

SimWorld::SimWorld(const Scene& truth, double t_start)
    : scene_(truth), dt_(1.0 / truth.joint.rate), t_start_(t_start), t_(t_start) {
  if (truth.sim.object.kind != sim::ObjectSpec::Kind::kDisk)
    throw std::invalid_argument(truth.origin +
                                ": object: the closed loop rolls a disk (object.type: disk)");
  const auto base = sim::build_problem(truth.sim);
  // The reaction torque is evaluated with explicit kinematics; the motion here is never used.
  auto fixed = std::make_shared<sim::RollingProblem>(*base);
  fixed->motion = std::make_shared<sim::FixedHand>(0.0);
  problem_ = fixed;
  rolling_ = std::make_unique<sim::ReducedDiskRolling>(problem_);

  step_options_ = sim::run_options(truth.sim);
  step_options_.formulation = sim::Formulation::kReduced;
  step_options_.record = false;
  step_options_.events.s_h_bounds = std::make_pair(-3.0, 3.0);

  const sim::HandKinematics h0 = base->motion->at(0.0);
  theta_ = h0.angle;
  theta_ref_ = theta_;
  const sim::InitialContact& init = truth.sim.initial;
  s_h_ = init.s_h;
  sdot_h_ = init.sdot_h;
  const auto y0 = rolling_->initial_state(init);
  disk_angle_ = y0[1];
  const double q = 2.0 * M_PI / static_cast<double>(truth.joint.encoder_counts);
  encoder_ = std::round(theta_ / q) * q;
  history_.reserve(8192);
  history_.push_back(sample_now(0.0, 0.0));
}

double SimWorld::reaction_torque(const WorldSample& w, double alpha) const {
  sim::HandKinematics h;
  h.angle = w.theta;
  h.angular_velocity = w.theta_dot;
  h.angular_acceleration = alpha;
  const int piece = problem_->hand->piece_at(w.s_h, w.sdot_h >= 0 ? +1 : -1);
  sim::ReducedDiskRolling::State y;
  y << w.s_h, w.disk_angle, w.sdot_h;
  const sim::Sample s = rolling_->sample_with(h, w.t, y, piece);
  const sim::CurveGeometry g = problem_->hand->geometry(w.s_h, piece);
  const Eigen::Matrix2d R = rotation(w.theta);
  const sim::Vec2 force_on_disk =
      s.force_normal * (R * g.normal) + s.force_tangential * (R * g.tangent);
  const sim::Vec2 contact = R * g.point;  // from the pivot
  // The disk pushes back on the hand with -force_on_disk at the contact point.
  return -(contact.x() * force_on_disk.y() - contact.y() * force_on_disk.x());
}

WorldSample SimWorld::sample_now(double alpha, double torque) const {
  WorldSample w;
  w.t = t_;
  w.theta = theta_;
  w.theta_dot = theta_dot_;
  w.theta_ddot = alpha;
  w.s_h = s_h_;
  w.sdot_h = sdot_h_;
  w.disk_angle = disk_angle_;
  w.theta_ref = theta_ref_;
  w.torque = torque;
  if (failure_) return w;  // the disk has left the hand: no contact forces
  sim::HandKinematics h;
  h.angle = theta_;
  h.angular_velocity = theta_dot_;
  h.angular_acceleration = alpha;
  const int piece = problem_->hand->piece_at(s_h_, sdot_h_ >= 0 ? +1 : -1);
  sim::ReducedDiskRolling::State y;
  y << s_h_, disk_angle_, sdot_h_;
  const sim::Sample s = rolling_->sample_with(h, t_, y, piece);
  w.fn_ratio = s.fn_ratio;
  w.ft_ratio = s.ft_ratio;
  w.mu_required = s.mu_required;
  w.disk_rate = s.object_angular_velocity;
  return w;
}

void SimWorld::step_disk(double alpha) {
  // The disk over this period, by the exact rolling dynamics under the held acceleration.
  auto problem = std::make_shared<sim::RollingProblem>(*problem_);
  problem->motion = std::make_shared<sim::HeldAcceleration>(t_, theta_, theta_dot_, alpha);
  sim::InitialContact init;
  init.t0 = t_;
  init.s_h = s_h_;
  init.sdot_h = sdot_h_;
  init.object_angle = disk_angle_;
  sim::RunOptions opt = step_options_;
  opt.t_end = t_ + dt_;
  const sim::RunResult r = sim::simulate(problem, init, opt);
  s_h_ = r.final.s_h;
  sdot_h_ = r.final.sdot_h;
  disk_angle_ = r.final.object_angle;
  if (r.reason != sim::StopReason::kEndTime) {
    failure_ = (r.reason == sim::StopReason::kContactLost ? "contact lost"
                : r.reason == sim::StopReason::kSlip      ? "slip (at mu = " +
                                                           fmt(problem_->contact.mu_static()) + ")"
                                                     : "disk rolled off the hand") +
               std::string(" at t = ") + fmt(r.final.t) + " s, s_h = " + fmt(r.final.s_h);
    failure_time_ = r.final.t;
    fn_min_ = std::min(fn_min_, r.final.fn_ratio);
  }
}

void SimWorld::servo_step() {
  const JointSpec& j = scene_.joint;
  const WorldSample& now = history_.back();

  // The drive: feedforward of the commanded acceleration on the nominal inertia, PD on the
  // reference, saturated.
  const double tau_cmd = j.inertia * command_ + j.kp * (theta_ref_ - encoder_) +
                         j.kd * (theta_dot_ref_ - velocity_estimate_);
  const double tau = std::clamp(tau_cmd, -j.torque_limit, j.torque_limit);
  // The disk's reaction is affine in the hand's acceleration: tau_disk = r0 + r1 alpha. Once
  // the disk has left the hand (a failure), the joint moves alone.
  const double r0 = failure_ ? 0.0 : reaction_torque(now, 0.0);
  const double r1 = failure_ ? 0.0 : reaction_torque(now, 1.0) - r0;
  const double drive = tau - j.viscous * theta_dot_ + r0;
  double alpha = 0;
  bool stop_at_end = false;
  if (theta_dot_ == 0.0 && std::abs(drive) <= j.coulomb) {
    alpha = 0;  // stiction holds
  } else {
    const double direction = theta_dot_ != 0.0 ? (theta_dot_ > 0 ? 1.0 : -1.0)
                                               : (drive > 0 ? 1.0 : -1.0);
    alpha = (drive - j.coulomb * direction) / (j.inertia - r1);
    const double next_rate = theta_dot_ + alpha * dt_;
    if (theta_dot_ != 0.0 && next_rate * theta_dot_ < 0 && std::abs(drive) <= j.coulomb) {
      // Dry friction brings the joint to rest within this period rather than reversing it.
      alpha = -theta_dot_ / dt_;
      stop_at_end = true;
    }
  }
  if (!failure_) {
    // The forces just after this tick (the acceleration jumps at ticks, and the force with it).
    const WorldSample start = sample_now(alpha, tau);
    fn_min_ = std::min(fn_min_, start.fn_ratio);
    if (std::isfinite(start.mu_required)) mu_max_ = std::max(mu_max_, start.mu_required);
    step_disk(alpha);
  }

  theta_ += dt_ * (theta_dot_ + 0.5 * dt_ * alpha);
  theta_dot_ = stop_at_end ? 0.0 : theta_dot_ + alpha * dt_;
  theta_ref_ += dt_ * (theta_dot_ref_ + 0.5 * dt_ * command_);
  theta_dot_ref_ += dt_ * command_;
  t_ = t_start_ + static_cast<double>(++tick_) * dt_;

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
  w.disk_angle = hermite(a.disk_angle, a.disk_rate, b.disk_angle, b.disk_rate, h, u);
  w.fn_ratio = a.fn_ratio + u * (b.fn_ratio - a.fn_ratio);
  w.ft_ratio = a.ft_ratio + u * (b.ft_ratio - a.ft_ratio);
  return w;
}

render::SceneState SimWorld::scene_state_at(double t) const {
  const WorldSample w = state_at(t);
  const sim::CurveGeometry g =
      problem_->hand->geometry(w.s_h, problem_->hand->piece_at(w.s_h, +1));
  const double r = *problem_->object.disk_radius;
  const sim::Vec2 c = rotation(w.theta) * (g.point + r * g.normal);
  render::SceneState s;
  s.t = t;
  s.hand_angle = w.theta;
  s.disk_center = {c.x(), c.y()};
  // After the disk left the hand its free flight is not simulated: it is drawn off the table.
  if (failure_ && t > failure_time_) s.disk_center = {1e3, 1e3};
  s.disk_angle = w.disk_angle;
  s.s_h = w.s_h;
  s.force_normal_ratio = w.fn_ratio;
  s.force_tangential_ratio = w.ft_ratio;
  return s;
}

GoalCheck SimWorld::goal_check() const {
  GoalCheck out;
  out.s_h = s_h_;
  const sim::Curve& hand = *problem_->hand;
  const double r = *problem_->object.disk_radius;
  const Eigen::Matrix2d R = rotation(theta_);
  const auto height = [&](double s) {
    const sim::CurveGeometry g = hand.geometry(s, hand.piece_at(s, +1));
    return (R * (g.point + r * g.normal)).y();
  };
  // Walk downhill from the disk to the bottom of its well, then uphill both ways to the rims.
  constexpr double kStep = 1e-3, kLimit = 2.95;
  double s = std::clamp(s_h_, -kLimit, kLimit);
  const double dir = height(s + kStep) < height(s - kStep) ? +kStep : -kStep;
  while (std::abs(s + dir) < kLimit && height(s + dir) < height(s)) s += dir;
  out.well_bottom = s;
  double left = s, right = s;
  while (left - kStep > -kLimit && height(left - kStep) >= height(left)) left -= kStep;
  while (right + kStep < kLimit && height(right + kStep) >= height(right)) right += kStep;
  out.rim_left = left;
  out.rim_right = right;
  // The disk's energy with the hand at rest where it is now (kinetic from the exact sample).
  sim::HandKinematics h;
  h.angle = theta_;
  h.angular_velocity = theta_dot_;
  sim::ReducedDiskRolling::State y;
  y << s_h_, disk_angle_, sdot_h_;
  const sim::Sample smp =
      rolling_->sample_with(h, t_, y, hand.piece_at(s_h_, sdot_h_ >= 0 ? +1 : -1));
  const double m = problem_->object.mass, g = problem_->gravity;
  const double energy = 0.5 * m * smp.object_velocity.squaredNorm() +
                        0.5 * problem_->object.inertia * smp.object_angular_velocity *
                            smp.object_angular_velocity +
                        m * g * smp.object_position.y();
  const double rim = std::min(height(left), height(right));
  out.energy_margin = m * g * rim - energy;
  if (failure_) {
    out.reason = *failure_;
  } else if (!(out.well_bottom > 0.5 && out.well_bottom < 1.5)) {
    out.reason = "disk at s_h = " + fmt(s_h_) + " settles in the well whose bottom is at s_h = " +
                 fmt(out.well_bottom) + ", not the goal well (bottom near s_h = +1)";
  } else if (!(out.energy_margin > 0)) {
    out.reason = "disk can still leave the goal well (energy " + fmt(-out.energy_margin) +
                 " J above its lower rim)";
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

SyntheticCamera::SyntheticCamera(const Scene& scene, const SimWorld& world, double t_start)
    : world_(world),
      camera_(scene.camera ? *scene.camera
                           : throw std::invalid_argument(
                                 scene.origin + ": camera: a synthetic camera needs a camera "
                                                "section in the scene")),
      faults_(scene.faults),
      renderer_(scene),
      t_start_(t_start),
      capture_jitter_(scene.effects.jitter_s),
      latency_rng_(scene.effects.seed ^ 0x9e3779b97f4a7c15ULL) {}

std::optional<CameraFrame> SyntheticCamera::poll(double now) {
  // A frame is rendered once the world has been simulated past its exposure, allowing for the
  // capture-time jitter (4 sigma) and the last servo period.
  const double margin = 2.0 * world_.servo_period() + 4.0 * capture_jitter_;
  for (;;) {
    const double tn = t_start_ + static_cast<double>(next_) / camera_.fps;
    if (tn + 0.5 * camera_.exposure + margin > now) break;
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
    const double latency = camera_.latency + (camera_.latency_jitter > 0 ? spread(latency_rng_) : 0);
    CameraFrame frame;
    frame.index = index;
    frame.t_capture = f.truth.t;
    // A camera delivers in order.
    frame.t_arrival = std::max(f.truth.t + latency, last_arrival_);
    last_arrival_ = frame.t_arrival;
    if (f.image.depth() != CV_8U) f.image.convertTo(frame.image, CV_8U);
    else frame.image = f.image;
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
