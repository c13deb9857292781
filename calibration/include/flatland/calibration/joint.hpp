// Table pose and joint calibration: where the table is (from a chessboard lying on it at a known
// place), and where the joint axis is on the table and what the encoder reads at the hand's zero
// (from images of the hand at known encoder angles). Method and measured accuracy: docs/JOINT.md.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/vision/hand_pose.hpp"

#include <opencv2/core.hpp>

#include <numbers>
#include <string>
#include <vector>

namespace flatland::calibration {

/// The inner corners of chessboards lying on the table at known places, gathered one image at a
/// time: the image can be dropped once added, so memory grows with the corners (40 per 9 x 6
/// board), not with the pixels.
class TableCorners {
 public:
  /// Finds `board`'s inner corners in `image` (8-bit grey or BGR) and keeps them with their
  /// places in the table frame (camera::corners_in_table). `name` (a file) names the placement in
  /// reports. The board must not look the same turned by a half turn (squares_x + squares_y odd),
  /// or its corners could be matched the wrong way round. Throws std::invalid_argument (one line,
  /// "image N: ...") for a ChArUco or symmetric board or no board found.
  void add(const cv::Mat& image, const camera::PlacedBoard& board, const std::string& name = "");
  std::size_t placements() const { return names_.size(); }
  const std::vector<cv::Point3f>& object_points() const { return object_; }  ///< m, table frame
  const std::vector<cv::Point2f>& image_points() const { return found_; }    ///< px
  /// Placement i's corners are [starts()[i], starts()[i + 1]) (the last runs to the end).
  const std::vector<std::size_t>& starts() const { return starts_; }
  const std::vector<std::string>& names() const { return names_; }

