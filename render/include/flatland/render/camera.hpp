// Camera model: OpenCV's pinhole + distortion (k1, k2, p1, p2, k3) and a pose over the table.
// Geometry matches cv::projectPoints exactly; rendered images are distorted by remapping a
// pinhole render through maps built with cv::undistortPoints, so they share that geometry.
#pragma once

#include "flatland/scene/scene.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::render {

struct CameraModel {
  int width = 640, height = 480;
  cv::Matx33d K = cv::Matx33d::eye();
  cv::Vec<double, 5> dist = cv::Vec<double, 5>::all(0);  ///< k1, k2, p1, p2, k3
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
