// The intrinsics calibration study (calibration_study.hpp).
#include "flatland/studies/calibration_study.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <random>

namespace flatland::studies {

namespace {

using sim::format_number;

/// `n` views of a chessboard of 9 x 6 inner corners (25 mm squares) at random poses (0.35-0.8 m
/// away, tilted 15-45 deg), every corner at least 10 px inside the image, projected through the
/// truth with cv::projectPoints and perturbed by Gaussian noise of `sigma` px per coordinate.
std::vector<calibration::BoardView> synthetic_views(const CalibrationStudyCamera& truth, int n,
                                                    double sigma, std::mt19937_64& rng) {
  std::vector<cv::Point3f> board;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 9; ++c) board.emplace_back(0.025f * c, 0.025f * r, 0.f);
  std::uniform_real_distribution<double> U(0, 1);
  std::normal_distribution<double> N(0, 1);
  std::vector<calibration::BoardView> views;
  while (static_cast<int>(views.size()) < n) {
    const double tilt = (15 + 30 * U(rng)) * std::numbers::pi / 180,
                 phi = 2 * std::numbers::pi * U(rng);
    const cv::Vec3d rvec(tilt * std::cos(phi), tilt * std::sin(phi), U(rng) - 0.5);
    const double z = 0.35 + 0.45 * U(rng);
    const cv::Vec3d tvec((U(rng) - 0.5) * 0.6 * z - 0.1, (U(rng) - 0.5) * 0.45 * z - 0.06, z);
    std::vector<cv::Point2f> px;
    cv::projectPoints(board, rvec, tvec, truth.K, truth.dist, px);
    bool inside = true;
    for (const auto& p : px)
      inside = inside && p.x >= 10 && p.y >= 10 && p.x <= truth.size.width - 11 &&
               p.y <= truth.size.height - 11;
    if (!inside) continue;
    for (auto& p : px) {
      p.x += static_cast<float>(sigma * N(rng));
      p.y += static_cast<float>(sigma * N(rng));
    }
    calibration::BoardView v;
    v.name = "view" + std::to_string(views.size());
    v.image_size = truth.size;
    v.image_points = std::move(px);
    v.object_points = board;
    views.push_back(std::move(v));
  }
  return views;
}

CalibrationStudyCell measure(const CalibrationStudyCamera& truth, int nv, double sigma,
                             int trials) {
  std::mt19937_64 rng(1000 * nv + static_cast<int>(sigma * 100));
  const std::array<double, 6> truth_p = truth.parameters();
  double sq[6] = {}, mx[6] = {}, rms = 0, time = 0;
  int ok = 0;
  CalibrationStudyCell cell;
  cell.views = nv;
  cell.noise_px = sigma;
  cell.trials = trials;
  for (int t = 0; t < trials; ++t) {
    const auto views = synthetic_views(truth, nv, sigma, rng);
    calibration::IntrinsicsOptions opt;
    opt.compute_covariance = false;  // timed: the estimate, not its uncertainty
    const auto t0 = std::chrono::steady_clock::now();
    try {
      const calibration::IntrinsicsResult r = calibration::calibrate_intrinsics(views, opt);
      time += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const auto p = r.params();
      for (int i = 0; i < 6; ++i) {
        const auto k = static_cast<std::size_t>(i);
        const double e = std::abs(p[k] - truth_p[k]);
        sq[i] += e * e;
        mx[i] = std::max(mx[i], e);
      }
      rms += r.rms_px;
      ++ok;
    } catch (const std::exception&) {
      ++cell.failures;
    }
  }
  for (std::size_t i = 0; i < 6; ++i) {
    cell.rms_error[i] = ok ? std::sqrt(sq[i] / ok) : std::nan("");
    cell.max_error[i] = ok ? mx[i] : std::nan("");
  }
  cell.rms_px = ok ? rms / ok : std::nan("");
  cell.time_s = ok ? time / ok : std::nan("");
  return cell;
}

}  // namespace

CalibrationStudyGrid calibration_study_grid(bool quick) {
  return {{5, 10, 20, 40}, {0, 0.1, 0.3, 1}, quick ? 2 : 8};
}

CalibrationStudyResult run_calibration_study(const CalibrationStudyOptions& options) {
  CalibrationStudyResult out;
  out.grid = calibration_study_grid(options.quick);
  const long total = static_cast<long>(out.grid.views.size() * out.grid.noises.size());
  for (int nv : out.grid.views)
    for (double sigma : out.grid.noises) {
      out.cells.push_back(measure(out.truth, nv, sigma, out.grid.trials));
      if (options.progress) options.progress(static_cast<long>(out.cells.size()), total);
    }
  return out;
}

std::string calibration_study_csv(const CalibrationStudyResult& result) {
  std::string csv = "views,noise_px,trials,failures";
  for (const char* nm : kCalibrationParameters)
    csv += std::string(",rms_err_") + nm + ",max_err_" + nm;
  csv += ",rms_px,time_s\n";
  for (const CalibrationStudyCell& c : result.cells) {
    std::string line = std::to_string(c.views) + "," + format_number(c.noise_px) + "," +
                       std::to_string(c.trials) + "," + std::to_string(c.failures);
    for (std::size_t i = 0; i < 6; ++i) {
      // Appended piecewise: GCC 12 warns (-Wrestrict, a false positive) on "," + string here.
      line += ',';
      line += format_number(c.rms_error[i]);
      line += ',';
      line += format_number(c.max_error[i]);
    }
    for (double v : {c.rms_px, c.time_s}) {
      line += ',';
      line += format_number(v);
    }
    line += '\n';
    csv += line;
  }
  return csv;
}

}  // namespace flatland::studies
