// The compile step's camera and boards (compile.hpp).
#include "flatland/model/compile.hpp"

#include <array>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace flatland::model {

namespace {

using camera::kMaxImageSide;
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

camera::CameraModel compile_camera(const CameraSpec& spec) {
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

  camera::CameraModel cam;
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

camera::PlacedBoard compile_target(const TargetSpec& target) {
  if (!camera::aruco_dictionary_id(target.dictionary))
    throw std::invalid_argument("targets.dictionary: unknown ArUco dictionary '" +
                                target.dictionary + "'");
  camera::PlacedBoard placed;
  placed.board.kind = target.kind == TargetSpec::Kind::kCharuco ? camera::Board::Kind::kCharuco
                                                                : camera::Board::Kind::kChessboard;
  placed.board.squares_x = target.squares_x;
  placed.board.squares_y = target.squares_y;
  placed.board.square = target.square;
  placed.board.marker = target.marker;
  placed.board.dictionary = target.dictionary;
  placed.position = {target.position[0], target.position[1], target.position[2]};
  placed.rotation = {target.rotation[0], target.rotation[1], target.rotation[2]};
  return placed;
}

}  // namespace flatland::model
