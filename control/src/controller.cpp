#include "flatland/control/controller.hpp"
#include "flatland/sim/format.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace flatland::control {
namespace {

/// Linear interpolation in a table with increasing x.
double interpolate(const std::vector<double>& x, const std::vector<double>& y, double at) {
  if (at <= x.front()) return y.front();
  if (at >= x.back()) return y.back();
  const auto it = std::upper_bound(x.begin(), x.end(), at);
  const std::size_t i = static_cast<std::size_t>(it - x.begin());
  const double w = (at - x[i - 1]) / (x[i] - x[i - 1]);
  return y[i - 1] + w * (y[i] - y[i - 1]);
}

}  // namespace

Plan::Plan(std::shared_ptr<const sim::HandMotion> motion, double duration,
           const sim::RunResult& run, double s_from, double s_to)
    : motion_(std::move(motion)), duration_(duration) {
  if (!motion_) throw std::invalid_argument("plan: no motion");
  if (!(duration > 0)) throw std::invalid_argument("plan: duration must be positive");
  if (run.trajectory.empty()) throw std::invalid_argument("plan: the nominal run was not recorded");
  if (!(s_from < s_to)) throw std::invalid_argument("plan: s_from must be below s_to");
  // s_h(t) at 1 ms (or finer) over the plan: the stage-2 lookup interpolates linearly in it,
  // with an error far below the tracker's (s_h moves ~1e-3 per ms at the fastest).
  const int n = std::max(2000, static_cast<int>(std::ceil(duration / 5e-4)));
  const double t_last = std::min(duration, run.trajectory.t_end());
  plan_t_.reserve(n + 1);
  plan_s_.reserve(n + 1);
  for (int i = 0; i <= n; ++i) {
    const double t = t_last * i / n;
    plan_t_.push_back(t);
    plan_s_.push_back(run.trajectory.s_h(t));
  }
  plan_sdot_.resize(plan_s_.size());
  for (std::size_t i = 0; i < plan_s_.size(); ++i) {
    const std::size_t a = i == 0 ? 0 : i - 1, b = std::min(i + 1, plan_s_.size() - 1);
    plan_sdot_[i] = (plan_s_[b] - plan_s_[a]) / (plan_t_[b] - plan_t_[a]);
  }
  // The stretch from the first crossing of s_from to the first crossing of s_to.
  std::size_t i0 = 0;
  while (i0 < plan_s_.size() && plan_s_[i0] < s_from) ++i0;
  if (i0 == 0 || i0 == plan_s_.size())
    throw std::invalid_argument("plan: the planned s_h never rises through " +
                                sim::format_significant(s_from, 4) + " (it starts at " +
                                sim::format_significant(plan_s_.front(), 4) + ")");
  std::size_t i1 = i0;
  while (i1 < plan_s_.size() && plan_s_[i1] < s_to) ++i1;
  if (i1 == plan_s_.size())
    throw std::invalid_argument("plan: the planned s_h never reaches " +
                                sim::format_significant(s_to, 4) + " (it ends at " +
                                sim::format_significant(plan_s_.back(), 4) + ")");
  const auto crossing = [&](std::size_t i, double s) {
    const double w = (s - plan_s_[i - 1]) / (plan_s_[i] - plan_s_[i - 1]);
    return plan_t_[i - 1] + w * (plan_t_[i] - plan_t_[i - 1]);
  };
  s_.push_back(s_from);
  t_.push_back(crossing(i0, s_from));
  for (std::size_t i = i0; i < i1; ++i) {
    if (!(plan_s_[i] > s_.back()))
      throw std::invalid_argument("plan: the planned s_h is not monotonic between " +
                                  sim::format_significant(s_from, 4) + " and " +
                                  sim::format_significant(s_to, 4) +
                                  " (at t = " + sim::format_significant(plan_t_[i], 4) +
                                  " s); stage 2 cannot index the plan by s_h");
    s_.push_back(plan_s_[i]);
    t_.push_back(plan_t_[i]);
  }
  s_.push_back(s_to);
  t_.push_back(crossing(i1, s_to));
}

double Plan::time_at(double s_h) const { return interpolate(s_, t_, s_h); }
double Plan::s_h_at(double t) const { return interpolate(plan_t_, plan_s_, t); }
double Plan::sdot_h_at(double t) const { return interpolate(plan_t_, plan_sdot_, t); }

