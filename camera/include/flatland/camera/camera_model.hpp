// Camera model: OpenCV's pinhole + distortion (k1, k2, p1, p2, k3, and k4, k5, k6 of the rational
// model) and a pose over the table. Geometry matches cv::projectPoints exactly (it calls it).
// No GL: the renderer, the tracker and calibration share it (docs/DEVELOPING.md, "Layers").
#pragma once

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::camera {

/// OpenCV's distortion coefficients k1, k2, p1, p2, k3, k4, k5, k6 (its order): the rational
/// model, of which the 5-coefficient plumb_bob model is the case k4 = k5 = k6 = 0 (OpenCV computes
/// both with the same formula, so a 5-coefficient camera projects identically either way).
using Distortion = cv::Vec<double, 8>;

/// The largest image side a camera may have, px: larger is almost certainly a unit mistake and
/// would exhaust memory in the renderer (the scene's camera and the distortion maps check it).
constexpr int kMaxImageSide = 16384;

struct CameraModel {
  int width = 640, height = 480;
  cv::Matx33d K = cv::Matx33d::eye();
  Distortion dist = Distortion::all(0);
  cv::Matx33d R =
      cv::Matx33d::eye();  ///< table -> camera rotation (OpenCV axes: x right, y down, z forward)
  cv::Vec3d t = cv::Vec3d(0, 0, 0);  ///< table -> camera translation: x_cam = R x_table + t
  double fps = 30.0;
  double exposure = 0.0;

  bool distorted() const;
  /// Any of k4, k5, k6 nonzero: the rational model's denominator is in use.
  bool rational() const { return dist[5] != 0 || dist[6] != 0 || dist[7] != 0; }
  cv::Vec3d rvec() const;               ///< Rodrigues vector of R (for cv::projectPoints)
  cv::Vec3d position_in_table() const;  ///< camera centre, table frame
  /// cv::projectPoints of table-frame points.
  std::vector<cv::Point2d> project(const std::vector<cv::Point3d>& table_points) const;
  cv::Point2d project(const cv::Point3d& table_point) const;
};

}  // namespace flatland::camera
