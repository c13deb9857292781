// What the closed loop sees of the world: a Clock, a Camera and a Joint. The estimator and the
// controller run unchanged whichever implementation is behind them: synthetic (the simulator and
// renderer), recorded (a video or image sequence with timestamps, a joint log) or live (a V4L2
// camera, the wall clock).
#pragma once

#include "flatland/control/types.hpp"
#include "flatland/vision/video_reader.hpp"

#include <opencv2/core.hpp>

#include <limits>
#include <optional>
#include <string>

namespace flatland::drivers {

/// Time for the loop: simulated (advancing the simulated world) or the steady wall clock.
class Clock {
 public:
  virtual ~Clock() = default;
  virtual double now() const = 0;
  /// Block until time t (s); a simulated clock advances its world to t.
  virtual void sleep_until(double t) = 0;
};

/// One camera frame as delivered to the loop.
struct CameraFrame {
  long index = 0;        ///< frame number since the camera started (gaps = dropped frames)
  double t_capture = 0;  ///< s, mid-exposure, on the loop's clock
  double t_arrival = 0;  ///< s, when the frame became available to the loop
  cv::Mat image;         ///< CV_8UC3 (BGR) or CV_8UC1; empty when unreadable
  /// What the frame can be trusted for: only an intact frame is measured. A recorded video's
  /// reader flags repeated, damaged and unreadable frames (vision::VideoReader); they keep their
  /// place in the loop's frame log, with no measurement.
  vision::FrameIntegrity integrity = vision::FrameIntegrity::kIntact;
};

class Camera {
 public:
  virtual ~Camera() = default;
  /// The next frame that has arrived by time `now`, oldest first; nullopt if none is waiting.
  virtual std::optional<CameraFrame> poll(double now) = 0;
  /// Short description for logs and JSON ("synthetic", "video:run/frames", "v4l2:0").
  virtual std::string describe() const = 0;
};

/// The hand's joint: read angle and velocity, command acceleration (held until the next command).
class Joint {
 public:
  virtual ~Joint() = default;
  virtual control::JointReading read(double t) = 0;
  virtual void command(double t, double theta_ddot) = 0;
  virtual std::string describe() const = 0;
  /// A replayed joint: the acceleration the recorded run commanded at the tick last read (the
  /// joint moved as that command made it move, whatever the loop commands now). NaN for a joint
  /// that obeys the loop's commands.
  virtual double recorded_command() const { return std::numeric_limits<double>::quiet_NaN(); }
};

}  // namespace flatland::drivers
