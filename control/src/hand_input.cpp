#include "flatland/control/hand_input.hpp"

#include <cmath>

namespace flatland::control {

const char* to_string(AccelerationSource source) {
  switch (source) {
    case AccelerationSource::kReadings:
      return "readings";
    case AccelerationSource::kCommand:
      return "command";
  }
  return "unknown";
}

HandInputChoice HandInputFromJoint::next(const JointReading& reading, double commanded) {
  HandInputChoice out;
  out.input = {reading.theta, reading.theta_dot, commanded};
  out.source = AccelerationSource::kCommand;
  if (previous_ && std::isfinite(reading.theta_dot) && std::isfinite(previous_->theta_dot)) {
    const double dt = reading.t - previous_->t;
    if (dt > 0 && std::isfinite(dt)) {
      out.input.theta_ddot = (reading.theta_dot - previous_->theta_dot) / dt;
      out.source = AccelerationSource::kReadings;
    }
  }
  previous_ = reading;
  return out;
}

}  // namespace flatland::control
