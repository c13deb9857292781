// cv::projectPoints is the single source of truth for the geometry: project() calls it, and the
// renderer's distortion maps invert exactly the same model (render/distortion_maps.hpp).
#include "flatland/camera/camera_model.hpp"

#include <opencv2/calib3d.hpp>

namespace flatland::camera {

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

}  // namespace flatland::camera
