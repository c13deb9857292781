#include "flatland/drivers/live.hpp"

#include "flatland/drivers/recorded.hpp"

#include <opencv2/videoio.hpp>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <deque>
#include <filesystem>
#include <mutex>
#include <stdexcept>
#include <string_view>
#include <thread>
#include <utility>

namespace flatland::drivers {

namespace {

using Seconds = std::chrono::duration<double>;

// A grab that fails this many times in a row means the device is gone: V4L2 itself waits
// seconds for a frame before failing, so a healthy camera never gets close.
constexpr int kMaxGrabFailures = 3;
// A driver time stamp further than this before the grab returned is not a capture time on our
// clock (some drivers stamp on another clock or not at all).
constexpr double kMaxDriverLatency = 1.0;

}  // namespace

double SteadyClock::now() const {
  return Seconds(std::chrono::steady_clock::now() - start_).count();
}

void SteadyClock::sleep_until(double t) {
  // Converting inf or NaN to a steady_clock duration is undefined behaviour, not a long sleep.
  if (!std::isfinite(t))
    throw std::invalid_argument("SteadyClock::sleep_until: t must be finite, got " +
                                std::to_string(t));
  std::this_thread::sleep_until(
      start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(Seconds(t)));
}

// ---------------------------------------------------------------------------------------------

struct LiveCamera::Impl {
  int device = 0;
  std::chrono::steady_clock::time_point start;
  std::size_t capacity = 4;
  cv::VideoCapture capture;

  std::mutex mutex;
  std::deque<CameraFrame> queue;
  long dropped = 0;
  std::string error;  // set by the grabber when the device stops delivering
  std::atomic<bool> stopping{false};
  std::thread grabber;

  std::string name() const { return "v4l2:" + std::to_string(device); }

  void run() {
    long index = 0;
    int failures = 0;
    while (!stopping) {
      cv::Mat image;  // fresh every time: the queued frames must not share one buffer
      bool ok = false;
      try {
        ok = capture.read(image) && !image.empty();
      } catch (const cv::Exception&) {
        ok = false;
      }
      const double t_arrival = Seconds(std::chrono::steady_clock::now() - start).count();
      if (!ok) {
        if (++failures >= kMaxGrabFailures) {
          std::lock_guard lock(mutex);
          error = "camera " + name() + ": the device stopped delivering frames";
          return;
        }
        continue;
      }
      failures = 0;
      // OpenCV's V4L2 backend reports the buffer's kernel time stamp as POS_MSEC; on drivers
      // with monotonic stamps that is CLOCK_MONOTONIC, the clock of std::chrono::steady_clock.
      double t_capture = t_arrival;
      const double ms = capture.get(cv::CAP_PROP_POS_MSEC);
      if (std::isfinite(ms) && ms > 0) {
        const double t = ms / 1000 - Seconds(start.time_since_epoch()).count();
        if (t <= t_arrival && t_arrival - t < kMaxDriverLatency) t_capture = t;
      }
      CameraFrame frame;
      frame.index = index++;
      frame.t_capture = t_capture;
      frame.t_arrival = t_arrival;
      frame.image = std::move(image);
      std::lock_guard lock(mutex);
      if (queue.size() >= capacity) {
        queue.pop_front();  // the loop wants the newest frames; the gap in index shows the drop
        ++dropped;
      }
      queue.push_back(std::move(frame));
    }
  }
};

LiveCamera::LiveCamera(int device, std::chrono::steady_clock::time_point start,
                       std::size_t queue_capacity)
    : impl_(std::make_unique<Impl>()) {
  impl_->device = device;
  impl_->start = start;
  impl_->capacity = std::max<std::size_t>(queue_capacity, 1);
  const std::string node = "/dev/video" + std::to_string(device);
  std::error_code ec;
  if (device < 0 || !std::filesystem::exists(node, ec))
    throw std::invalid_argument("camera " + impl_->name() + ": no such device (" + node +
                                " does not exist)");
  bool opened = false;
  try {
    opened = impl_->capture.open(device, cv::CAP_V4L2);
  } catch (const cv::Exception&) {
    opened = false;
  }
  if (!opened)
    throw std::invalid_argument("camera " + impl_->name() + ": cannot open " + node +
                                " (busy, no permission, or not a capture device)");
  impl_->grabber = std::thread([impl = impl_.get()] { impl->run(); });
}

LiveCamera::~LiveCamera() {
  impl_->stopping = true;
  // The grabber notices within one frame period (a blocked read returns with the next frame or
  // V4L2's time-out).
  if (impl_->grabber.joinable()) impl_->grabber.join();
  impl_->capture.release();
}

std::optional<CameraFrame> LiveCamera::poll(double now) {
  std::lock_guard lock(impl_->mutex);
  if (!impl_->queue.empty()) {
    if (impl_->queue.front().t_arrival > now) return std::nullopt;
    CameraFrame frame = std::move(impl_->queue.front());
    impl_->queue.pop_front();
    return frame;
  }
  if (!impl_->error.empty()) throw std::runtime_error(impl_->error);
  return std::nullopt;
}

std::string LiveCamera::describe() const { return impl_->name(); }

long LiveCamera::dropped() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->dropped;
}

// ---------------------------------------------------------------------------------------------

namespace {

const char* const kCameraForms =
    "synthetic, video:PATH (a recording directory or a video file) "
    "or v4l2:N (/dev/videoN)";

}  // namespace

std::unique_ptr<Camera> open_camera(const std::string& spec,
                                    std::chrono::steady_clock::time_point start) {
  if (spec == "synthetic") return nullptr;
  const std::string_view s = spec;
  if (s.starts_with("video:")) {
    const std::string path(s.substr(6));
    if (path.empty()) throw std::invalid_argument("--camera: video: needs a path (video:PATH)");
    return std::make_unique<RecordedCamera>(path);
  }
  if (s.starts_with("v4l2:")) {
    const std::string_view n = s.substr(5);
    int device = -1;
    const auto res = std::from_chars(n.data(), n.data() + n.size(), device);
    if (n.empty() || res.ec != std::errc() || res.ptr != n.data() + n.size() || device < 0 ||
        n.front() == '-' || n.front() == '+')
      throw std::invalid_argument("--camera: " + spec +
                                  ": the device must be a non-negative integer (v4l2:0 is "
                                  "/dev/video0)");
    return std::make_unique<LiveCamera>(device, start);
  }
  throw std::invalid_argument("--camera: unknown camera '" + spec + "' (expected " + kCameraForms +
                              ")");
}

std::unique_ptr<Joint> open_joint(const std::string& spec) {
  if (spec == "synthetic") return nullptr;
  const std::string_view s = spec;
  if (s.starts_with("log:")) {
    const std::string path(s.substr(4));
    if (path.empty()) throw std::invalid_argument("--joint: log: needs a path (log:PATH)");
    return std::make_unique<LogJoint>(path);
  }
  throw std::invalid_argument("--joint: unknown joint '" + spec +
                              "' (expected synthetic or log:PATH, a recording directory or its "
                              "joint.csv)");
}

}  // namespace flatland::drivers
