// Camera files: YAML in the ROS camera_info layout (image_width, image_height, camera_name,
// camera_matrix, distortion_model, distortion_coefficients) plus flatland's extras (table pose,
// joint axis, encoder offset, calibration report). Written by OpenCV's FileStorage (its "%YAML:1.0"
// flavour), read with yaml-cpp: OpenCV 4.6's YAML reader hangs on some malformed files.
#pragma once

#include "flatland/camera/camera_model.hpp"

#include <opencv2/core.hpp>

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace flatland::camera {

/// The joint seen from the table frame (from `calibrate_joint`).
struct JointCalibration {
  cv::Point2d axis_table{0, 0};  ///< m, joint axis position in the table frame
  double encoder_offset = 0;     ///< rad: true hand angle = encoder angle + offset
};

/// What a calibration produced, with its uncertainty.
struct CalibrationReport {
  double rms_px = 0;
  std::vector<double> view_rms_px;
  int views_used = 0;
  std::vector<std::string> views_rejected;  ///< file names (or indices) and why
  /// Standard deviations from Ceres' covariance: fx, fy, cx, cy, k1, k2, p1, p2, k3.
  std::array<double, 9> std{};
  std::optional<std::array<double, 3>> std_rational;  ///< k4, k5, k6 (rational model only)
};

/// How the table pose was fitted (flatland calibrate --table).
struct TablePoseReport {
  double rms_px = 0;  ///< reprojection RMS of the boards' inner corners
  int corners = 0;    ///< inner corners used
  int images = 0;     ///< board placements
  /// Covariance of (table_rvec, table_tvec) (rad, m) with the intrinsics held, row-major 6 x 6,
  /// when the fit reported one: the joint fit propagates it to the axis's sigma.
  std::optional<std::array<double, 36>> covariance;
  /// d(table_rvec, table_tvec) / d(intrinsic k), 6 numbers per intrinsic in the order of `std`
  /// (fx fy cx cy k1 k2 p1 p2 k3 [k4 k5 k6]): how the fit moved the pose for a changed intrinsic.
  std::vector<double> sensitivity;
};

/// How the joint was fitted (flatland calibrate --joint; calibrate_joint's JointReport in short).
struct JointFitReport {
  int images = 0, inliers = 0;
  double center_rms_m = 0;      ///< RMS distance of the measured hand centres from the axis
  double angle_rms_rad = 0;     ///< RMS of measured - (encoder + offset)
  double sigma_axis_m = 0;      ///< 1-sigma of each axis coordinate
  double sigma_offset_rad = 0;  ///< 1-sigma of the encoder offset
};

struct CameraFile {
  std::string camera_name = "flatland";
  CameraModel camera;  ///< width, height, K, dist; R, t = table pose when known
  /// distortion_model rational_polynomial (8 coefficients) rather than plumb_bob (5); written so
  /// whenever camera.rational() too.
  bool rational_model = false;
  bool has_table_pose = false;
  std::optional<JointCalibration> joint;
  std::optional<CalibrationReport> report;  ///< of the intrinsics
  std::optional<TablePoseReport> table_report;
  std::optional<JointFitReport> joint_report;
  /// Sections written although their data did not support them (`calibrate --force`), each
  /// "<section>: <why>" (section intrinsics, table or joint): `flatland.unsupported` in the file.
  /// Readers of the file report them (flatland track warns); docs/CALIBRATION.md.
  std::vector<std::string> unsupported;
};

/// Write atomically (temp file + rename). Throws std::runtime_error on I/O failure.
void write_camera_file(const std::string& path, const CameraFile& file);
/// Read and validate; throws std::invalid_argument "<path>: <field>: <reason>" on bad content
/// (missing keys, wrong sizes, non-positive focal lengths, unknown distortion model).
CameraFile read_camera_file(const std::string& path);
/// The same from the file's text; `origin` (a path, or "<string>") starts every error message.
/// Throws only std::invalid_argument, whatever the bytes (fuzzed: fuzz/camera_file_fuzzer.cpp).
CameraFile parse_camera_file(const std::string& text, const std::string& origin = "<string>");

}  // namespace flatland::camera
