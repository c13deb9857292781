// Intrinsics calibration against known truth: 20 rendered chessboard views (σ = 1 DN noise) of a
// distorted camera, the same corners through cv::calibrateCamera, outlier views, the bad-input
// errors, ChArUco, and `flatland calibrate` end to end.
#include "cli_support.hpp"
#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/model/compile.hpp"
#include "render_support.hpp"
#include "test_scale.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <numbers>
#include <random>

using namespace flatland;
using namespace flatland::calibration;
namespace fs = std::filesystem;

namespace {

// The camera under test: fx = fy = 800 px, principal point off centre, barrel distortion.
CameraSpec truth_camera() {
  CameraSpec c;
  c.width = 640;
  c.height = 480;
  c.fx = c.fy = 800;
  c.cx = 319.5 + 3;
  c.cy = 239.5 - 2;
  c.distortion = {-0.2, 0.08, 0.001, -0.0005, 0.0};
  c.position = {0.0, 0.0, 1.0};
  c.look_at = {0.0, 0.0, 0.0};
  return c;
}

// Anti-aliasing of the test images. The renderer's corners carry a systematic error that
// dominates the 1 DN noise: measured corner RMS against truth (17 x 17 cornerSubPix window)
// 0.12 px at 2 x 2 samples per pixel, 0.07 px at 4 x 4. The principal point's 0.5 px bound
// needs the latter.
constexpr int kSupersample = 4;

struct RenderedViews {
  std::vector<cv::Mat> images;
  std::vector<TargetSpec> targets;
  std::vector<BoardView> views;  ///< detected, one per image
};

// `n` views of a board at random poses: centred anywhere in the view, 0.05-0.3 m above the
// table, tilted 15-45 deg about a random in-plane axis and turned in-plane by up to 0.5 rad;
// every corner of the printed board (with its margin) at least 12 px inside the image. Poses at
// which the detector misses the board (rare: steep views near the image edge) are replaced.
RenderedViews render_views(const TargetSpec& board_template, const camera::Board& board, int n,
                           std::uint64_t seed) {
  RenderedViews out;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const CameraSpec cam = truth_camera();
  const camera::CameraModel model = flatland::model::compile_camera(cam);
  // One renderer, its board moved from view to view (Renderer::set_boards).
  Scene s;
  s.camera = cam;
  s.effects.supersample = kSupersample;
  s.effects.noise_read_dn = 1.0;
  render::Renderer r(flatland_test::render_setup(s));
  const double w = board_template.squares_x * board_template.square;
  const double h = board_template.squares_y * board_template.square;
  const double m = board_template.kind == TargetSpec::Kind::kChessboard ? board_template.square : 0;
  while (static_cast<int>(out.targets.size()) < n) {
    const double z = 0.05 + 0.25 * U(rng);
    const double tilt = (15 + 30 * U(rng)) * std::numbers::pi / 180;
    const double phi = 2 * std::numbers::pi * U(rng);
    const double psi = (U(rng) - 0.5);
    // Anywhere the board can still be wholly in view (the check below rejects the rest).
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
        inside =
            inside && px.x > 12 && px.x < cam.width - 13 && px.y > 12 && px.y < cam.height - 13;
      }
    if (!inside) continue;
    TargetSpec t = board_template;
    cv::Vec3d rv;
    cv::Rodrigues(R, rv);
    t.position = {origin[0], origin[1], origin[2]};
    t.rotation = {rv[0], rv[1], rv[2]};
    r.set_boards({flatland::model::compile_target(t)});
    render::SceneState state;
    state.disk_center = {5.0, 5.0};  // the disk out of view
    cv::Mat linear = r.render_linear(state);
    render::EffectsRng noise(seed * 1000 + out.targets.size());
    render::apply_noise(linear, s.effects.noise_read_dn, 0.0, noise);
    const cv::Mat image = render::quantize(linear);
    auto found = detect_board(image, board, "view" + std::to_string(out.views.size()));
    if (!found) continue;
    out.images.push_back(image);
    out.targets.push_back(t);
    out.views.push_back(*found);
  }
  return out;
}

TargetSpec chessboard_target() {
  TargetSpec t;
  t.squares_x = 16;
  t.squares_y = 12;
  t.square = 0.025;
  return t;
}

