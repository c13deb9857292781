// Camera model: OpenCV's pinhole + distortion (k1, k2, p1, p2, k3) and a pose over the table.
// Geometry matches cv::projectPoints exactly; rendered images are distorted by remapping a
// pinhole render through maps built with cv::undistortPoints, so they share that geometry.
#pragma once

#include "flatland/scene/scene.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::render {

/// OpenCV's distortion coefficients k1, k2, p1, p2, k3, k4, k5, k6 (its order): the rational
/// model, of which the 5-coefficient plumb_bob model is the case k4 = k5 = k6 = 0 (OpenCV computes
/// both with the same formula, so a 5-coefficient camera projects identically either way).
using Distortion = cv::Vec<double, 8>;

struct CameraModel {
  int width = 640, height = 480;
  cv::Matx33d K = cv::Matx33d::eye();
  Distortion dist = Distortion::all(0);
  cv::Matx33d R =
      cv::Matx33d::eye();  ///< table -> camera rotation (OpenCV axes: x right, y down, z forward)
  cv::Vec3d t = cv::Vec3d(0, 0, 0);  ///< table -> camera translation: x_cam = R x_table + t
  double fps = 30.0;
  double exposure = 0.0;

  /// From a scene's camera section; validates (fx, fy > 0, size > 0, camera above the table,
  /// look_at != position, up not parallel to the viewing direction). Throws std::invalid_argument
  /// naming the field ("camera.fx: must be positive").
  static CameraModel from_spec(const CameraSpec& spec);

  bool distorted() const;
  /// Any of k4, k5, k6 nonzero: the rational model's denominator is in use.
  bool rational() const { return dist[5] != 0 || dist[6] != 0 || dist[7] != 0; }
  cv::Vec3d rvec() const;               ///< Rodrigues vector of R (for cv::projectPoints)
  cv::Vec3d position_in_table() const;  ///< camera centre, table frame
  /// cv::projectPoints of table-frame points.
  std::vector<cv::Point2d> project(const std::vector<cv::Point3d>& table_points) const;
  cv::Point2d project(const cv::Point3d& table_point) const;
};

/// Remap tables that turn an undistorted pinhole image into the camera's distorted image.
/// `ideal` is the pinhole camera to render (same pose, focal lengths scaled by `supersample`,
/// image enlarged to cover every distorted pixel); `map_x/map_y` give, for each pixel of the
/// distorted image at `supersample` times the camera resolution, its position in the ideal image.
struct DistortionMaps {
  int supersample = 1;
  int ideal_width = 0, ideal_height = 0;
  cv::Matx33d ideal_K;
  cv::Mat map_x, map_y;  ///< CV_32FC1, size (height*s) x (width*s)
};
/// Built once per (intrinsics, distortion, size, supersample) and shared: the maps of a returned
/// value are the cached ones, so treat them as read-only.
DistortionMaps make_distortion_maps(const CameraModel& camera, int supersample);

}  // namespace flatland::render
