// The renderer's geometric accuracy and speed against supersampling and resolution: the intensity
// centroid of the disk's face in render_8u frames against cv::projectPoints of its centre, at
// seeded disk positions on the free table, and frames per second rendered back to back
// (docs/ACCURACY.md).
#pragma once

#include "flatland/model/model.hpp"
#include "flatland/sim/search.hpp"

#include <opencv2/core.hpp>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace flatland::studies {

/// px: the renderer's acceptance bound on the centroid error (tests/render/test_render.cpp).
inline constexpr double kRenderAcceptancePx = 0.05;

struct RenderStudyPosition {
  cv::Point2d table;  ///< m, disk centre
  double angle = 0;   ///< rad, the disk's turn (where its marker is)
};

struct RenderStudyCell {
  int supersample = 1;
  double scale = 1;  ///< of the scene's image size
  int width = 0, height = 0;
  double fx = 0, radius_px = 0;
  int positions = 0, frames = 0;                                    ///< frames: timed renders
  double err_rms = NAN, err_max = NAN, bias_x = NAN, bias_y = NAN;  ///< px
  double ms_median = NAN, ms_p95 = NAN, fps_median = NAN, fps_mean = NAN;  ///< wall
};

/// What the study measures: supersampling factors 1-4 (quick: 1, 2, 4) at image scales 0.5, 1
/// and 2 (quick: 0.5, 1), each at 24 disk positions (quick: 4) turned two ways, rendered back to
/// back for at least 0.5 s per cell (quick: 0.05 s).
struct RenderStudyGrid {
  std::vector<int> factors;
  std::vector<double> scales;
  int positions = 0;
  double timing_seconds = 0;
};
RenderStudyGrid render_study_grid(bool quick);

struct RenderStudyOptions {
  bool quick = false;  ///< factors 1, 2, 4 at scales 0.5, 1 with 4 positions (else 1-4, 0.5-2, 24)
  sim::Progress progress;  ///< (positions measured, positions in all cells)
};

struct RenderStudyResult {
  RenderStudyGrid grid;
  std::vector<cv::Size> resolutions;  ///< per scale
  std::vector<RenderStudyPosition> positions;
  std::vector<RenderStudyCell> cells;  ///< scale-major, then factor
  std::uint64_t seed = 0;              ///< the scene's effects.seed: the positions' draws
  std::string gl;                      ///< the GL context's description
  /// The camera is oblique or distorted: the image of the face is not a scaled copy of it, so
  /// the errors include the projection's own bias, not only the renderer's.
  bool projection_biased = false;
  double wall_seconds = 0, load_start = NAN, load_end = NAN;
};

/// The study on a compiled scene with a camera (std::invalid_argument otherwise, or when the
/// camera sees too little free table for the positions); std::runtime_error without GL.
RenderStudyResult run_render_study(const model::Model& model,
                                   const RenderStudyOptions& options = {});

/// render.csv: one row per cell.
std::string render_study_csv(const RenderStudyResult& result);

}  // namespace flatland::studies
