// A calibration session: the images a lab takes to calibrate the FLATLAND camera, its table and
// its joint, and the two CSV files that say what each image shows. `read_table_csv` /
// `read_joint_csv` read the CSV files of a real or synthetic session for `flatland calibrate`
// (drivers::render_calibration_session films a synthetic one). Formats: docs/CALIBRATION.md.
#pragma once

#include "flatland/camera/board.hpp"

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
  /// The board lying here (camera::corners_in_table gives its inner corners).
  camera::PlacedBoard placed(const camera::Board& board) const;
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

}  // namespace flatland::calibration