// Rendered once for every test that needs them.
const camera::Board& chessboard_spec() {
  static const camera::Board b = camera::Board::parse("chessboard:15x11:0.025");
  return b;
}

// The first n of the 20 rendered views (the pose sequence is the same for every n), rendered
// once per test process: ctest runs every test in its own process, and at ~1.6 s per view only
// the tests that need all 20 should pay for them.
const RenderedViews& chessboard_views(int n = 20) {
  static RenderedViews cache;
  if (static_cast<int>(cache.views.size()) < n)
    cache = render_views(chessboard_target(), chessboard_spec(), n, 7);
  return cache;
}

std::vector<BoardView> detected_chessboard_views(int n = 20) {
  const std::vector<BoardView>& all = chessboard_views(n).views;
  return std::vector<BoardView>(all.begin(), all.begin() + n);
}

std::array<double, 9> truth_params() {
  const CameraSpec c = truth_camera();
  return {c.fx,
          c.fy,
          c.cx,
          c.cy,
          c.distortion[0],
          c.distortion[1],
          c.distortion[2],
          c.distortion[3],
          c.distortion[4]};
}

const char* kNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};

// Views of a synthetic board projected exactly (no renderer), with Gaussian corner noise.
std::vector<BoardView> projected_views(const std::vector<cv::Vec3d>& rvecs,
                                       const std::vector<cv::Vec3d>& tvecs, double sigma,
                                       cv::Size size = {640, 480}) {
  const CameraSpec c = truth_camera();
  const cv::Matx33d K(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
  const cv::Vec<double, 5> dist(c.distortion.data());
  const std::vector<cv::Point3f> obj = chessboard_spec().corners();
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0.0, sigma);
  std::vector<BoardView> out;
  for (std::size_t i = 0; i < rvecs.size(); ++i) {
    std::vector<cv::Point2f> px;
    cv::projectPoints(obj, rvecs[i], tvecs[i], K, dist, px);
    for (auto& p : px) p += cv::Point2f(static_cast<float>(N(rng)), static_cast<float>(N(rng)));
    out.push_back({"synthetic" + std::to_string(i), size, px, obj});
  }
  return out;
}

std::string expect_invalid(const std::vector<BoardView>& views) {
  try {
    calibrate_intrinsics(views);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "no std::invalid_argument";
  return "";
}

}  // namespace

TEST(CalibrationIntrinsics, BoardSpecParsing) {
  // A chessboard counts inner corners (OpenCV's patternSize), so 9x6 is 10 x 7 squares.
  const camera::Board c = camera::Board::parse("chessboard:9x6:0.02");
  EXPECT_EQ(c.kind, camera::Board::Kind::kChessboard);
  EXPECT_EQ(c.squares_x, 10);
  EXPECT_EQ(c.squares_y, 7);
  EXPECT_EQ(c.pattern_size(), cv::Size(9, 6));
  EXPECT_DOUBLE_EQ(c.square, 0.02);
  EXPECT_EQ(c.corners().size(), 54u);
  EXPECT_EQ(c.notation(), "chessboard:9x6:0.02");
  EXPECT_EQ(camera::Board::parse("chessboard:3x3:0.5").corners().size(), 9u);
  // A ChArUco board counts squares (cv::aruco::CharucoBoard), so 7x5 has 6 x 4 inner corners.
  const camera::Board a = camera::Board::parse("charuco:7x5:0.04:0.03:DICT_5X5_100");
  EXPECT_EQ(a.kind, camera::Board::Kind::kCharuco);
  EXPECT_EQ(a.squares_x, 7);
  EXPECT_EQ(a.squares_y, 5);
  EXPECT_EQ(a.corners().size(), 24u);
  EXPECT_EQ(a.notation(), "charuco:7x5:0.04:0.03:DICT_5X5_100");
  EXPECT_DOUBLE_EQ(a.marker, 0.03);
  EXPECT_EQ(a.dictionary, "DICT_5X5_100");
  EXPECT_EQ(camera::Board::parse("charuco:7x5:0.04:0.03").dictionary, "DICT_4X4_50");
  for (const char* bad :
       {"chess:9x6:0.02", "chessboard:9x6", "chessboard:9by6:0.02", "chessboard:9x6:-1",
        "chessboard:1x6:0.02", "chessboard:2x6:0.02", "chessboard:9x1000:0.02",
        "charuco:1x5:0.04:0.03", "charuco:7x5:0.04", "charuco:7x5:0.04:0.05",
        "charuco:7x5:0.04:0.03:DICT_9X9_1", "chessboard:9x6:abc"})
    EXPECT_THROW(camera::Board::parse(bad), std::invalid_argument) << bad;
}