 private:
  std::vector<cv::Point3f> object_;
  std::vector<cv::Point2f> found_;
  std::vector<std::size_t> starts_;
  std::vector<std::string> names_;
};

/// The table pose in the camera: x_cam = R x_table + t (as camera::CameraModel::R, t).
struct TablePose {
  cv::Matx33d R = cv::Matx33d::eye();
  cv::Vec3d t{0, 0, 0};
  double rms_px = 0;                     ///< reprojection RMS of the board's inner corners
  int corners = 0;                       ///< inner corners used
  std::vector<double> placement_rms_px;  ///< per placement, in the order added
  /// Covariance of (rvec, tvec) (rad, m) with the intrinsics held: the corners' scatter through
  /// the fit, its variance taken from the residuals (SSR / (2N - 6)).
  cv::Matx<double, 6, 6> noise_covariance = cv::Matx<double, 6, 6>::zeros();
  /// d(rvec, tvec) / d(intrinsic k), k over the intrinsics_std given: how the fit moves the pose
  /// to make up for a changed camera matrix or distortion.
  std::vector<cv::Vec<double, 6>> sensitivity;
  /// The whole covariance: noise_covariance plus each intrinsic's variance through `sensitivity`.
  cv::Matx<double, 6, 6> covariance = cv::Matx<double, 6, 6>::zeros();
  /// Reciprocal condition number of the pose's normal matrix (columns scaled to unit norm).
  double rcond = 0;
  /// Two or more placements: the F statistic of one common pose against a pose per placement
  /// (the extra squared residual per saved degree of freedom over the separate fits' residual
  /// variance), and its quantile at 1 - kTableSignificance; 0 for one placement.
  double f_statistic = 0, f_limit = 0;
  /// Why the corners do not support this pose (one line), empty when they do: the pose is not
  /// determined (rcond below kMinTableRcond), or the placements do not agree on one pose
  /// (f_statistic above f_limit: a row of table.csv says the board was where it was not).
  std::string unsupported;
  /// 1-sigma of the camera centre in the table frame (m), from `covariance`.
  cv::Vec3d sigma_camera_in_table() const;
};

constexpr double kMinTableRcond = 1e-12;
constexpr double kTableSignificance = 1e-3;

/// The table pose from every placement's corners in one fit (the camera fixed): spread
/// placements determine the table's tilt far better than one. `intrinsics_std` (fx fy cx cy k1 k2
/// p1 p2 k3, then k4 k5 k6 if given; a calibration's report) adds the camera's own uncertainty
/// to the covariance. Throws std::invalid_argument (one line) for no placements, bad K, a
/// failed solve or a board behind the camera.
TablePose estimate_table_pose(const TableCorners& corners, const cv::Matx33d& K,
                              const camera::Distortion& dist,
                              const std::vector<double>& intrinsics_std = {});
/// The same from one image of a board (TableCorners of one placement).
TablePose estimate_table_pose(const cv::Mat& image, const camera::PlacedBoard& board,
                              const cv::Matx33d& K, const camera::Distortion& dist);
/// The same from several images of boards at known places, one board per image. Errors name the
/// image index.
TablePose estimate_table_pose(const std::vector<cv::Mat>& images,
                              const std::vector<camera::PlacedBoard>& boards, const cv::Matx33d& K,
                              const camera::Distortion& dist);

/// How uncertain the camera the hand is measured through is: its intrinsics and its table pose,
/// with the pose's dependence on the intrinsics (a table fit makes up for a wrong focal length
/// with its height, and the two errors nearly cancel near the boards).
struct CameraUncertainty {
  std::vector<double> intrinsics_std;  ///< fx fy cx cy k1 k2 p1 p2 k3 [k4 k5 k6]; empty: exact
  cv::Matx<double, 6, 6> pose_noise = cv::Matx<double, 6, 6>::zeros();  ///< TablePose's
  std::vector<cv::Vec<double, 6>> pose_sensitivity;  ///< TablePose::sensitivity (or empty)
};

/// What a joint fit needs of its data. Defaults: docs/JOINT.md#what-the-data-must-show.
struct JointOptions {
  /// Encoder readings closer than this count as one angle.
  double distinct_rad = 1.0 * std::numbers::pi / 180;
  /// At least this many distinct readings among the inliers ...
  int min_distinct_readings = 4;
  /// ... spread over at least this much (the range of the readings modulo a half turn).
  double min_span_rad = 45.0 * std::numbers::pi / 180;
  /// The chi-square test of the residuals against the measurement sigma fails at this
  /// significance (the probability that consistent data fail it).
  double significance = 1e-3;
  /// Each image's measurement sigma is the hand pose's noise sigma and this model error added in
  /// quadrature: the outline method's per-image accuracy on rendered images (docs/JOINT.md).
  double model_sigma_center_m = 0.03e-3;
  double model_sigma_angle_rad = 0.01 * std::numbers::pi / 180;
};

/// Per-image results of calibrate_joint, for reports and for rejecting outliers.
struct JointReport {
  std::vector<vision::HandPose> poses;        ///< hand pose measured in each image
  std::vector<cv::Point2d> center_residuals;  ///< m, centre - axis
  std::vector<double> angle_residuals;        ///< rad, measured - (encoder + offset), modulo pi
  std::vector<bool> inlier;                   ///< false: rejected as an outlier
  double center_rms = 0;                      ///< m, RMS of |centre - axis| over the inliers
  double angle_rms = 0;                       ///< rad
  /// m, 1-sigma of each axis coordinate: the images' part and the camera's (its table pose and
  /// intrinsics, mapped to the axis), in quadrature.
  double sigma_axis = 0;
  double sigma_offset = 0;  ///< rad, 1-sigma of the offset, the same two parts
  /// The images' part: each image's measurement sigma through the mean, scaled up by the
  /// residuals' Birge ratio sqrt(chi-square / dof) when that exceeds 1.
  double sigma_axis_images = 0, sigma_offset_images = 0;
  int distinct_readings = 0;  ///< among the inliers, JointOptions::distinct_rad apart
  double span_rad = 0;        ///< range of the inliers' readings modulo a half turn
  double chi2 = 0;            ///< sum of squared residuals / measurement sigma^2 over inliers
  int dof = 0;                ///< 3 x inliers - 3
  double chi2_limit = 0;      ///< the chi-square quantile at 1 - significance
  /// Why the data do not support the result (one line), empty when they do: too few distinct
  /// readings, too small a span, or residuals inconsistent with the measurement sigma.
  std::string unsupported;
};

/// Joint axis (table frame) and encoder offset (true hand angle = encoder angle + offset) from
/// the hand's pose measured at known encoder angles (rad), each by vision::measure_hand_pose
/// through `camera` (with its table pose; `uncertainty`, propagated to the result's sigma). The
/// hand's outline is symmetric under a half turn, so the offset is found modulo pi and reported in
/// (-pi/2, pi/2]: the encoder must be zeroed to within a quarter turn. Data that do not support the
/// result still give it, with JointReport::unsupported saying why (too few images or readings,
/// fewer than 3 that agree, residuals inconsistent with the noise). Throws std::invalid_argument
/// (one line) for no poses, a size mismatch or non-finite angles.
camera::JointCalibration calibrate_joint(const std::vector<vision::HandPose>& poses,
                                         const std::vector<double>& encoder_angles,
                                         const camera::CameraModel& camera, double plate_height,
                                         const CameraUncertainty& uncertainty,
                                         JointReport* report = nullptr,
                                         const JointOptions& options = {});
/// The same from images: measures each (vision::measure_hand_pose), the table pose and the
/// intrinsics taken as exact; errors name the image index.
camera::JointCalibration calibrate_joint(const std::vector<cv::Mat>& images,
                                         const std::vector<double>& encoder_angles,
                                         const camera::CameraModel& camera, double plate_height,
                                         JointReport* report = nullptr,
                                         const JointOptions& options = {});

}  // namespace flatland::calibration
