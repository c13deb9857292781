// Table pose and joint calibration: where the table is (from a chessboard lying on it at a known
// place), and where the joint axis is on the table and what the encoder reads at the hand's zero
// (from images of the hand at known encoder angles). Method and measured accuracy: docs/JOINT.md.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/vision/hand_pose.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::calibration {

/// The table pose in the camera: x_cam = R x_table + t (as camera::CameraModel::R, t).
struct TablePose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};
  double rms_px = 0;  ///< reprojection RMS of the board's inner corners
  int corners = 0;    ///< inner corners used
};

/// The table pose from one image of a chessboard lying on the table. `board` says what the board
/// is (type chessboard; squares_x x squares_y squares of side `square`) and where it lies in the
/// table frame (`position`, Rodrigues `rotation`, as a scene's `targets` entry:
/// camera::corners_in_table gives its inner corners in the table frame). The board must not look
/// the same turned by a half turn (squares_x + squares_y odd, as is inner corners' sum), or its
/// corners could be matched the wrong way round. Throws
/// std::invalid_argument (one line) for a ChArUco or symmetric board, bad K, or no board found.
TablePose estimate_table_pose(const cv::Mat& image, const camera::PlacedBoard& board, const cv::Matx33d& K,
                              const camera::Distortion& dist);
/// The same from several images of boards at known places (one board per image, the camera
/// fixed): all corners in one pose fit. Spread placements determine the table's tilt better.
/// Errors name the image index.
TablePose estimate_table_pose(const std::vector<cv::Mat>& images,
                              const std::vector<camera::PlacedBoard>& boards, const cv::Matx33d& K,
                              const camera::Distortion& dist);

/// Per-image results of calibrate_joint, for reports and for rejecting outliers.
struct JointReport {
  std::vector<vision::HandPose> poses;        ///< hand pose measured in each image
  std::vector<cv::Point2d> center_residuals;  ///< m, centre - axis
  std::vector<double> angle_residuals;        ///< rad, measured - (encoder + offset), modulo pi
  std::vector<bool> inlier;                   ///< false: rejected as an outlier
  double center_rms = 0;                      ///< m, RMS of |centre - axis| over the inliers
  double angle_rms = 0;                       ///< rad
  double sigma_axis = 0;    ///< m, 1-sigma of each axis coordinate (from the scatter)
  double sigma_offset = 0;  ///< rad, 1-sigma of the offset (from the scatter)
};

/// Joint axis (table frame) and encoder offset (true hand angle = encoder angle + offset) from
/// images of the hand at known encoder angles (rad), seen by `camera` (with the table pose).
/// `plate_height`: m, height of the hand's top face (render.hand_thickness). The hand's outline
/// is symmetric under a half turn, so the offset is found modulo pi and reported in (-pi/2, pi/2]:
/// the encoder must be zeroed to within a quarter turn. Angles spread over a half turn or more
/// give the best offset; the axis needs no spread. Needs at least 3 images. Throws
/// std::invalid_argument (one line) for fewer than 3 images, a size mismatch, non-finite angles,
/// or an image where no hand is found (naming the image index).
camera::JointCalibration calibrate_joint(const std::vector<cv::Mat>& images,
                                 const std::vector<double>& encoder_angles,
                                 const camera::CameraModel& camera, double plate_height,
                                 JointReport* report = nullptr);

}  // namespace flatland::calibration