std::string to_string(ServoLaw law) { return law == ServoLaw::kPaper ? "paper" : "time-scaled"; }

ServoLaw parse_servo_law(const std::string& name) {
  if (name == "paper") return ServoLaw::kPaper;
  if (name == "time-scaled") return ServoLaw::kTimeScaled;
  throw std::invalid_argument("controller.law: unknown value '" + name +
                              "' (allowed: paper, time-scaled)");
}

// ---------------------------------------------------------------------------------------------

PaperController::PaperController(PaperConfig config) : config_(config) {}

void PaperController::start(const ControllerContext& context) {
  if (!context.plan) throw std::invalid_argument("controller: no plan");
  if (!(context.dt > 0)) throw std::invalid_argument("controller: dt must be positive");
  plan_ = context.plan;
  dt_ = context.dt;
  stage_ = Stage::kWaiting;
  t_end_.reset();
}

double PaperController::plan_acceleration(double tau) const {
  // The joint integrates the held command over the tick; the mid-tick value makes that
  // integration second-order accurate, so open-loop playback ends on the plan's final angle.
  return plan_->hand(tau + 0.5 * dt_).angular_acceleration;
}

const char* to_string(StopCause cause) {
  switch (cause) {
    case StopCause::kJoint:
      return "joint";
    case StopCause::kEstimator:
      return "estimator";
    case StopCause::kCamera:
      return "camera";
    case StopCause::kTracking:
      return "tracking";
    case StopCause::kDisk:
      return "disk";
    case StopCause::kTimeout:
      return "timeout";
    case StopCause::kController:
      return "controller";
  }
  return "unknown";
}

double safe_stop_command(double theta_dot, double deceleration, double dt) {
  const double a = std::min(deceleration, std::abs(theta_dot) / dt);
  return theta_dot > 0 ? -a : a;
}

ControlOutput PaperController::step(const ControlInput& input) {
  if (!plan_) throw std::logic_error("PaperController::step before start");
  ControlOutput c;
  const double t = input.t;
  const JointReading& joint = input.joint;
  const Estimate& estimate = input.estimate;
  const double dt = dt_;
  const double T = plan_->duration();

  if (stage_ == Stage::kWaiting && t >= 0)
    stage_ = config_.feedback ? Stage::kDip : Stage::kOpenLoop;

  switch (stage_) {
    case Stage::kWaiting:
      c.theta_ddot = 0;
      break;
    case Stage::kOpenLoop:
      if (t >= T) {
        stage_ = Stage::kDone;
        t_end_ = T;
        break;
      }
      c.theta_ddot = plan_acceleration(t);
      break;
    case Stage::kDip:
      if (estimate.s_h > config_.dip_until) {
        stage_ = Stage::kServo;
      } else {
        c.theta_ddot = plan_acceleration(t);
        break;
      }
      [[fallthrough]];
    case Stage::kServo: {
      if (estimate.s_h > config_.finish_after) {
        stage_ = Stage::kFinish;
        t3_ = t;
        tau3_ = plan_->time_at(config_.finish_after);
        const double tr = T - tau3_;
        const sim::HandKinematics p = plan_->hand(tau3_);
        const double d_theta = joint.theta - p.angle;
        const double d_rate = joint.theta_dot - p.angular_velocity;
        if (tr > dt) {
          c3_ = (2.0 * d_theta + d_rate * tr) / (tr * tr * tr);
          c2_ = -(d_rate + 3.0 * c3_ * tr * tr) / (2.0 * tr);
        } else {
          c2_ = c3_ = 0;
        }
      } else {
        const double tp = plan_->time_at(estimate.s_h);
        const sim::HandKinematics p = plan_->hand(tp);
        if (config_.law == ServoLaw::kPaper) {
          c.theta_ddot = config_.kp * (p.angle - joint.theta) +
                         config_.kd * (p.angular_velocity - joint.theta_dot);
        } else {
          // The disk's pace against the plan's at the same s_h; bounded so that a noisy rate
          // estimate cannot reverse or race the hand.
          const double rate = std::clamp(estimate.sdot_h / plan_->sdot_h_at(tp), 0.5, 2.0);
          c.theta_ddot = rate * rate * p.angular_acceleration +
                         config_.kp * (p.angle - joint.theta) +
                         config_.kd * (rate * p.angular_velocity - joint.theta_dot);
        }
        break;
      }
    }
      [[fallthrough]];
    case Stage::kFinish: {
      const double elapsed = t - t3_;
      if (tau3_ + elapsed >= T) {
        stage_ = Stage::kDone;
        t_end_ = t3_ + (T - tau3_);
        break;
      }
      const double s = elapsed + 0.5 * dt;
      c.theta_ddot = plan_acceleration(tau3_ + elapsed) + 2.0 * c2_ + 6.0 * c3_ * s;
      break;
    }
    case Stage::kDone:
    case Stage::kSafeStop:
      break;
  }
  if (stage_ == Stage::kDone) {
    // Hold the plan's final angle (the joint's reference would otherwise keep any rate left over
    // from rounding).
    const double hold = plan_->hand(T).angle;
    c.theta_ddot = config_.kp * (hold - joint.theta) - config_.kd * joint.theta_dot;
    c.done = true;
    c.t_done = t_end_;
  }
  c.mode = to_string(stage_);
  c.theta_reference = stage_ == Stage::kServo ? plan_->hand(plan_->time_at(estimate.s_h)).angle
                                              : plan_->hand(std::max(t, 0.0)).angle;
  return c;
}