// The other count reads the same numbers the other way: a chessboard's as squares, a ChArUco
// board's as inner corners.
TEST(CalibrationIntrinsics, BoardOtherCount) {
  const auto chess = camera::Board::parse("chessboard:10x7:0.025").other_count();
  ASSERT_TRUE(chess.has_value());
  EXPECT_EQ(chess->notation(), "chessboard:9x6:0.025");
  EXPECT_FALSE(camera::Board::parse("chessboard:3x5:0.025").other_count().has_value());
  const auto charuco = camera::Board::parse("charuco:6x4:0.04:0.03").other_count();
  ASSERT_TRUE(charuco.has_value());
  EXPECT_EQ(charuco->notation(), "charuco:7x5:0.04:0.03:DICT_4X4_50");
}

// A chessboard is counted as OpenCV's patternSize counts it. A scene's `cols: 9, rows: 6`
// chessboard, rendered, is what cv::findChessboardCorners finds with patternSize 9x6 (and not with
// 10x7, its squares), and `chessboard:9x6` hands detect_board that patternSize: 54 corners, each
// where the camera projects the scene's corner.
TEST(CalibrationIntrinsics, ChessboardNotationIsOpenCvsPatternSize) {
  const std::string board_yaml =
      "targets:\n  - type: chessboard\n    cols: 9\n    rows: 6\n    square: 0.02\n"
      "    position: [-0.1, 0.09, 0.05]\n    rotation: [0.3, 0.2, 0.1]\n";
  const Scene parsed = parse_scene(
      flatland_test::read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly.yaml") +
      board_yaml);
  ASSERT_EQ(parsed.targets.size(), 1u);
  Scene s;
  s.camera = truth_camera();
  s.effects.supersample = 2;
  s.targets = parsed.targets;
  render::Renderer r(flatland_test::render_setup(s));
  render::SceneState state;
  state.disk_center = {5.0, 5.0};  // the disk out of view
  const cv::Mat image = r.render_8u(state);
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> found;
  EXPECT_TRUE(cv::findChessboardCorners(gray, cv::Size(9, 6), found));
  EXPECT_FALSE(cv::findChessboardCorners(gray, cv::Size(10, 7), found));

  const camera::Board board = camera::Board::parse("chessboard:9x6:0.02");
  EXPECT_EQ(board.pattern_size(), cv::Size(9, 6));
  const std::optional<BoardView> view = detect_board(image, board, "rendered");
  ASSERT_TRUE(view.has_value());
  ASSERT_EQ(view->image_points.size(), 54u);
  const std::vector<cv::Point2d> truth =
      flatland::model::compile_camera(truth_camera())
          .project(camera::corners_in_table(flatland::model::compile_target(s.targets[0])));
  ASSERT_EQ(truth.size(), 54u);
  // OpenCV may list the grid from either end: match each true corner to its nearest detection.
  for (const cv::Point2d& t : truth) {
    double best = 1e9;
    for (const cv::Point2f& f : view->image_points)
      best = std::min(best, std::hypot(f.x - t.x, f.y - t.y));
    EXPECT_LT(best, 0.3) << "corner at " << t;
  }
}

