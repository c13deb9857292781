// Live drivers: the steady wall clock and a V4L2 camera, plus open_camera(), which turns a
// --camera specification into a Camera (recorded or live).
#pragma once

#include "flatland/drivers/interfaces.hpp"

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

namespace flatland::drivers {

/// The loop's time on std::chrono::steady_clock: seconds since `start` (construction by default).
/// A LiveCamera given the same start stamps its frames on this clock.
class SteadyClock : public Clock {
 public:
  SteadyClock() : SteadyClock(std::chrono::steady_clock::now()) {}
  explicit SteadyClock(std::chrono::steady_clock::time_point start) : start_(start) {}

  double now() const override;
  /// std::this_thread::sleep_until; returns at once for a time already past. A non-finite t is
  /// std::invalid_argument (there is no "forever" on this clock).
  void sleep_until(double t) override;
  std::chrono::steady_clock::time_point start() const { return start_; }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// A V4L2 camera (cv::VideoCapture with cv::CAP_V4L2). A background thread grabs frames into a
/// small queue; when the loop falls behind the oldest frame is dropped (the index then has a gap).
/// t_arrival is when the grab returned; t_capture is the driver's buffer time stamp when it is on
/// the same (monotonic) clock and plausible, else t_arrival. Both are seconds since `start`.
class LiveCamera : public Camera {
 public:
  /// std::invalid_argument "camera v4l2:N: no such device (/dev/videoN does not exist)" or
  /// "camera v4l2:N: cannot open /dev/videoN ..." (bad input for the CLI: exit 2).
  LiveCamera(int device, std::chrono::steady_clock::time_point start,
             std::size_t queue_capacity = 4);
  LiveCamera(const LiveCamera&) = delete;
  LiveCamera& operator=(const LiveCamera&) = delete;
  ~LiveCamera() override;

  /// The oldest queued frame with t_arrival <= now. Once the device has stopped delivering
  /// (unplugged, driver error) and the queue is empty: std::runtime_error.
  std::optional<CameraFrame> poll(double now) override;
  /// "v4l2:N".
  std::string describe() const override;
  /// Frames dropped because the queue was full.
  long dropped() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The Camera for a --camera specification: "video:PATH" (a recording directory, or a video file
/// with PATH.timestamps.csv; RecordedCamera) or "v4l2:N" (LiveCamera on /dev/videoN, stamping on
/// a clock started at `start`). "synthetic" is built by the caller (it needs the simulated
/// world): nullptr. Anything else: std::invalid_argument "--camera: ..." listing the forms.
std::unique_ptr<Camera> open_camera(
    const std::string& spec,
    std::chrono::steady_clock::time_point start = std::chrono::steady_clock::now());

/// The Joint for a --joint specification: "log:PATH" (a recording directory or its joint.csv;
/// LogJoint); "synthetic": nullptr (built by the caller); anything else: std::invalid_argument
/// "--joint: ...".
std::unique_ptr<Joint> open_joint(const std::string& spec);

}  // namespace flatland::drivers
