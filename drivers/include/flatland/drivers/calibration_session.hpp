// A synthetic calibration session: the images a lab takes to calibrate the FLATLAND camera, its
// table and its joint, rendered from a scene with their exact truth, for `flatland calibrate`
// (`flatland render-calibration`; docs/CALIBRATION.md).
#pragma once

#include "flatland/calibration/session.hpp"
#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/model/model.hpp"

#include <opencv2/core.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace flatland::drivers {

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
  camera::Board board;
  std::vector<std::string> intrinsics_images;
  std::vector<calibration::TablePlacement> table;
  std::vector<calibration::JointImage> joint;
  camera::CameraFile
      truth;  ///< the scene's camera: intrinsics, table pose, joint axis (0, 0), offset 0
};

/// Receives each image (8-bit BGR) under its path relative to the session's directory
/// ("intrinsics/view_00.png", "table/board_0.png", "joint/hand_0.png"), in order.
using SessionImageSink = std::function<void(const std::string& path, const cv::Mat& image)>;

/// Render one session of a compiled scene (which needs a camera) through its effects (noise, anti-
/// aliasing): intrinsics views in which the board is detected, table views with the hand turned
/// across the view out of the boards' way, joint views with no board, the disk out of view in
/// all. The hand pivots at the table origin and its encoder reads the true hand angle. Throws
/// std::invalid_argument for counts out of range ([3, 200] intrinsics views, [1, 50] table,
/// [3, 100] joint), a bad board, or a camera that cannot see a board whole;
/// std::runtime_error when no GL context can be made.
CalibrationSession render_calibration_session(const model::Model& model,
                                              const SessionOptions& options,
                                              const SessionImageSink& sink);

}  // namespace flatland::drivers
