// Camera intrinsics and OpenCV-model distortion from several views of a planar target
// (chessboard, or ChArUco through OpenCV's aruco module), solved with Ceres: a robust first pass,
// outlier views dropped, a least-squares second pass and standard deviations from Ceres'
// covariance.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/camera/camera_model.hpp"

#include <opencv2/core.hpp>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace flatland::calibration {

/// One view's correspondences.
struct BoardView {
  std::string name;  ///< file name (or index) for reports
  cv::Size image_size;
  std::vector<cv::Point2f> image_points;   ///< px
  std::vector<cv::Point3f> object_points;  ///< m, board plane z = 0
};

/// Find the board: chessboard through cv::findChessboardCorners + cv::cornerSubPix; ChArUco
/// through cv::aruco::detectMarkers + interpolateCornersCharuco, refined by cv::cornerSubPix
/// (OpenCV 4.6's interpolated corners are ~0.5 px off). nullopt when the board is not found (a
/// ChArUco view needs at least 6 corners). Accepts 8-bit gray or BGR images.
std::optional<BoardView> detect_board(const cv::Mat& image, const camera::Board& board,
                                      const std::string& name = "");

struct IntrinsicsOptions {
  double loss_scale_px = 1.0;  ///< Huber scale of the first (robust) pass
  /// A view is an outlier if its RMS after the robust pass exceeds
  /// max(outlier_factor * median view RMS, outlier_floor_px).
  double outlier_factor = 3.0;
  double outlier_floor_px = 1.0;
  double min_tilt_deg = 5.0;  ///< all views tilted less than this: focal length unobservable
  int max_iterations = 100;
  bool compute_covariance = true;
  // Parameters held, as OpenCV's flags hold them (no initial camera matrix: the principal point
  // stays at the image centre, the aspect ratio at 1, the distortion terms at 0). A held
  // parameter's standard deviation is 0.
  bool fix_k3 = false;               ///< CALIB_FIX_K3
  bool zero_tangent_dist = false;    ///< CALIB_ZERO_TANGENT_DIST: p1 = p2 = 0
  bool fix_aspect_ratio = false;     ///< CALIB_FIX_ASPECT_RATIO: fy = fx
  bool fix_principal_point = false;  ///< CALIB_FIX_PRINCIPAL_POINT: (cx, cy) = ((w-1)/2, (h-1)/2)
  /// CALIB_RATIONAL_MODEL: k4, k5, k6 in the denominator of the radial term, 8 coefficients.
  bool rational_model = false;
  /// "k3,tangential,aspect,principal-point" (any of them, comma-separated; empty: none) into the
  /// flags above. Throws std::invalid_argument naming an unknown one.
  void parse_fixed(const std::string& list);
  /// The held parameters' names, in that notation.
  std::vector<std::string> fixed_names() const;
};

struct IntrinsicsResult {
  cv::Matx33d K = cv::Matx33d::eye();
  camera::Distortion dist = camera::Distortion::all(0);  ///< k1 k2 p1 p2 k3 (k4 k5 k6)
  bool rational = false;  ///< calibrated with the rational model (k4, k5, k6 free)
  cv::Size image_size;
  double rms_px = 0;  ///< over the views used
  /// Per input view (same order as the input): RMS reprojection error, px, at the final
  /// solution for used views and at the robust pass for rejected ones.
  std::vector<double> view_rms_px;
  std::vector<bool> used;               ///< per input view
  std::vector<cv::Vec3d> rvecs, tvecs;  ///< per input view, board -> camera
  std::vector<std::string> rejected;    ///< "<name>: <reason>"
  /// Standard deviations of fx fy cx cy k1 k2 p1 p2 k3 (NaN if the covariance is rank deficient
  /// or was not computed).
  std::array<double, 9> std{};
  std::array<double, 3> std_rational{};  ///< of k4, k5, k6 (NaN unless rational)
  std::array<double, 9> params() const;  ///< fx fy cx cy k1 k2 p1 p2 k3
  int views_used() const;
  /// The camera (intrinsics only; pose identity) and the report for the camera file.
  camera::CameraModel camera() const;
  camera::CalibrationReport report() const;
};

/// Calibrate from views of one board. Initialisation is independent of cv::calibrateCamera:
/// cv::initCameraMatrix2D, zero distortion, cv::solvePnP per view. Throws std::invalid_argument
/// with a one-line message for fewer than 3 usable views (before or after outlier rejection),
/// mixed image sizes ("mixed image sizes: a.png is 640x480, b.png is 800x600"), and all views
/// fronto-parallel ("focal length unobservable: all views are fronto-parallel ..."). Views with
/// fewer than 6 points are rejected (listed in `rejected`), not fatal. std::runtime_error if
/// Ceres fails.
IntrinsicsResult calibrate_intrinsics(const std::vector<BoardView>& views,
                                      const IntrinsicsOptions& options = {});

}  // namespace flatland::calibration
