// Plain data that flows through the closed loop (paper section 5): what the joint reads, what the
// camera pipeline measures, what the estimator believes and what the controller commands.
// Times are explicit (s, on the loop's clock); angles in rad; s_h is the hand's global contact
// parameter (pieces m cover [2m-1, 2m+1]; -1 palm well, 0 fingertip, +1 back well).
#pragma once

#include <Eigen/Core>

#include <string>

namespace flatland::control {

/// The joint as the loop sees it at one tick: the encoder's angle and the drive's velocity
/// estimate.
struct JointReading {
  double t = 0;
  double theta = 0;      ///< rad
  double theta_dot = 0;  ///< rad/s
};

/// The hand's kinematics the estimator propagates with over one tick: the angle and rate read at
/// the tick's start and an angular acceleration held over the tick (the loop's comes from the
/// joint's readings, or from the command where they give none: hand_input.hpp).
struct HandInput {
  double theta = 0, theta_dot = 0, theta_ddot = 0;
};

/// One vision measurement of the contact parameter.
struct Measurement {
  double t_capture = 0;  ///< s, when the image was exposed (mid-exposure)
  double t_arrival = 0;  ///< s, when it reached the loop (t_capture + latency)
  double s_h = 0;
  double sigma = 0;  ///< 1-sigma uncertainty of s_h
};

/// The estimator's belief at time t.
struct Estimate {
  double t = 0;
  double s_h = 0, sdot_h = 0;
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();  ///< of (s_h, sdot_h)
};

/// The controller's stages (section 5) and the safe stop.
enum class Stage {
  kWaiting,     ///< before t = 0: hand at rest
  kDip,         ///< stage 1: the plan's opening dip, open loop
  kServo,       ///< stage 2: servo to the plan indexed by the estimated s_h
  kFinish,      ///< stage 3: the plan's final overshoot, open loop
  kOpenLoop,    ///< open-loop playback of the whole plan (the baseline controller)
  kDone,        ///< the motion is over; hand held at rest
  kSafeStop,    ///< decelerating to rest after a fault
};
std::string to_string(Stage s);

/// What the controller asks of the joint for one tick.
struct Command {
  double t = 0;
  double theta_ddot = 0;  ///< rad/s^2, held over the tick
  Stage stage = Stage::kWaiting;
};

}  // namespace flatland::control
