// The contact estimator of the closed loop (paper section 5: "a simple estimator was used to
// estimate the disk's position between vision data frames"): an extended Kalman filter on
// (s_h, sdot_h). Between camera frames it propagates at the loop's rate (1 kHz) with the rolling
// model of a disk on the hand, driven by the hand's measured angle/rate and an acceleration held
// over each tick (the loop's: estimated from the joint's readings, hand_input.hpp); at each frame
// it corrects with the measured s_h. Frames arrive late (camera
// latency); with latency compensation the filter rewinds to the capture time through its stored
// history, corrects there and re-propagates to the present with the stored inputs.
//
// A constant-velocity model (sddot_h = 0) is the measured baseline.
#pragma once

#include "flatland/control/interfaces.hpp"
#include "flatland/control/rolling_filter.hpp"
#include "flatland/control/types.hpp"
#include "flatland/sim/rolling.hpp"

#include <Eigen/Core>

#include <memory>
#include <string>

namespace flatland::control {

/// The extended Kalman filter (type `ekf`): the mean by RK4 on the rolling model, the covariance
/// through the model's Jacobian at the mean. The history, update and errors are RollingFilter's
/// (rolling_filter.hpp).
class Ekf final : public RollingFilter {
 public:
  /// `model`: the nominal hand, disk and in-plane gravity (its motion is not used: the hand's
  /// kinematics come from HandInput). Throws std::invalid_argument if the object is not a disk
  /// or a config field is invalid (the message names the field, e.g. "estimator.history: ...").
  /// The belief starts at t = 0, (0, 0) with the initial covariance; call reset().
  Ekf(std::shared_ptr<const sim::RollingProblem> model, EstimatorConfig config);
  std::string name() const override { return "ekf"; }

 private:
  /// One RK4 step of the mean and one linearised covariance step over h (<= 2 ms).
  void substep(double t, double h, const HandInput& u, Eigen::Vector2d& x,
               Eigen::Matrix2d& P) const override;
};

/// Normalised estimation error squared of an estimate against the truth (chi-square, 2 dof when
/// the filter is consistent).
double nees(const Estimate& e, double s_h_true, double sdot_h_true);

}  // namespace flatland::control
