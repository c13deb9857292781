// The hand input the estimator propagates with: what the joint did, not what was asked of it.
// The angle and rate are the joint's readings; the angular acceleration over the coming tick is
// the change of the read rate over the tick just ended (a causal first difference), and the
// command only where the readings cannot give one (the first tick, a non-finite rate, readings
// not later than the previous one). A recorded joint replayed against changed code therefore
// drives the estimator exactly as in the recorded run, and a live joint that lags its command is
// followed as it moves. docs/ESTIMATOR.md derives the estimate's delay, noise and what it costs
// in process noise.
#pragma once

#include "flatland/control/types.hpp"

#include <optional>

namespace flatland::control {

/// Where the acceleration of a tick's hand input came from.
enum class AccelerationSource {
  kReadings,  ///< the first difference of the joint's rate readings
  kCommand,   ///< the commanded acceleration (no usable previous reading)
};
/// "readings", "command".
const char* to_string(AccelerationSource source);

/// A tick's hand input and where its acceleration came from.
struct HandInputChoice {
  HandInput input;
  AccelerationSource source = AccelerationSource::kCommand;
};

/// Turns each tick's joint reading into the estimator's hand input (see the file comment).
class HandInputFromJoint {
 public:
  /// The input for the tick that starts at reading.t: theta and theta_dot as read, and
  ///   theta_ddot = (reading.theta_dot - previous.theta_dot) / (reading.t - previous.t)
  /// when the previous call's reading exists, both rates are finite and reading.t is later;
  /// `commanded` otherwise. Remembers the reading for the next call.
  HandInputChoice next(const JointReading& reading, double commanded);
  /// Forget the previous reading: the next call falls back to the command.
  void reset() { previous_.reset(); }

 private:
  std::optional<JointReading> previous_;
};

}  // namespace flatland::control
