// The disk tracker's speed-accuracy trade. The scene's motion is simulated once and filmed by its
// camera at several exposure times (motion blur); every frame gets read noise at several levels
// (the same random numbers scaled, so that levels differ only in size); every tracking method
// follows each sequence from its first frame. Centre error against the renderer's truth (px, and
// mm on the table through the camera), per-frame latency (wall) and lost frames per (method,
// exposure, noise) (docs/ACCURACY.md).
#pragma once

#include "flatland/model/model.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/vision/tracker.hpp"

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace flatland::studies {

/// A tracked centre this far from the truth (px) is a wrong lock, not an inaccuracy.
inline constexpr double kGrossErrorPx = 2.0;

struct TrackerStudyMethod {
  std::string name;  ///< CSV/JSON label
  vision::TrackMethod method = vision::TrackMethod::kEdge;
  bool table_plane = false;  ///< the edge fit on the table plane (the camera known), as `track`
  /// The edge fit with one pass from a close guess (TrackerConfig::second_pass_shift_px = 1 px;
  /// the default casts both), to measure what the shortcut gives up in accuracy and in its sigma.
  bool one_pass = false;
};

/// What the study measures: the methods edge, edge-one-pass, edge-plane, moments, hough and the
/// contour peer (TrackMethod::kContour); read noise 0-64 DN
/// (quick: 0, 2, 8, 32); exposures of 0, 1/4, 1/2 and 1 frame interval (quick: 0 and 1); every
/// frame of the camera's rate (quick: every third).
struct TrackerStudyGrid {
  std::vector<TrackerStudyMethod> methods;
  std::vector<double> noises;  ///< DN
  /// exposure, of the frame interval (an interlaced camera's: of the field interval)
  std::vector<double> fractions;
  int stride = 1;
};
TrackerStudyGrid tracker_study_grid(bool quick);

struct TrackerStudyBlur {
  double fraction = 0;  ///< of the frame interval (interlaced: of the field interval)
  double exposure = 0;  ///< s
  int subframes = 1;
  double px_mean = 0, px_max = 0;  ///< streak of the disk centre over the exposure
  /// The mean of the sub-frames' projected centres minus the projected centre at mid-exposure
  /// (the truth): what a perfect tracker of the smeared disk is off by, from the motion's
  /// acceleration and curvature over the exposure. RMS and max over the frames.
  double shift_rms = 0, shift_max = 0;
};

struct TrackerStudyCell {
  std::size_t method = 0, blur = 0, noise = 0;  ///< indices into the grid and blurs
  int frames = 0, lost = 0, reacquired = 0, gross = 0;
  std::vector<double> err_px, err_mm, ms;  ///< per tracked frame
  std::vector<double> sigma_px;            ///< the tracker's sigma_px, per tracked frame
  double rms_px = NAN, max_px = NAN, rms_mm = NAN, max_mm = NAN;
  /// Whether the tracker's sigma tells the truth: the median of sigma_px, and of |error| / sigma_px
  /// over the tracked frames, and the share of them with |error| > 3 sigma_px. sigma_px is each
  /// coordinate's standard deviation, so for a true sigma |error| / sigma is Rayleigh distributed:
  /// median sqrt(2 ln 2) = 1.18, beyond 3 in exp(-4.5) = 1.1 % of frames.
  double sigma_median_px = NAN, z_median = NAN, beyond_3_sigma = NAN;
  double ms_median = NAN, ms_p95 = NAN, ms_max = NAN;
};

struct TrackerStudyOptions {
  bool quick = false;
  sim::Progress progress;  ///< (frames rendered, frames in all exposures)
};

struct TrackerStudyResult {
  TrackerStudyGrid grid;
  std::vector<double> times;  ///< s, the frames' capture times
  std::vector<TrackerStudyBlur> blurs;
  /// Ordered by (method, blur, noise): each curve of a plot (a method at an exposure, against
  /// noise) is consecutive rows.
  std::vector<TrackerStudyCell> cells;
  std::string gl;
  double frame_interval_s = 0, duration_s = 0;
  std::uint64_t seed = 0;  ///< the scene's effects.seed: the noise
  double wall_seconds = 0, load_start = NAN, load_end = NAN;
};

/// The study on a compiled scene with a camera (std::invalid_argument otherwise, or when its run
/// gives fewer than 3 frames); std::runtime_error without GL.
TrackerStudyResult run_tracker_study(const model::Model& model,
                                     const TrackerStudyOptions& options = {});

/// tracker.csv: one row per cell.
std::string tracker_study_csv(const TrackerStudyResult& result);

}  // namespace flatland::studies
