// The hand's pose from one overhead image: the joint axis and the hand's angle from its outline,
// as a check on the encoder and as the measurement behind the joint calibration.
//
// The paper's hand is symmetric about both of its own axes (x(s) even and y(s) odd within the right
// half, the left half the mirror image x -> -x), so the area centroid of its top face is the hand
// frame's origin (the joint axis) and the principal axis of the face's second moments is the hand's
// x axis. The outline therefore gives the angle only modulo pi: the encoder resolves it.
#pragma once

#include "flatland/camera/camera_model.hpp"

#include <opencv2/core.hpp>

#include <optional>

namespace flatland::vision {

struct HandPose {
  cv::Point2d center_table{0, 0};  ///< m, area centroid of the top face, table frame
  double angle = 0;                ///< rad in (-pi/2, pi/2]: the hand's x axis, modulo pi
  double area = 0;                 ///< m^2, measured top-face area (a sanity check)
  double elongation = 0;           ///< sqrt of the ratio of principal second moments (> 1)
  double sigma_center = 0;         ///< m, 1-sigma of each centre coordinate from image noise
  double sigma_angle = 0;          ///< rad, 1-sigma of the angle from image noise
  double hand_level = 0, table_level = 0;  ///< DN, the grey levels used for the coverage map
  int pixels = 0;                          ///< pixels with non-zero coverage
};

struct HandPoseOptions {
  /// Grey levels (DN) of the hand's top face and of the table; measured from the image if unset.
  std::optional<double> hand_level, table_level;
  /// Smallest bright blob (px) accepted as the hand.
  int min_area_px = 500;
  /// Coverage starts at this fraction of the face-table contrast above the table, so that the
  /// plate's side walls (up to ~0.32 of it) do not count as face. 0: plain linear coverage.
  double coverage_floor = 0.35;
};

/// Measure the hand's pose. `image`: CV_8UC1/CV_8UC3 (BGR) or CV_32FC1/CV_32FC3 (DN); `camera`:
/// intrinsics, distortion and the table pose (R, t); `plate_height`: m, height of the hand's top
/// face above the table (render.hand_thickness). The hand is the largest bright blob; it must lie
/// entirely inside the image. Throws std::invalid_argument (one line) when no hand is found, the
/// hand touches the image border or the camera does not match the image.
HandPose measure_hand_pose(const cv::Mat& image, const camera::CameraModel& camera,
                           double plate_height, const HandPoseOptions& options = {});

/// The angle congruent to `axis_angle` modulo pi that is nearest to `expected` (e.g. the encoder
/// angle plus its offset): how the encoder resolves the outline's half-turn ambiguity.
double resolve_half_turn(double axis_angle, double expected);

}  // namespace flatland::vision