TEST(CalibrationIntrinsics, RenderedChessboardViewsRecoverTheTruth) {
  const std::vector<BoardView> views = detected_chessboard_views();
  ASSERT_EQ(views.size(), 20u) << "the chessboard was not found in every rendered view";
  const IntrinsicsResult r = calibrate_intrinsics(views);
  const std::array<double, 9> p = r.params(), t = truth_params();
  std::printf("rms %.4f px, %d views used\n", r.rms_px, r.views_used());
  for (int k = 0; k < 9; ++k)
    std::printf("%s = %.6f (truth %.6f, std %.2g, %.2f sigma)\n", kNames[k], p[k], t[k], r.std[k],
                (p[k] - t[k]) / r.std[k]);
  EXPECT_EQ(r.views_used(), 20);
  EXPECT_TRUE(r.rejected.empty());
  EXPECT_LT(r.rms_px, 0.2);
  EXPECT_NEAR(p[0], t[0], 0.002 * t[0]);
  EXPECT_NEAR(p[1], t[1], 0.002 * t[1]);
  EXPECT_NEAR(p[2], t[2], 0.5);
  EXPECT_NEAR(p[3], t[3], 0.5);
  EXPECT_NEAR(p[4], t[4], 0.01);
  for (int k = 0; k < 9; ++k) {
    ASSERT_TRUE(std::isfinite(r.std[k]) && r.std[k] > 0) << kNames[k];
    EXPECT_LE(std::abs(p[k] - t[k]), 3 * r.std[k]) << kNames[k] << " is more than 3 sigma off";
  }
}

TEST(CalibrationIntrinsics, AgreesWithOpenCvOnTheSameCorners) {
  // The sanitizer stage compares on the first 10 views, as HeldParametersMatchOpenCvsFlags does.
  const std::vector<BoardView> views =
      detected_chessboard_views(flatland::test::short_tests() ? 10 : 20);
  ASSERT_GE(views.size(), 10u);
  const IntrinsicsResult r = calibrate_intrinsics(views);
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  for (const BoardView& v : views) {
    obj.push_back(v.object_points);
    img.push_back(v.image_points);
  }
  cv::Mat K, dist;
  std::vector<cv::Mat> rv, tv;
  const double rms = cv::calibrateCamera(obj, img, views[0].image_size, K, dist, rv, tv, 0);
  std::printf("rms ours %.6f px, OpenCV %.6f px\n", r.rms_px, rms);
  EXPECT_NEAR(r.rms_px, rms, 1e-3);
  const double cv_p[4] = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2),
                          K.at<double>(1, 2)};
  const std::array<double, 9> p = r.params();
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(p[k], cv_p[k], 1e-3 * cv_p[k]) << kNames[k];
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(p[4 + k], dist.at<double>(k), 2e-3) << kNames[4 + k];
}

TEST(CalibrationIntrinsics, HeldParametersMatchOpenCvsFlags) {
  // Each CALIB_FIX_* equivalent against cv::calibrateCamera with that flag on the same corners.
  const std::vector<BoardView> views = detected_chessboard_views(10);
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  for (const BoardView& v : views) {
    obj.push_back(v.object_points);
    img.push_back(v.image_points);
  }
  const cv::Size size = views[0].image_size;
  const std::vector<std::pair<std::string, int>> cases = {
      {"k3", cv::CALIB_FIX_K3},
      {"tangential", cv::CALIB_ZERO_TANGENT_DIST},
      {"aspect", cv::CALIB_FIX_ASPECT_RATIO},
      {"principal-point", cv::CALIB_FIX_PRINCIPAL_POINT},
      {"k3,tangential,aspect,principal-point", cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST |
                                                   cv::CALIB_FIX_ASPECT_RATIO |
                                                   cv::CALIB_FIX_PRINCIPAL_POINT}};
  for (const auto& [names, flags] : cases) {
    SCOPED_TRACE(names);
    IntrinsicsOptions options;
    options.parse_fixed(names);
    const IntrinsicsResult r = calibrate_intrinsics(views, options);
    cv::Mat K = cv::Mat::eye(3, 3, CV_64F), dist;  // fx / fy = 1 for CALIB_FIX_ASPECT_RATIO
    std::vector<cv::Mat> rv, tv;
    const double rms = cv::calibrateCamera(obj, img, size, K, dist, rv, tv, flags);
    const std::array<double, 9> p = r.params();
    EXPECT_NEAR(r.rms_px, rms, 1e-3);
    const double cv_p[4] = {K.at<double>(0, 0), K.at<double>(1, 1), K.at<double>(0, 2),
                            K.at<double>(1, 2)};
    for (int k = 0; k < 4; ++k) EXPECT_NEAR(p[k], cv_p[k], 1e-3 * cv_p[k]) << kNames[k];
    for (int k = 0; k < 5; ++k) EXPECT_NEAR(p[4 + k], dist.at<double>(k), 2e-3) << kNames[4 + k];
    // Held exactly, with no uncertainty.
    if (options.fix_k3) {
      EXPECT_EQ(p[8], 0.0);
      EXPECT_EQ(r.std[8], 0.0);
    }
    if (options.zero_tangent_dist) {
      EXPECT_EQ(p[6], 0.0);
      EXPECT_EQ(p[7], 0.0);
    }
    if (options.fix_aspect_ratio) {
      EXPECT_EQ(p[0], p[1]);
    }
    if (options.fix_principal_point) {
      EXPECT_EQ(p[2], (size.width - 1) / 2.0);
      EXPECT_EQ(p[3], (size.height - 1) / 2.0);
    }
  }
  // The truth's principal point is 3 px right of and 2 px above the centre, where the free fit
  // finds it: the hold at the centre (checked above) did move it.
  const std::array<double, 9> free = calibrate_intrinsics(views).params();
  EXPECT_NEAR(free[2], truth_camera().cx, 1.0);
  EXPECT_NEAR(free[3], truth_camera().cy, 1.0);
  IntrinsicsOptions bad;
  EXPECT_THROW(bad.parse_fixed("k3,k4"), std::invalid_argument);
}

