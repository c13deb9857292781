// Distortion remap tables. cv::projectPoints is the single source of truth for the geometry
// (camera::CameraModel::project calls it), and the maps are built by inverting exactly the same
// model (cv::undistortPoints, iterated to convergence) and then checked against it, so a rendered
// image, project() and a calibration run by OpenCV on the rendered images all agree on where a
// table point lands.
#include "flatland/render/distortion_maps.hpp"
#include "fail.hpp"
#include "flatland/sim/format.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/utility.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <list>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

namespace {

using camera::kMaxImageSide;
// Pixels of margin around the undistorted footprint: bilinear remapping reads one neighbour, and
// one more keeps the edge pixels away from whatever the renderer clears the border to.
constexpr int kIdealMargin = 2;
// The ideal image may be this many times larger (per side) than the distorted one; a bigger
// footprint means a distortion so strong it folds over, which no pinhole render can stand in for.
constexpr int kMaxIdealGrowth = 4;
// Largest tolerated error (supersampled px) of re-distorting a map position onto its pixel centre.
constexpr double kMaxRoundTripPx = 1e-3;

}  // namespace

namespace {

DistortionMaps compute_distortion_maps(const camera::CameraModel& camera, int supersample) {
  if (supersample < 1 || supersample > kMaxImageSide)
    fail("effects.supersample", "must be a positive integer, got " + std::to_string(supersample));
  if (camera.width <= 0 || camera.height <= 0)
    fail("camera.width", "the image size must be positive, got " + std::to_string(camera.width) +
                             " x " + std::to_string(camera.height));
  const int s = supersample;
  const long long wl = static_cast<long long>(camera.width) * s;
  const long long hl = static_cast<long long>(camera.height) * s;
  if (wl > kMaxImageSide * 4LL || hl > kMaxImageSide * 4LL)
    fail("effects.supersample", "the supersampled image " + std::to_string(wl) + " x " +
                                    std::to_string(hl) + " px is too large");
  const int w = static_cast<int>(wl), h = static_cast<int>(hl);

  // Supersampled intrinsics. Pixel centres sit at integers (OpenCV), so a camera pixel centre c
  // covers supersampled pixels s*c .. s*c + s-1, whose centre is (c + 0.5) * s - 0.5.
  const double fx = camera.K(0, 0) * s, fy = camera.K(1, 1) * s;
  const double cx = (camera.K(0, 2) + 0.5) * s - 0.5, cy = (camera.K(1, 2) + 0.5) * s - 0.5;
  const cv::Matx33d K_s(fx, 0, cx, 0, fy, cy, 0, 0, 1);

  DistortionMaps maps;
  maps.supersample = s;
  maps.map_x.create(h, w, CV_32FC1);
  maps.map_y.create(h, w, CV_32FC1);

  if (!camera.distorted()) {
    // The pinhole render is the image: identity maps (the renderer skips remapping).
    maps.ideal_width = w;
    maps.ideal_height = h;
    maps.ideal_K = K_s;
    for (int v = 0; v < h; ++v) {
      float* mx = maps.map_x.ptr<float>(v);
      float* my = maps.map_y.ptr<float>(v);
      for (int u = 0; u < w; ++u) {
        mx[u] = static_cast<float>(u);
        my[u] = static_cast<float>(v);
      }
    }
    return maps;
  }

  // Undistorted normalised coordinates of every output pixel centre, row-major, and for each row
  // the largest error of sending them back through the forward model. Strong distortion can fold
  // over (the radial factor stops being monotonic), and then the inversion converges to nothing:
  // the check catches it. Rows are independent, so they are done in parallel (at s = 3 that is
  // 2.8 million points, about a second on one core).
  std::vector<cv::Point2d> normalised(static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
  std::vector<double> row_error(static_cast<std::size_t>(h), 0.0);
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
    const std::size_t first = static_cast<std::size_t>(rows.start) * static_cast<std::size_t>(w);
    const std::size_t count =
        static_cast<std::size_t>(rows.end - rows.start) * static_cast<std::size_t>(w);
    std::vector<cv::Point2d> pixels;
    pixels.reserve(count);
    for (int v = rows.start; v < rows.end; ++v)
      for (int u = 0; u < w; ++u) pixels.emplace_back(u, v);
    std::vector<cv::Point2d> out;
    // The default 5 fixed-point iterations leave ~0.01 px (s = 1) to ~0.03 px (s = 3) at the
    // corners for k1 = -0.3; iterate until the re-distorted point is within 1e-12 px.
    cv::undistortPoints(
        pixels, out, K_s, camera.dist, cv::noArray(), cv::noArray(),
        cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
    std::vector<cv::Point3d> rays;
    rays.reserve(count);
    for (const auto& n : out) rays.emplace_back(n.x, n.y, 1.0);
    std::vector<cv::Point2d> back;
    cv::projectPoints(rays, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0), K_s, camera.dist, back);
    for (std::size_t i = 0; i < count; ++i) {
      const double e = std::hypot(back[i].x - pixels[i].x, back[i].y - pixels[i].y);
      double& worst = row_error[static_cast<std::size_t>(pixels[i].y)];
      worst = std::isfinite(e) ? std::max(worst, e) : std::numeric_limits<double>::infinity();
      normalised[first + i] = out[i];
    }
  });
  const double worst = *std::max_element(row_error.begin(), row_error.end());
  if (!(worst <= kMaxRoundTripPx))
    fail("camera.distortion",
         "the distortion cannot be inverted over the image (round-trip error " +
             sim::format_significant(worst, 9) +
             " px); the coefficients are too strong for this field of view");

