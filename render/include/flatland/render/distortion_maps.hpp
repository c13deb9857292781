// Distortion remap tables: rendered images are distorted by remapping a pinhole render through
// maps built with cv::undistortPoints, so they share camera::CameraModel's geometry exactly.
#pragma once

#include "flatland/camera/camera_model.hpp"

#include <opencv2/core.hpp>

namespace flatland::render {

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
DistortionMaps make_distortion_maps(const camera::CameraModel& camera, int supersample);

}  // namespace flatland::render