// ---------------------------------------------------------------------------------------------

SafetyMonitor::SafetyMonitor(SafetyConfig config, double t_start)
    : config_(config),
      t_last_measurement_(t_start),
      t_last_frame_(t_start),
      t_last_fresh_(t_start) {}

std::optional<StopReason> SafetyMonitor::check_joint(const JointReading& joint) {
  if (!std::isfinite(joint.theta) || !std::isfinite(joint.theta_dot))
    return StopReason{StopCause::kJoint, "joint: non-finite reading at t = " +
                                             sim::format_significant(joint.t, 4) + " s"};
  if (last_joint_) {
    const double predicted =
        last_joint_->theta + last_joint_->theta_dot * (joint.t - last_joint_->t);
    const double jump = joint.theta - predicted;
    if (std::abs(jump) > config_.max_joint_jump)
      return StopReason{StopCause::kJoint,
                        "joint: encoder glitch at t = " + sim::format_significant(joint.t, 4) +
                            " s (reading " + sim::format_significant(joint.theta, 4) + " rad, " +
                            sim::format_significant(jump, 4) + " rad from the prediction; limit " +
                            sim::format_significant(config_.max_joint_jump, 4) + ")"};
  }
  last_joint_ = joint;
  return std::nullopt;
}

void SafetyMonitor::frame(double t, bool fresh, bool tracked) {
  any_frame_ = true;
  t_last_frame_ = t;
  if (fresh) t_last_fresh_ = t;
  if (fresh && tracked) t_last_measurement_ = t;
}

std::optional<StopReason> SafetyMonitor::innovation(double nis) {
  if (nis > config_.innovation_gate) {
    if (++strikes_ >= config_.innovation_strikes)
      return StopReason{StopCause::kEstimator,
                        "estimator: " + std::to_string(strikes_) +
                            " implausible innovations in a row (NIS " +
                            sim::format_significant(nis, 4) + " > " +
                            sim::format_significant(config_.innovation_gate, 4) + ")"};
  } else {
    strikes_ = 0;
  }
  return std::nullopt;
}

std::optional<StopReason> SafetyMonitor::check_time(double t) const {
  const double since = t - t_last_measurement_;
  if (since <= config_.lost_timeout) return std::nullopt;
  if (!any_frame_ || t - t_last_frame_ > config_.lost_timeout)
    return StopReason{StopCause::kCamera,
                      "camera: no frames for " + sim::format_significant(t - t_last_frame_, 3) +
                          " s (at t = " + sim::format_significant(t, 4) + " s)"};
  if (t - t_last_fresh_ > config_.lost_timeout)
    return StopReason{StopCause::kCamera, "camera: stalled, no new image for " +
                                              sim::format_significant(t - t_last_fresh_, 3) +
                                              " s (at t = " + sim::format_significant(t, 4) +
                                              " s)"};
  return StopReason{StopCause::kTracking,
                    "tracking: disk lost for " + sim::format_significant(since, 3) +
                        " s (at t = " + sim::format_significant(t, 4) + " s)"};
}

}  // namespace flatland::control
