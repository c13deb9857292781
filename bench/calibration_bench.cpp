// Calibration wall time for 20 rendered chessboard views: flatland's Ceres calibration (both
// passes, with and without the covariance) against cv::calibrateCamera on the same corners.
// Results: docs/CALIBRATION.md.
#include "flatland/calibration/intrinsics.hpp"
#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"

#include <benchmark/benchmark.h>
#include <opencv2/calib3d.hpp>

#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>

using namespace flatland;
using namespace flatland::calibration;

namespace {

// The test suite's setup (tests/calibration/test_calibration_intrinsics.cpp): fx = fy = 800 px, barrel
// distortion, a 16 x 12 chessboard of 25 mm squares tilted 15-45 deg, 4 x 4 anti-aliasing,
// sigma = 1 DN noise.
const std::vector<BoardView>& views() {
  static const std::vector<BoardView> v = [] {
    CameraSpec cam;
    cam.width = 640;
    cam.height = 480;
    cam.fx = cam.fy = 800;
    cam.cx = 322.5;
    cam.cy = 237.5;
    cam.distortion = {-0.2, 0.08, 0.001, -0.0005, 0.0};
    cam.position = {0.0, 0.0, 1.0};
    const camera::CameraModel model = flatland::model::compile_camera(cam);
    const camera::Board board = camera::Board::parse("chessboard:15x11:0.025");
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> U(0.0, 1.0);
    std::vector<BoardView> out;
    const double w = 0.4, h = 0.3, m = 0.025;
    while (out.size() < 20) {
      const double z = 0.05 + 0.25 * U(rng);
      const double tilt = (15 + 30 * U(rng)) * std::numbers::pi / 180;
      const double phi = 2 * std::numbers::pi * U(rng), psi = U(rng) - 0.5;
      const cv::Point2d c(-0.32 + 0.64 * U(rng), -0.24 + 0.48 * U(rng));
      cv::Matx33d Rt, Rz;
      cv::Rodrigues(cv::Vec3d(tilt * std::cos(phi), tilt * std::sin(phi), 0), Rt);
      cv::Rodrigues(cv::Vec3d(0, 0, psi), Rz);
      const cv::Matx33d R = Rt * Rz;
      const cv::Vec3d origin = cv::Vec3d(c.x, c.y, z) - R * cv::Vec3d(w / 2, h / 2, 0);
      bool inside = true;
      for (double bx : {-m, w + m})
        for (double by : {-m, h + m}) {
          const cv::Vec3d p = origin + R * cv::Vec3d(bx, by, 0);
          const cv::Point2d px = model.project(cv::Point3d(p[0], p[1], p[2]));
          inside = inside && px.x > 12 && px.x < 627 && px.y > 12 && px.y < 467;
        }
      if (!inside) continue;
      TargetSpec t;
      t.squares_x = 16;
      t.squares_y = 12;
      t.square = 0.025;
      cv::Vec3d rv;
      cv::Rodrigues(R, rv);
      t.position = {origin[0], origin[1], origin[2]};
      t.rotation = {rv[0], rv[1], rv[2]};
      Scene s;
      s.camera = cam;
      s.effects.supersample = 4;
      s.targets = {t};
      render::Renderer r(flatland::model::render_setup(*flatland::model::compile(s)));
      render::SceneState state;
      state.disk_center = {5.0, 5.0};
      cv::Mat linear = r.render_linear(state);
      render::EffectsRng noise(out.size() + 1);
      render::apply_noise(linear, 1.0, 0.0, noise);
      if (auto d = detect_board(render::quantize(linear), board)) out.push_back(*d);
    }
    return out;
  }();
  return v;
}

void BM_CeresCalibration(benchmark::State& state) {
  const auto& v = views();
  IntrinsicsOptions o;
  o.compute_covariance = state.range(0) != 0;
  for (auto _ : state) benchmark::DoNotOptimize(calibrate_intrinsics(v, o).rms_px);
  state.SetLabel(o.compute_covariance ? "20 views, with covariance" : "20 views, no covariance");
}
BENCHMARK(BM_CeresCalibration)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond);

void BM_OpenCvCalibrateCamera(benchmark::State& state) {
  const auto& v = views();
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  for (const BoardView& b : v) {
    obj.push_back(b.object_points);
    img.push_back(b.image_points);
  }
  for (auto _ : state) {
    cv::Mat K, dist;
    std::vector<cv::Mat> rv, tv;
    benchmark::DoNotOptimize(cv::calibrateCamera(obj, img, v[0].image_size, K, dist, rv, tv, 0));
  }
  state.SetLabel("20 views, same corners");
}
BENCHMARK(BM_OpenCvCalibrateCamera)->Unit(benchmark::kMillisecond);

void BM_DetectChessboard(benchmark::State& state) {
  // Detection is outside the comparison above; this is what it adds per image.
  CameraSpec cam;
  cam.fx = cam.fy = 800;
  cam.position = {0.0, 0.0, 1.0};
  TargetSpec t;
  t.squares_x = 16;
  t.squares_y = 12;
  t.square = 0.025;
  t.position = {-0.2, -0.15, 0.1};
  t.rotation = {0.3, 0.2, 0.05};
  Scene s;
  s.camera = cam;
  s.effects.supersample = 2;
  s.targets = {t};
  render::Renderer r(flatland::model::render_setup(*flatland::model::compile(s)));
  render::SceneState st;
  st.disk_center = {5.0, 5.0};
  const cv::Mat image = r.render_8u(st);
  const camera::Board board = camera::Board::parse("chessboard:15x11:0.025");
  for (auto _ : state) benchmark::DoNotOptimize(detect_board(image, board));
}
BENCHMARK(BM_DetectChessboard)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