TEST(CalibrationIntrinsics, RationalModelMatchesOpenCvAndTheTruth) {
  // A wide-angle camera with OpenCV's rational model (k4..k6 nonzero), its corners synthesised by
  // cv::projectPoints with 0.05 px of noise: 20 views of a 15 x 11 board, tilted 20-45 deg.
  camera::CameraModel truth;
  truth.K = cv::Matx33d(300, 0, 322, 0, 300, 238, 0, 0, 1);
  truth.dist = camera::Distortion(1.5, 0.3, 0.001, -0.0005, 0.0, 1.9, 0.6, 0.02);
  const camera::Board board = camera::Board::parse("chessboard:15x11:0.025");
  const std::vector<cv::Point3f> corners = board.corners();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(0, 1);
  std::normal_distribution<double> noise(0, 0.05);
  std::vector<BoardView> views;
  while (views.size() < 20) {
    const double tilt = (20 + 25 * U(rng)) * std::numbers::pi / 180,
                 phi = 2 * std::numbers::pi * U(rng);
    const cv::Vec3d rvec(tilt * std::cos(phi), tilt * std::sin(phi), U(rng) - 0.5);
    const cv::Vec3d tvec(-0.2 + 0.2 * U(rng), -0.15 + 0.15 * U(rng), 0.35 + 0.25 * U(rng));
    std::vector<cv::Point2f> px;
    cv::projectPoints(corners, rvec, tvec, truth.K, truth.dist, px);
    bool inside = true;
    for (cv::Point2f& p : px) {
      inside = inside && p.x > 5 && p.y > 5 && p.x < 634 && p.y < 474;
      p += cv::Point2f(static_cast<float>(noise(rng)), static_cast<float>(noise(rng)));
    }
    if (!inside) continue;
    // The name appended rather than "v" + std::string (GCC 12's -Wrestrict false positive, bug
    // 105329, once this file compiles in a unit with others).
    std::string name = "v";
    name += std::to_string(views.size());
    views.push_back({name, {640, 480}, px, corners});
  }
  IntrinsicsOptions options;
  options.rational_model = true;
  const IntrinsicsResult r = calibrate_intrinsics(views, options);
  EXPECT_TRUE(r.rational);
  EXPECT_TRUE(r.camera().rational());
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  for (const BoardView& v : views) {
    obj.push_back(v.object_points);
    img.push_back(v.image_points);
  }
  cv::Mat K, dist;
  std::vector<cv::Mat> rv, tv;
  const double rms =
      cv::calibrateCamera(obj, img, {640, 480}, K, dist, rv, tv, cv::CALIB_RATIONAL_MODEL);
  std::printf("rational: rms ours %.5f px, OpenCV %.5f px; fx %.3f / %.3f (truth 300)\n", r.rms_px,
              rms, r.K(0, 0), K.at<double>(0, 0));
  EXPECT_NEAR(r.rms_px, rms, 1e-3);
  EXPECT_NEAR(r.rms_px, 0.05 * std::sqrt(2.0), 0.01);  // the noise (per coordinate): it fits
  // k4..k6 trade off against f and k1..k3 (the model is nearly degenerate), so f is known to
  // about a per cent only.
  EXPECT_NEAR(r.K(0, 0), 300, 0.01 * 300);
  // k4..k6 trade off against k1..k3, so compare what matters: where each camera sends a ray.
  // Over a grid of directions inside the view, the pixels agree with OpenCV's and the truth's.
  camera::CameraModel opencv;
  opencv.K = cv::Matx33d(K);
  for (int k = 0; k < 8; ++k) opencv.dist[k] = dist.at<double>(k);
  std::vector<cv::Point3d> rays;
  for (double x = -0.8; x <= 0.81; x += 0.1)
    for (double y = -0.6; y <= 0.61; y += 0.1) rays.emplace_back(x, y, 1.0);
  std::vector<cv::Point2d> ours, theirs, truth_px;
  const cv::Vec3d zero(0, 0, 0);
  cv::projectPoints(rays, zero, zero, r.K, r.dist, ours);
  cv::projectPoints(rays, zero, zero, opencv.K, opencv.dist, theirs);
  cv::projectPoints(rays, zero, zero, truth.K, truth.dist, truth_px);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    EXPECT_LT(cv::norm(ours[i] - theirs[i]), 0.05) << rays[i];
    EXPECT_LT(cv::norm(ours[i] - truth_px[i]), 0.3) << rays[i];
  }
  // The 5-coefficient model cannot fit this lens as well (measured: 0.137 px against 0.071).
  EXPECT_GT(calibrate_intrinsics(views).rms_px, 1.5 * r.rms_px);
}