  // Footprint of the output pixels in the pinhole image with intrinsics K_s.
  double umin = std::numeric_limits<double>::infinity(), umax = -umin;
  double vmin = umin, vmax = -umin;
  for (const auto& n : normalised) {
    const double u = fx * n.x + cx, v = fy * n.y + cy;
    umin = std::min(umin, u);
    umax = std::max(umax, u);
    vmin = std::min(vmin, v);
    vmax = std::max(vmax, v);
  }
  // Grow the K_s image by whole pixels on each side (never shrink it) so that the footprint plus
  // the margin fits; whole pixels keep the ideal pixel grid aligned with the K_s one.
  const auto pad = [](double overshoot) {
    return std::max(0.0, std::ceil(overshoot + kIdealMargin));
  };
  const double left = pad(-umin), right = pad(umax - (w - 1));
  const double top = pad(-vmin), bottom = pad(vmax - (h - 1));
  const double ideal_w = w + left + right, ideal_h = h + top + bottom;
  if (!(ideal_w <= static_cast<double>(w) * kMaxIdealGrowth) ||
      !(ideal_h <= static_cast<double>(h) * kMaxIdealGrowth))
    fail("camera.distortion",
         "the undistorted image would be " + sim::format_significant(ideal_w, 9) + " x " +
             sim::format_significant(ideal_h, 9) + " px for a " + std::to_string(w) + " x " +
             std::to_string(h) + " px image; the distortion is too strong");
  maps.ideal_width = static_cast<int>(ideal_w);
  maps.ideal_height = static_cast<int>(ideal_h);
  const double icx = cx + left, icy = cy + top;
  maps.ideal_K = cv::Matx33d(fx, 0, icx, 0, fy, icy, 0, 0, 1);

  std::size_t i = 0;
  for (int v = 0; v < h; ++v) {
    float* mx = maps.map_x.ptr<float>(v);
    float* my = maps.map_y.ptr<float>(v);
    for (int u = 0; u < w; ++u, ++i) {
      mx[u] = static_cast<float>(fx * normalised[i].x + icx);
      my[u] = static_cast<float>(fy * normalised[i].y + icy);
    }
  }
  return maps;
}

// Maps depend on the intrinsics, the distortion, the size and the supersampling only (not on the
// pose), and building them dominates a renderer's construction: about 1 s at 640 x 480 with 4 x 4
// supersampling, where rendering a frame takes milliseconds. Callers that build one renderer per
// pose (calibration image sets, studies) share them through this cache. Entries are read-only
// (the renderer only reads them through cv::remap) and bounded in total size.
struct MapsKey {
  int width, height, supersample;
  cv::Matx33d K;
  camera::Distortion dist;
  bool operator==(const MapsKey& o) const {
    return width == o.width && height == o.height && supersample == o.supersample && K == o.K &&
           dist == o.dist;
  }
};
constexpr std::size_t kMapsCacheBytes = std::size_t{160} << 20;

std::size_t bytes_of(const DistortionMaps& m) {
  return m.map_x.total() * m.map_x.elemSize() + m.map_y.total() * m.map_y.elemSize();
}

}  // namespace

DistortionMaps make_distortion_maps(const camera::CameraModel& camera, int supersample) {
  static std::mutex mutex;
  static std::list<std::pair<MapsKey, DistortionMaps>> cache;  // most recently used first
  const MapsKey key{camera.width, camera.height, supersample, camera.K, camera.dist};
  {
    std::lock_guard lock(mutex);
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->first == key) {
        cache.splice(cache.begin(), cache, it);
        return cache.front().second;
      }
  }
  DistortionMaps maps = compute_distortion_maps(camera, supersample);  // validates; may throw
  const std::size_t size = bytes_of(maps);
  if (size <= kMapsCacheBytes) {
    std::lock_guard lock(mutex);
    cache.emplace_front(key, maps);
    std::size_t total = 0;
    for (auto it = cache.begin(); it != cache.end();) {
      total += bytes_of(it->second);
      it = total > kMapsCacheBytes ? cache.erase(it) : std::next(it);
    }
  }
  return maps;
}

}  // namespace flatland::render
