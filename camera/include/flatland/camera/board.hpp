// Calibration boards: a board's kind and size (counted as OpenCV counts them), where it lies in
// the table frame, its inner corners, and OpenCV's table of predefined ArUco dictionaries. One
// type for every module: the renderer draws a PlacedBoard, calibration detects a Board and fits
// the table pose to a PlacedBoard's corners.
#pragma once

#include <opencv2/core.hpp>

#include <optional>
#include <string>
#include <vector>

namespace flatland::camera {

/// A planar calibration board. Its size is kept in squares (as cv::aruco::CharucoBoard's
/// squaresX, squaresY), so it has (squares_x - 1) x (squares_y - 1) inner corners. The notation
/// counts as OpenCV does: a chessboard by its inner corners (patternSize of
/// cv::findChessboardCorners, ROS camera_calibration --size), a ChArUco board by its squares.
struct Board {
  enum class Kind { kChessboard, kCharuco };
  Kind kind = Kind::kChessboard;
  int squares_x = 10, squares_y = 7;       ///< OpenCV's sample chessboard: 9x6 inner corners
  double square = 0.02;                    ///< m
  double marker = 0.015;                   ///< m (ChArUco marker side)
  std::string dictionary = "DICT_4X4_50";  ///< OpenCV predefined dictionary (ChArUco)

  /// "chessboard:COLSxROWS:SQUARE_M" (COLS x ROWS inner corners, each at least 3, as
  /// cv::findChessboardCorners needs) or "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]" (squares).
  /// Throws std::invalid_argument "OPTION: ..." naming what is wrong (`option`: the command-line
  /// option or field the text came from).
  static Board parse(const std::string& text, const std::string& option = "--board");
  /// The notation parse() reads, e.g. "chessboard:9x6:0.025".
  std::string notation() const;
  /// The board the same notation means in the other count: for a chessboard given in inner
  /// corners, the one whose squares those are (one corner fewer each way); for a ChArUco board
  /// given in squares, the one whose inner corners those are (one square more). For the hint when
  /// a board is found nowhere. nullopt when that board would be too small to detect.
  std::optional<Board> other_count() const;
  /// Inner corners per row and rows of them: cv::findChessboardCorners' patternSize.
  cv::Size pattern_size() const { return {squares_x - 1, squares_y - 1}; }
  /// Inner corners in the board plane (z = 0), OpenCV's order: corner k at
  /// ((k % (squares_x-1)) + 1, (k / (squares_x-1)) + 1) * square; for ChArUco corner id k.
  std::vector<cv::Point3f> corners() const;
};

/// A board lying in the table frame (a scene's `targets` entry, a table.csv row).
struct PlacedBoard {
  Board board;
  /// m: the board's origin in the table frame, the outer corner of its square grid from which
  /// its rows run along its x axis; the board is seen from +z with its y axis up the print.
  cv::Vec3d position{0, 0, 0};
  cv::Vec3d rotation{0, 0, 0};  ///< rad, Rodrigues vector board -> table
};

/// Inner corners of a placed board in the table frame, in OpenCV's order: corner k is OpenCV's
/// object point k (ChArUco corner id k), i.e. row by row from the board's printed top-left. Our
/// board frame is seen from +z with x along the columns and y up; OpenCV's runs y down the printed
/// board: (x, y)_opencv = (x, squares_y*square - y). The truth for chessboard and ChArUco corner
/// detection and calibration.
std::vector<cv::Point3d> corners_in_table(const PlacedBoard& placed);

/// OpenCV's predefined ArUco dictionaries, in cv::aruco::PREDEFINED_DICTIONARY_NAME order.
const std::vector<std::string>& aruco_dictionary_names();
/// The cv::aruco::PREDEFINED_DICTIONARY_NAME of `name`; nullopt for a name OpenCV does not have.
std::optional<int> aruco_dictionary_id(const std::string& name);

}  // namespace flatland::camera