TEST(CalibrationIntrinsics, OutlierViewIsFlaggedAndDropped) {
  std::vector<BoardView> views = detected_chessboard_views(10);
  // A view whose corners were matched to the wrong board points (a detector gone wrong):
  // neighbouring corners swapped along every row. (Reversing whole rows would not do: a mirrored
  // board is still a consistent plane, seen from behind.)
  BoardView bad = views[3];
  bad.name = "bad.png";
  for (std::size_t k = 0; k + 1 < bad.object_points.size(); k += 2)
    std::swap(bad.object_points[k], bad.object_points[k + 1]);
  views.push_back(bad);
  const IntrinsicsResult r = calibrate_intrinsics(views);
  EXPECT_EQ(r.views_used(), 10);
  ASSERT_EQ(r.rejected.size(), 1u);
  EXPECT_NE(r.rejected[0].find("bad.png"), std::string::npos) << r.rejected[0];
  EXPECT_FALSE(r.used.back());
  EXPECT_NEAR(r.params()[0], 800, 0.005 * 800);
  EXPECT_LT(r.rms_px, 0.2);
}

TEST(CalibrationIntrinsics, TooFewViewsIsAnError) {
  std::vector<BoardView> views = detected_chessboard_views(2);
  EXPECT_NE(expect_invalid(views).find("fewer than 3 usable views"), std::string::npos);
  EXPECT_NE(expect_invalid({}).find("no views"), std::string::npos);
}

TEST(CalibrationIntrinsics, FrontoParallelViewsAreAnError) {
  std::vector<cv::Vec3d> rvecs, tvecs;
  for (int i = 0; i < 8; ++i) {
    rvecs.emplace_back(0, 0, 0.2 * i);  // turned in the image plane only
    tvecs.emplace_back(-0.1 + 0.02 * i, -0.08 + 0.01 * i, 0.5 + 0.05 * i);
  }
  const std::string msg = expect_invalid(projected_views(rvecs, tvecs, 0.05));
  EXPECT_NE(msg.find("focal length unobservable: all views are fronto-parallel"), std::string::npos)
      << msg;
  // The same views tilted by 25 deg calibrate.
  for (auto& r : rvecs) r[0] = 0.44;
  EXPECT_NO_THROW(calibrate_intrinsics(projected_views(rvecs, tvecs, 0.05)));
}

TEST(CalibrationIntrinsics, MixedImageSizesAreAnError) {
  std::vector<BoardView> views = detected_chessboard_views(5);
  views[2].image_size = cv::Size(800, 600);
  views[2].name = "big.png";
  const std::string msg = expect_invalid(views);
  EXPECT_NE(msg.find("mixed image sizes"), std::string::npos) << msg;
  EXPECT_NE(msg.find("big.png is 800x600"), std::string::npos) << msg;
}

