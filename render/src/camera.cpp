// Camera model: intrinsics, distortion and a look-at pose over the table; distortion remap tables.
//
// cv::projectPoints is the single source of truth for the geometry: project() calls it, and the
// distortion maps are built by inverting exactly the same model (cv::undistortPoints, iterated to
// convergence) and then checked against it, so a rendered image, project() and a calibration run
// by OpenCV on the rendered images all agree on where a table point lands.
#include "flatland/render/camera.hpp"

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

// Larger images are almost certainly a unit mistake and would exhaust memory in the renderer.
constexpr int kMaxImageSide = 16384;
// Pixels of margin around the undistorted footprint: bilinear remapping reads one neighbour, and
// one more keeps the edge pixels away from whatever the renderer clears the border to.
constexpr int kIdealMargin = 2;
// The ideal image may be this many times larger (per side) than the distorted one; a bigger
// footprint means a distortion so strong it folds over, which no pinhole render can stand in for.
constexpr int kMaxIdealGrowth = 4;
// Largest tolerated error (supersampled px) of re-distorting a map position onto its pixel centre.
constexpr double kMaxRoundTripPx = 1e-3;

std::string num(double v) {
  std::ostringstream os;
  os.precision(9);
  os << v;
  return os.str();
}

// Streamed rather than built with `"(" + ...`, which trips GCC 12's -Wrestrict false positive.
std::string vec3(const std::array<double, 3>& v) {
  std::ostringstream os;
  os.precision(9);
  os << '(' << v[0] << ", " << v[1] << ", " << v[2] << ')';
  return os.str();
}

[[noreturn]] void fail(const std::string& field, const std::string& reason) {
  throw std::invalid_argument(field + ": " + reason);
}

void require_finite3(const std::array<double, 3>& v, const std::string& field) {
  for (double c : v)
    if (!std::isfinite(c)) fail(field, "must be finite, got " + vec3(v));
}

cv::Vec3d to_vec(const std::array<double, 3>& v) { return {v[0], v[1], v[2]}; }

}  // namespace

CameraModel CameraModel::from_spec(const CameraSpec& spec) {
  if (spec.width <= 0 || spec.width > kMaxImageSide)
    fail("camera.width", "must be in [1, " + std::to_string(kMaxImageSide) + "] px, got " +
                             std::to_string(spec.width));
  if (spec.height <= 0 || spec.height > kMaxImageSide)
    fail("camera.height", "must be in [1, " + std::to_string(kMaxImageSide) + "] px, got " +
                              std::to_string(spec.height));
  // `!(x > 0)` rather than `x <= 0` so that NaN is rejected too.
  if (!(spec.fx > 0) || !std::isfinite(spec.fx))
    fail("camera.fx", "must be positive and finite, got " + num(spec.fx));
  if (!(spec.fy > 0) || !std::isfinite(spec.fy))
    fail("camera.fy", "must be positive and finite, got " + num(spec.fy));
  if (!std::isfinite(spec.cx)) fail("camera.cx", "must be finite, got " + num(spec.cx));
  if (!std::isfinite(spec.cy)) fail("camera.cy", "must be finite, got " + num(spec.cy));
  for (double d : spec.distortion)
    if (!std::isfinite(d)) fail("camera.distortion", "coefficients must be finite, got " + num(d));
  if (!(spec.fps > 0) || !std::isfinite(spec.fps))
    fail("camera.fps", "must be positive and finite, got " + num(spec.fps));
  if (!(spec.exposure >= 0) || !(spec.exposure <= 1.0 / spec.fps))
    fail("camera.exposure",
         "must be in [0, 1/fps] = [0, " + num(1.0 / spec.fps) + "] s, got " + num(spec.exposure));
  require_finite3(spec.position, "camera.position");
  require_finite3(spec.look_at, "camera.look_at");
  require_finite3(spec.up, "camera.up");
  if (!(spec.position[2] > 0))
    fail("camera.position",
         "the camera must be above the table (z > 0), got z = " + num(spec.position[2]));

  const cv::Vec3d position = to_vec(spec.position);
  const cv::Vec3d view = to_vec(spec.look_at) - position;
  const double view_norm = cv::norm(view);
  if (!(view_norm > 1e-9))
    fail("camera.look_at", "must differ from camera.position, both are " + vec3(spec.position));
  const cv::Vec3d z_c = view / view_norm;
  // Looking level or upwards would put the table plane behind the camera (or at the horizon).
  if (!(z_c[2] < 0))
    fail("camera.look_at", "must be below the camera so that the table is in front of it, got " +
                               vec3(spec.look_at) + " from camera.position " + vec3(spec.position));
  const cv::Vec3d up = to_vec(spec.up);
  const double up_norm = cv::norm(up);
  if (!(up_norm > 0)) fail("camera.up", "must be a non-zero vector, got " + vec3(spec.up));
  const cv::Vec3d side = z_c.cross(up / up_norm);
  const double side_norm = cv::norm(side);
  // sin of the angle between `up` and the viewing direction; below ~0.06 deg the image
  // orientation would hinge on rounding.
  if (!(side_norm > 1e-6))
    fail("camera.up", "must not be parallel to the viewing direction, got " + vec3(spec.up));
  // x_c = z_c x up points to the image right when `up` is the image up: for a camera above the
  // origin looking down with up = +y this gives x_c = +x, y_c = z_c x x_c = -y (image rows grow
  // towards table -y), i.e. the natural overhead view with table +y up in the image.
  const cv::Vec3d x_c = side / side_norm;
  const cv::Vec3d y_c = z_c.cross(x_c);

  CameraModel cam;
  cam.width = spec.width;
  cam.height = spec.height;
  cam.K = cv::Matx33d(spec.fx, 0, spec.cx, 0, spec.fy, spec.cy, 0, 0, 1);
  for (int i = 0; i < 5; ++i) cam.dist[i] = spec.distortion[static_cast<std::size_t>(i)];
  cam.R = cv::Matx33d(x_c[0], x_c[1], x_c[2], y_c[0], y_c[1], y_c[2], z_c[0], z_c[1], z_c[2]);
  cam.t = -(cam.R * position);
  cam.fps = spec.fps;
  cam.exposure = spec.exposure;
  return cam;
}

bool CameraModel::distorted() const {
  for (int i = 0; i < 8; ++i)
    if (dist[i] != 0) return true;
  return false;
}

cv::Vec3d CameraModel::rvec() const {
  cv::Vec3d r;
  cv::Rodrigues(R, r);
  return r;
}

cv::Vec3d CameraModel::position_in_table() const { return -(R.t() * t); }

std::vector<cv::Point2d> CameraModel::project(const std::vector<cv::Point3d>& table_points) const {
  std::vector<cv::Point2d> out;
  if (table_points.empty()) return out;  // projectPoints asserts on an empty input
  cv::projectPoints(table_points, rvec(), t, K, dist, out);
  return out;
}

cv::Point2d CameraModel::project(const cv::Point3d& table_point) const {
  return project(std::vector<cv::Point3d>{table_point}).front();
}

namespace {

DistortionMaps compute_distortion_maps(const CameraModel& camera, int supersample) {
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
         "the distortion cannot be inverted over the image (round-trip error " + num(worst) +
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
    fail("camera.distortion", "the undistorted image would be " + num(ideal_w) + " x " +
                                  num(ideal_h) + " px for a " + std::to_string(w) + " x " +
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
  Distortion dist;
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

DistortionMaps make_distortion_maps(const CameraModel& camera, int supersample) {
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
