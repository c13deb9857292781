// Calibration boards: notation, corners, placement in the table frame, ArUco dictionaries.
#include "flatland/camera/board.hpp"

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::camera {

namespace {

int parse_int(const std::string& s, const std::string& what, const std::string& option) {
  std::size_t used = 0;
  int v = 0;
  try {
    v = std::stoi(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != s.size())
    throw std::invalid_argument(option + ": " + what + ": not an integer: '" + s + "'");
  return v;
}

double parse_double(const std::string& s, const std::string& what, const std::string& option) {
  std::size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != s.size() || !std::isfinite(v))
    throw std::invalid_argument(option + ": " + what + ": not a number: '" + s + "'");
  return v;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == sep) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

std::string size_text(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

std::string fmt(double v, int precision) {
  std::ostringstream os;
  os.precision(precision);
  os << v;
  return os.str();
}

}  // namespace

Board Board::parse(const std::string& text, const std::string& option) {
  const std::vector<std::string> f = split(text, ':');
  Board b;
  if (f[0] == "chessboard") {
    b.kind = Kind::kChessboard;
    if (f.size() != 3)
      throw std::invalid_argument(option + ": expected chessboard:COLSxROWS:SQUARE_M, got '" +
                                  text + "'");
  } else if (f[0] == "charuco") {
    b.kind = Kind::kCharuco;
    if (f.size() != 4 && f.size() != 5)
      throw std::invalid_argument(
          option + ": expected charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT], got '" + text + "'");
  } else {
    throw std::invalid_argument(option + ": unknown board type '" + f[0] +
                                "' (chessboard or charuco)");
  }
  // Counted as OpenCV counts them: a chessboard by its inner corners (the patternSize of
  // cv::findChessboardCorners and ROS camera_calibration's --size), a ChArUco board by its squares
  // (cv::aruco::CharucoBoard's squaresX, squaresY).
  const bool chessboard = b.kind == Kind::kChessboard;
  const char* unit = chessboard ? "inner corners" : "squares";
  const std::vector<std::string> dims = split(f[1], 'x');
  if (dims.size() != 2)
    throw std::invalid_argument(option + ": expected COLSxROWS (" + unit + "), got '" + f[1] + "'");
  const int cols = parse_int(dims[0], "COLS", option);
  const int rows = parse_int(dims[1], "ROWS", option);
  // cv::findChessboardCorners refuses a pattern narrower than 3 corners; a ChArUco board needs
  // 2x2 squares for one inner corner.
  const int least = chessboard ? 3 : 2;
  constexpr int kMost = 999;
  if (cols < least || rows < least || cols > kMost || rows > kMost)
    throw std::invalid_argument(option + ": COLSxROWS counts " + std::string(unit) +
                                " and must be " + std::to_string(least) + " to " +
                                std::to_string(kMost) + " each, got " + f[1]);
  b.squares_x = chessboard ? cols + 1 : cols;
  b.squares_y = chessboard ? rows + 1 : rows;
  b.square = parse_double(f[2], "SQUARE_M", option);
  if (!(b.square > 0)) throw std::invalid_argument(option + ": SQUARE_M must be positive (m)");
  if (b.kind == Kind::kCharuco) {
    b.marker = parse_double(f[3], "MARKER_M", option);
    if (!(b.marker > 0 && b.marker < b.square))
      throw std::invalid_argument(option + ": MARKER_M must be in (0, SQUARE_M) (m)");
    if (f.size() == 5) {
      if (!aruco_dictionary_id(f[4]))
        throw std::invalid_argument(option + ": unknown ArUco dictionary '" + f[4] + "'");
      b.dictionary = f[4];
    }
  }
  return b;
}

std::string Board::notation() const {
  const cv::Size n = kind == Kind::kChessboard ? pattern_size() : cv::Size(squares_x, squares_y);
  std::string s = std::string(kind == Kind::kChessboard ? "chessboard:" : "charuco:") +
                  size_text(n) + ":" + fmt(square, 6);
  // Appended piece by piece: GCC 12's -Wrestrict misfires on "literal" + std::string&&.
  if (kind == Kind::kCharuco) s.append(":").append(fmt(marker, 6)).append(":").append(dictionary);
  return s;
}

std::optional<Board> Board::other_count() const {
  Board b = *this;
  const int step = kind == Kind::kChessboard ? -1 : 1;
  b.squares_x += step;
  b.squares_y += step;
  const int least_squares = kind == Kind::kChessboard ? 4 : 2;
  if (b.squares_x < least_squares || b.squares_y < least_squares) return std::nullopt;
  return b;
}

std::vector<cv::Point3f> Board::corners() const {
  // As cv::aruco::CharucoBoard::chessboardCorners: inner corner (c, r) at ((c+1), (r+1)) squares
  // from the printed top-left outer corner, rows running down the print.
  std::vector<cv::Point3f> out;
  for (int r = 0; r < squares_y - 1; ++r)
    for (int c = 0; c < squares_x - 1; ++c)
      out.emplace_back(static_cast<float>((c + 1) * square), static_cast<float>((r + 1) * square),
                       0.0f);
  return out;
}

std::vector<cv::Point3d> corners_in_table(const PlacedBoard& placed) {
  const Board& b = placed.board;
  cv::Matx33d R;
  cv::Rodrigues(placed.rotation, R);
  std::vector<cv::Point3d> out;
  // OpenCV's board frame (object points, ChArUco corner ids) runs y down the printed board with
  // z into it; ours is seen from +z with y up: (x, y)_opencv = (x, rows * square - y)_ours.
  for (int r = 1; r < b.squares_y; ++r)
    for (int c = 1; c < b.squares_x; ++c) {
      const cv::Vec3d q =
          R * cv::Vec3d(c * b.square, (b.squares_y - r) * b.square, 0) + placed.position;
      out.emplace_back(q[0], q[1], q[2]);
    }
  return out;
}

const std::vector<std::string>& aruco_dictionary_names() {
  static const std::vector<std::string> names = {
      "DICT_4X4_50",         "DICT_4X4_100",       "DICT_4X4_250",       "DICT_4X4_1000",
      "DICT_5X5_50",         "DICT_5X5_100",       "DICT_5X5_250",       "DICT_5X5_1000",
      "DICT_6X6_50",         "DICT_6X6_100",       "DICT_6X6_250",       "DICT_6X6_1000",
      "DICT_7X7_50",         "DICT_7X7_100",       "DICT_7X7_250",       "DICT_7X7_1000",
      "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10",
      "DICT_APRILTAG_36h11"};
  return names;
}

std::optional<int> aruco_dictionary_id(const std::string& name) {
  const auto& names = aruco_dictionary_names();
  for (std::size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) return static_cast<int>(i);
  return std::nullopt;
}

}  // namespace flatland::camera