TEST(CalibrationIntrinsics, BoardNotFoundInABlankImage) {
  const cv::Mat blank(480, 640, CV_8UC3, cv::Scalar(128, 128, 128));
  EXPECT_FALSE(detect_board(blank, chessboard_spec()).has_value());
  EXPECT_FALSE(detect_board(blank, camera::Board::parse("charuco:7x5:0.04:0.03")).has_value());
  EXPECT_FALSE(detect_board(cv::Mat(), chessboard_spec()).has_value());
}

TEST(CalibrationIntrinsics, RenderedCharucoViewsCalibrate) {
  TargetSpec t;
  t.kind = TargetSpec::Kind::kCharuco;
  t.squares_x = 7;
  t.squares_y = 5;
  t.square = 0.05;
  t.marker = 0.037;
  const camera::Board board = camera::Board::parse("charuco:7x5:0.05:0.037");
  const RenderedViews rendered = render_views(t, board, 12, 11);
  const std::vector<BoardView>& views = rendered.views;
  // The detected ids map to the renderer's truth: corner id k is
  // camera::corners_in_table(flatland::model::compile_target(t))[k].
  {
    const camera::CameraModel model = flatland::model::compile_camera(truth_camera());
    const std::vector<cv::Point2d> truth = model.project(
        camera::corners_in_table(flatland::model::compile_target(rendered.targets[0])));
    const std::vector<cv::Point3f> all = board.corners();
    double sum = 0;
    for (std::size_t k = 0; k < views[0].image_points.size(); ++k) {
      const auto id = std::find(all.begin(), all.end(), views[0].object_points[k]) - all.begin();
      const cv::Point2d d = cv::Point2d(views[0].image_points[k]) - truth[id];
      sum += d.dot(d);
    }
    const double rms = std::sqrt(sum / views[0].image_points.size());
    std::printf("charuco corner rms vs truth %.4f px\n", rms);
    EXPECT_LT(rms, 0.2) << "refined ChArUco corners vs truth, px";
  }
  const IntrinsicsResult r = calibrate_intrinsics(views);
  const std::array<double, 9> p = r.params(), tr = truth_params();
  std::printf("charuco: rms %.4f px\n", r.rms_px);
  for (int k = 0; k < 9; ++k)
    std::printf("  %s = %.6f (truth %.6f, std %.2g)\n", kNames[k], p[k], tr[k], r.std[k]);
  // Fewer, sparser corners than the chessboard test: looser bounds, and 3 sigma as there.
  EXPECT_NEAR(p[0], tr[0], 0.005 * tr[0]);
  EXPECT_NEAR(p[1], tr[1], 0.005 * tr[1]);
  EXPECT_NEAR(p[4], tr[4], 0.02);
  for (int k = 0; k < 4; ++k)
    EXPECT_LE(std::abs(p[k] - tr[k]), 3 * r.std[k]) << kNames[k] << " is more than 3 sigma off";
}

// ---------------------------------------------------------------- flatland calibrate

namespace {

using flatland_test::Result;

class CalibrateCli : public flatland_test::CliTestBase {
 protected:
  // The rendered chessboard views as view_00.png ... in DIR/imgs.
  void write_views(int n) {
    fs::create_directories(dir_ / "imgs");
    const RenderedViews& v = chessboard_views(n);
    for (int i = 0; i < n; ++i) {
      char name[32];
      std::snprintf(name, sizeof name, "view_%02d.png", i);
      ASSERT_TRUE(
          cv::imwrite((dir_ / "imgs" / name).string(), v.images[static_cast<std::size_t>(i)]));
    }
  }
  bool only_stdio_files_left() const {
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      if (e.is_regular_file() && e.path().extension() != ".png") return false;
    return true;
  }
  static constexpr const char* kBoard = "--board chessboard:15x11:0.025";
};

}  // namespace

