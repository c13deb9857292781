// The intrinsics calibration's accuracy and cost against the number of views and the corner
// noise: synthetic chessboard corners (cv::projectPoints of a known camera plus Gaussian noise)
// through calibration::calibrate_intrinsics, repeated over seeded trials (docs/ACCURACY.md).
#pragma once

#include "flatland/sim/search.hpp"

#include <opencv2/core.hpp>

#include <array>
#include <string>
#include <vector>

namespace flatland::studies {

/// The camera the corners are projected through: VGA, f = 800 px, an off-centre principal point
/// and barrel distortion, so that every parameter has something to recover.
struct CalibrationStudyCamera {
  cv::Matx33d K{800, 0, 322.5, 0, 800, 237.5, 0, 0, 1};
  cv::Vec<double, 5> dist{-0.2, 0.08, 0.001, -0.0005, 0.0};
  cv::Size size{640, 480};
  /// fx, fy, cx, cy, k1, k2: the parameters the study scores.
  std::array<double, 6> parameters() const {
    return {K(0, 0), K(1, 1), K(0, 2), K(1, 2), dist[0], dist[1]};
  }
};
/// The scored parameters' names, in parameters() order.
inline constexpr std::array<const char*, 6> kCalibrationParameters = {"fx", "fy", "cx",
                                                                      "cy", "k1", "k2"};

/// One cell: `trials` calibrations from `views` views at `noise_px`.
struct CalibrationStudyCell {
  int views = 0;
  double noise_px = 0;
  int trials = 0, failures = 0;  ///< failures: calibrations that threw
  /// Per parameter (kCalibrationParameters): RMS and largest error over the successful trials
  /// (NaN when none succeeded).
  std::array<double, 6> rms_error{}, max_error{};
  double rms_px = 0;  ///< the calibrations' mean reprojection RMS
  double time_s = 0;  ///< mean wall time of one calibration (without its covariance)
};

/// What the study measures: 5, 10, 20 and 40 views at corner noise 0, 0.1, 0.3 and 1 px, each
/// cell over 8 trials (quick: 2).
struct CalibrationStudyGrid {
  std::vector<int> views;
  std::vector<double> noises;  ///< px
  int trials = 0;
};
CalibrationStudyGrid calibration_study_grid(bool quick);

struct CalibrationStudyOptions {
  bool quick = false;      ///< 2 trials per cell instead of 8
  sim::Progress progress;  ///< (cells done, cells)
};

struct CalibrationStudyResult {
  CalibrationStudyCamera truth;
  CalibrationStudyGrid grid;
  std::vector<CalibrationStudyCell> cells;  ///< views-major, in the grid's order
};

/// The study; each cell's corners come from a std::mt19937_64 seeded by the cell alone.
CalibrationStudyResult run_calibration_study(const CalibrationStudyOptions& options = {});

/// calibration.csv: views, noise_px, trials, failures, rms_err_P and max_err_P per parameter,
/// rms_px, time_s.
std::string calibration_study_csv(const CalibrationStudyResult& result);

}  // namespace flatland::studies
