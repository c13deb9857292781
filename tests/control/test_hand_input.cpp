// The estimator's hand input from the joint's readings (control/hand_input.hpp): the acceleration
// is the read rate's change over the last tick, the command only where the readings give none.
// Expectations are closed forms of the readings' own motion.
#include "flatland/control/hand_input.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

using namespace flatland;
using control::AccelerationSource;
using control::HandInputFromJoint;
using control::JointReading;

namespace {

// A hand whose acceleration ramps (constant jerk j): theta = j t^3 / 6, theta_dot = j t^2 / 2.
constexpr double kJerk = 7.5;
JointReading ramp(double t) { return {t, kJerk * t * t * t / 6.0, kJerk * t * t / 2.0}; }

}  // namespace

TEST(HandInputFromJoint, NamesItsSources) {
  EXPECT_EQ(std::string(control::to_string(AccelerationSource::kReadings)), "readings");
  EXPECT_EQ(std::string(control::to_string(AccelerationSource::kCommand)), "command");
}

// The first reading has nothing before it: the command is all there is. Every later one gives
// the mean acceleration over the interval since the previous reading, which for a constant jerk
// is j (t_k + t_{k-1}) / 2, exactly; angle and rate pass through as read. Uneven intervals (a
// late tick) change nothing.
TEST(HandInputFromJoint, AccelerationIsTheMeanOverTheLastInterval) {
  HandInputFromJoint hand;
  const double times[] = {0.1, 0.101, 0.102, 0.1045, 0.105, 0.2};
  const auto first = hand.next(ramp(times[0]), -3.0);
  EXPECT_EQ(first.source, AccelerationSource::kCommand);
  EXPECT_EQ(first.input.theta_ddot, -3.0);
  EXPECT_EQ(first.input.theta, ramp(times[0]).theta);
  EXPECT_EQ(first.input.theta_dot, ramp(times[0]).theta_dot);
  for (int k = 1; k < 6; ++k) {
    const JointReading r = ramp(times[k]);
    const auto c = hand.next(r, 1e6);  // a command far from the motion: it must not leak in
    EXPECT_EQ(c.source, AccelerationSource::kReadings);
    EXPECT_EQ(c.input.theta, r.theta);
    EXPECT_EQ(c.input.theta_dot, r.theta_dot);
    const double mean = kJerk * (times[k] + times[k - 1]) / 2.0;
    EXPECT_NEAR(c.input.theta_ddot, mean, 1e-11 * std::abs(mean) + 1e-12) << "reading " << k;
  }
}

// Where the readings cannot give an acceleration the command stands in, and the reading is still
// remembered so that the next usable pair counts again.
TEST(HandInputFromJoint, FallsBackToTheCommandWithoutAUsablePair) {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  HandInputFromJoint hand;
  hand.next({0.0, 0.0, 1.0}, 0.0);
  EXPECT_EQ(hand.next({0.001, 0.0, 1.5}, 9.0).input.theta_ddot, 500.0);  // 0.5 rad/s in 1 ms
  // A non-finite rate: now, and as the previous reading of the next tick.
  auto c = hand.next({0.002, 0.0, nan}, 9.0);
  EXPECT_EQ(c.source, AccelerationSource::kCommand);
  EXPECT_EQ(c.input.theta_ddot, 9.0);
  c = hand.next({0.003, 0.0, 2.0}, 8.0);
  EXPECT_EQ(c.source, AccelerationSource::kCommand);
  EXPECT_EQ(c.input.theta_ddot, 8.0);
  c = hand.next({0.004, 0.0, 2.002}, 8.0);
  EXPECT_EQ(c.source, AccelerationSource::kReadings);
  EXPECT_NEAR(c.input.theta_ddot, 2.0, 1e-9);
  // A reading at the same time as the previous one, or earlier: no interval to divide by.
  c = hand.next({0.004, 0.0, 3.0}, 7.0);
  EXPECT_EQ(c.source, AccelerationSource::kCommand);
  EXPECT_EQ(c.input.theta_ddot, 7.0);
  c = hand.next({0.0035, 0.0, 3.0}, 6.0);
  EXPECT_EQ(c.source, AccelerationSource::kCommand);
  // reset() forgets the previous reading.
  hand.next({0.005, 0.0, 3.0}, 0.0);
  hand.reset();
  c = hand.next({0.006, 0.0, 4.0}, 5.0);
  EXPECT_EQ(c.source, AccelerationSource::kCommand);
  EXPECT_EQ(c.input.theta_ddot, 5.0);
}