TEST_F(CalibrateCli, CalibratesRenderedViewsAndWritesTheCameraFile) {
  write_views(20);
  flatland_test::write_text(dir_ / "imgs" / "corrupt.png", "not a png at all");
  const Result r =
      run(std::string("calibrate --images 'imgs/*.png' ") + kBoard + " --out camera.yaml --json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("corrupt.png"), std::string::npos) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key :
       {"rms_px", "fx", "fy", "cx", "cy", "dist", "std", "views_used", "views_rejected"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["views_used"], 20);
  EXPECT_NEAR(j["fx"].get<double>(), 800, 1.6);
  ASSERT_EQ(j["dist"].size(), 5u);
  for (const char* k : kNames) EXPECT_TRUE(j["std"].contains(k)) << k;
  const camera::CameraFile f = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_DOUBLE_EQ(f.camera.K(0, 0), j["fx"].get<double>());
  EXPECT_EQ(f.camera.width, 640);
  ASSERT_TRUE(f.report.has_value());
  EXPECT_EQ(f.report->views_used, 20);
}

TEST_F(CalibrateCli, BadInputExitsTwoAndWritesNothing) {
  // No file matches.
  Result r = run(std::string("calibrate --images 'imgs/*.png' ") + kBoard + " --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("no file matches"), std::string::npos) << r.err;
  // Fewer than 3 usable views.
  write_views(2);
  r = run(std::string("calibrate --images 'imgs/*.png' ") + kBoard + " --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("fewer than 3 usable views"), std::string::npos) << r.err;
  // Board found in no image (the wrong board size).
  r = run("calibrate --images 'imgs/*.png' --board chessboard:7x7:0.04 --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("board found in no image"), std::string::npos) << r.err;
  // Mixed image sizes.
  write_views(4);
  cv::Mat big;
  cv::resize(chessboard_views(4).images[3], big, cv::Size(800, 600));
  cv::imwrite((dir_ / "imgs" / "view_99.png").string(), big);
  r = run(std::string("calibrate --images 'imgs/*.png' ") + kBoard + " --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("mixed image sizes"), std::string::npos) << r.err;
  // A bad --board.
  r = run("calibrate --images 'imgs/*.png' --board square:9x6:0.02 --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--board"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "camera.yaml"));
  EXPECT_TRUE(only_stdio_files_left());
}

// Found nowhere, the error names the board searched for; when the same numbers in the other
// count find it (a chessboard counted by its squares), it says so and gives the --board to use.
TEST_F(CalibrateCli, MiscountedBoardGetsAHint) {
  write_views(3);
  Result r =
      run("calibrate --images 'imgs/*.png' --board chessboard:16x12:0.025 --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  const std::vector<std::string> lines = flatland_test::lines_of(r.err);
  ASSERT_FALSE(lines.empty());
  const std::string& error = lines.back();
  EXPECT_EQ(error.rfind("flatland: error: board found in no image (3 images searched for a "
                        "chessboard of 16x12 inner corners (17x13 squares)",
                        0),
            0u)
      << error;
  EXPECT_NE(error.find("but a chessboard of 15x11 inner corners (16x12 squares) is in 3 of the "
                       "first 3: flatland counts a chessboard by its inner corners"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("try --board chessboard:15x11:0.025"), std::string::npos) << error;
  // No hint when the other count finds nothing either.
  r = run("calibrate --images 'imgs/*.png' --board chessboard:7x7:0.04 --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("board found in no image"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("try --board"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "camera.yaml"));
}

TEST_F(CalibrateCli, FrontoParallelImagesExitTwo) {
  // Boards seen straight on: the camera looks down and the boards lie flat on the table.
  fs::create_directories(dir_ / "imgs");
  for (int i = 0; i < 4; ++i) {
    TargetSpec t = chessboard_target();
    t.position = {-0.2 + 0.01 * i, -0.15 + 0.01 * i, 0.02 * i};
    t.rotation = {0, 0, 0.03 * i};
    Scene s;
    s.camera = truth_camera();
    s.effects.supersample = 2;
    s.targets = {t};
    render::Renderer rr(flatland_test::render_setup(s));
    render::SceneState st;
    st.disk_center = {5.0, 5.0};
    cv::imwrite((dir_ / "imgs" / ("flat" + std::to_string(i) + ".png")).string(), rr.render_8u(st));
  }
  const Result r =
      run(std::string("calibrate --images 'imgs/*.png' ") + kBoard + " --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("focal length unobservable"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "camera.yaml"));
}
