// A calibration session: the images a lab takes to calibrate the FLATLAND camera, its table and
// its joint, and the two CSV files that say what each image shows. `render_calibration_session`
// films one synthetic session of a scene (with its exact truth), and `read_table_csv` /
// `read_joint_csv` read the CSV files of a real or synthetic session for `flatland calibrate`.
// Formats: docs/CALIBRATION.md.
#pragma once

#include "flatland/calibration/camera_file.hpp"
#include "flatland/calibration/intrinsics.hpp"
#include "flatland/scene/scene.hpp"

#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace flatland::calibration {

/// A board lying flat on the table at a known place: one row of table.csv.
struct TablePlacement {
  std::string image;  ///< path (in a CSV: relative to the CSV's directory)
  /// m: the board's origin in the table frame, as a scene's `targets[i].position`: the outer
  /// corner of its square grid from which its rows run along its x axis.
  double x = 0, y = 0, z = 0;
  double yaw = 0;  ///< rad: the board's x axis from the table's x axis, about the table normal
  /// The board placed here as a scene target (for render::target_corners).
  TargetSpec target(const BoardSpec& board) const;
};

/// The hand at a known encoder reading: one row of joint.csv.
struct JointImage {
  std::string image;   ///< path (in a CSV: relative to the CSV's directory)
  double encoder = 0;  ///< rad, the encoder's reading when the image was taken
};

/// table.csv: header `image,x,y,yaw` with an optional `z` column (any order), one row per image.
/// Image paths are returned resolved against the CSV's directory. Throws std::invalid_argument
/// "<path>:<line>: <reason>" (one line) for a missing or unknown column, a bad number, an empty
/// file, a file over 1 MiB or over 10 000 rows.
std::vector<TablePlacement> read_table_csv(const std::string& path);
/// joint.csv: header `image,encoder`; the same rules.
std::vector<JointImage> read_joint_csv(const std::string& path);
std::string table_csv(const std::vector<TablePlacement>& rows);
std::string joint_csv(const std::vector<JointImage>& rows);

struct SessionOptions {
  int intrinsics_views = 16;  ///< the board held at random poses facing the camera
  int table_views = 4;        ///< the board lying on the table, placements spread over the view
  int joint_views = 8;        ///< the hand at encoder angles spread over a half turn
  std::uint64_t seed = 1;     ///< poses, placements and sensor noise
  /// The board; empty: OpenCV's sample chessboard (9x6 inner corners) with its square sized so
  /// that the board spans about a quarter of the view's width on the table.
  std::string board;
};

/// What a rendered session holds; its images went to the sink.
struct CalibrationSession {
  BoardSpec board;
  std::vector<std::string> intrinsics_images;
  std::vector<TablePlacement> table;
  std::vector<JointImage> joint;
  CameraFile truth;  ///< the scene's camera: intrinsics, table pose, joint axis (0, 0), offset 0
};

/// Receives each image (8-bit BGR) under its path relative to the session's directory
/// ("intrinsics/view_00.png", "table/board_0.png", "joint/hand_0.png"), in order.
using SessionImageSink = std::function<void(const std::string& path, const cv::Mat& image)>;

/// Render one session of `scene` (which needs a camera) through its effects (noise, anti-
/// aliasing): intrinsics views in which the board is detected, table views with the hand turned
/// across the view out of the boards' way, joint views with no board, the disk out of view in
/// all. The hand pivots at the table origin and its encoder reads the true hand angle. Throws
/// std::invalid_argument for counts out of range ([3, 200] intrinsics views, [1, 50] table,
/// [3, 100] joint), a bad board, or a camera that cannot see a board whole;
/// std::runtime_error when no GL context can be made.
CalibrationSession render_calibration_session(const Scene& scene, const SessionOptions& options,
                                              const SessionImageSink& sink);

}  // namespace flatland::calibration
