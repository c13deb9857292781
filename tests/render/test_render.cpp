// Rendered images against exact truth: the disk's centroid and a chessboard's corners against
// cv::projectPoints (also through a strongly distorted lens), determinism, backend agreement and
// the GL error path.
#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/spec.hpp"
#include "render_support.hpp"

#include <gtest/gtest.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <vector>

using namespace flatland;
using namespace flatland::render;

namespace {

using flatland_test::overhead_scene;

// Intensity centroid of the disk's bright face: weights are the excess over the table
// (the dark O-ring and rubber side are clipped to zero), inside a window around the disk.
cv::Point2d face_centroid(const cv::Mat& bgr, cv::Point2d around, double radius_px) {
  cv::Mat gray;
  cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
  gray.convertTo(gray, CV_64F);
  const int r = static_cast<int>(radius_px * 1.4);
  const cv::Rect roi(static_cast<int>(around.x) - r, static_cast<int>(around.y) - r, 2 * r + 1,
                     2 * r + 1);
  const cv::Mat w = gray(roi);
  // The table level: the median of the window's border.
  std::vector<double> border;
  for (int i = 0; i < w.cols; ++i) border.push_back(w.at<double>(0, i));
  std::nth_element(border.begin(), border.begin() + border.size() / 2, border.end());
  const double table = border[border.size() / 2];
  double sw = 0, sx = 0, sy = 0;
  for (int y = 0; y < w.rows; ++y)
    for (int x = 0; x < w.cols; ++x) {
      const double v = std::max(0.0, w.at<double>(y, x) - table - 5.0);
      sw += v;
      sx += v * (x + roi.x);
      sy += v * (y + roi.y);
    }
  return {sx / sw, sy / sw};
}

double corner_rms(const cv::Mat& bgr, const TargetSpec& board, const camera::CameraModel& cam) {
  cv::Mat gray;
  cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
  std::vector<cv::Point2f> found;
  const cv::Size pattern(board.squares_x - 1, board.squares_y - 1);
  if (!cv::findChessboardCorners(gray, pattern, found,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
    return -1;
  cv::cornerSubPix(gray, found, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  const std::vector<cv::Point2d> truth =
      cam.project(camera::corners_in_table(flatland::model::compile_target(board)));
  // OpenCV may report the grid from either end: match each truth corner to its nearest detection.
  double sum = 0;
  for (const cv::Point2d& t : truth) {
    double best = 1e9;
    for (const cv::Point2f& f : found) best = std::min(best, std::hypot(f.x - t.x, f.y - t.y));
    sum += best * best;
  }
  return std::sqrt(sum / truth.size());
}

SceneState disk_at(double x, double y, double angle) {
  SceneState st;
  st.hand_angle = 0.0;
  st.disk_center = {x, y};
  st.disk_angle = angle;
  return st;
}

}  // namespace

TEST(Render, DiskCentroidMatchesProjectedCentre) {
  const Scene scene = overhead_scene(4);
  Renderer r(flatland_test::render_setup(scene));
  const double radius_px = 900 * scene.sim.object.radius / (1.0 - scene.render.disk_thickness);
  for (cv::Point2d c :
       {cv::Point2d(0.12, 0.21), cv::Point2d(-0.1, 0.19), cv::Point2d(0.25, 0.22)}) {
    // The off-centre marker is dark; rendering the disk turned by pi as well and averaging the two
    // centroids cancels its pull exactly, leaving the geometry of the face.
    const SceneState a = disk_at(c.x, c.y, 0.3), b = disk_at(c.x, c.y, 0.3 + std::numbers::pi);
    const FrameTruth truth = r.truth(a);
    const cv::Point2d ca = face_centroid(r.render_8u(a), truth.disk_center_px, radius_px);
    const cv::Point2d cb = face_centroid(r.render_8u(b), truth.disk_center_px, radius_px);
    const cv::Point2d mean = 0.5 * (ca + cb);
    RecordProperty("centroid_error_px", std::to_string(cv::norm(mean - truth.disk_center_px)));
    std::printf("centroid error %.4f px\n", cv::norm(mean - truth.disk_center_px));
    EXPECT_NEAR(mean.x, truth.disk_center_px.x, 0.05) << "disk at " << c;
    EXPECT_NEAR(mean.y, truth.disk_center_px.y, 0.05) << "disk at " << c;
    // The truth itself is cv::projectPoints of the face centre, computed independently here.
    std::vector<cv::Point2d> px;
    cv::projectPoints(std::vector<cv::Point3d>{{c.x, c.y, scene.render.disk_thickness}},
                      r.camera().rvec(), r.camera().t, r.camera().K, r.camera().dist, px);
    EXPECT_NEAR(px[0].x, truth.disk_center_px.x, 1e-9);
    EXPECT_NEAR(px[0].y, truth.disk_center_px.y, 1e-9);
  }
}

TEST(Render, ChessboardCornersMatchProjectionEvenThroughStrongDistortion) {
  for (double k1 : {0.0, -0.3}) {
    Scene scene = overhead_scene(3);
    scene.camera->position = {0.0, -0.1, 0.8};
    scene.camera->look_at = {0.02, 0.02, 0.0};
    scene.camera->distortion = {k1, k1 == 0 ? 0.0 : 0.08, 0.0, 0.0, 0.0};
    TargetSpec board;
    board.squares_x = 9;
    board.squares_y = 6;
    board.square = 0.03;
    board.position = {-0.12, -0.06, 0.03};  // above the hand
    board.rotation = {0.25, -0.15, 0.1};
    scene.targets = {board};
    Renderer r(flatland_test::render_setup(scene));
    const cv::Mat image = r.render_8u(disk_at(5.0, 5.0, 0.0));  // the disk out of view
    const double rms = corner_rms(image, board, r.camera());
    ASSERT_GE(rms, 0.0) << "chessboard not found with k1 = " << k1;
    std::printf("chessboard corner rms %.4f px (k1 = %g)\n", rms, k1);
    EXPECT_LT(rms, 0.1) << "k1 = " << k1;
  }
}

TEST(Render, SameSceneAndSeedGiveIdenticalFrames) {
  Scene scene = overhead_scene(2);
  scene.camera->exposure = 0.01;
  scene.effects.blur_subframes = 3;
  scene.effects.noise_read_dn = 2.0;
  scene.effects.noise_shot_gain = 0.5;
  scene.effects.vignetting = 0.2;
  scene.effects.jitter_s = 0.001;
  scene.effects.seed = 42;
  const sim::RunResult run = sim::run_spec(scene.sim);
  Renderer a(flatland_test::render_setup(scene)), b(flatland_test::render_setup(scene));
  for (double t : {0.2, 0.5, 0.8}) {
    const Frame fa = a.capture(run.trajectory, t), fb = b.capture(run.trajectory, t);
    ASSERT_EQ(fa.image.size(), fb.image.size());
    EXPECT_EQ(cv::norm(fa.image, fb.image, cv::NORM_INF), 0.0);
    EXPECT_EQ(fa.truth.t, fb.truth.t);
  }
  // Another seed gives other noise at the same instant.
  Scene other = scene;
  other.effects.seed = 43;
  Renderer fresh(flatland_test::render_setup(scene)), reseeded(flatland_test::render_setup(other));
  const Frame f42 = fresh.capture(run.trajectory, 0.5), f43 = reseeded.capture(run.trajectory, 0.5);
  EXPECT_GT(cv::norm(f42.image, f43.image, cv::NORM_INF), 0.0);
}

// The renderer reuses a frame's buffer once no one else holds it (its pool), and never one that is
// held: frames kept alive are still the frames as rendered (each compared with a copy taken when it
// came), through more captures than the pool has buffers, and again after the others are let go.
TEST(Render, HeldFramesAreNeverOverwritten) {
  Scene scene = overhead_scene(1);
  scene.effects.noise_read_dn = 2.0;
  scene.effects.seed = 9;
  const sim::RunResult run = sim::run_spec(scene.sim);
  Renderer renderer(flatland_test::render_setup(scene));
  std::vector<cv::Mat> held, copies;
  for (int i = 0; i < 6; ++i) {
    const Frame f = renderer.capture(run.trajectory, 0.1 + 0.15 * i);
    held.push_back(f.image);
    copies.push_back(f.image.clone());
  }
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(cv::norm(held[i], copies[i], cv::NORM_INF), 0.0) << "frame " << i;
    for (int j = 0; j < i; ++j) EXPECT_NE(held[i].data, held[j].data) << i << ", " << j;
  }
  // Keep every other frame; the pool may now reuse the rest.
  for (int i = 5; i >= 0; i -= 2) held.erase(held.begin() + i);
  for (int k = 0; k < 8; ++k) renderer.capture(run.trajectory, 0.2 + 0.05 * k);
  for (int i = 0; i < 3; ++i)
    EXPECT_EQ(cv::norm(held[i], copies[2 * i], cv::NORM_INF), 0.0) << "frame " << 2 * i;
}

// A frame with noise and nothing fractional before it (no supersampling, blur, vignetting or
// distortion) is noised on the 8-bit render directly: the same frame as the float path, the render
// as floats noised from the same draw of the generator and rounded, for read and shot noise.
TEST(Render, NoisyCaptureOfAWholeNumberRenderIsTheFloatPathRounded) {
  for (const double gain : {0.0, 0.4}) {
    Scene scene = overhead_scene(1);
    scene.effects.noise_read_dn = 2.0;
    scene.effects.noise_shot_gain = gain;
    scene.effects.seed = 5;
    const sim::RunResult run = sim::run_spec(scene.sim);
    Renderer noisy(flatland_test::render_setup(scene)), clean(flatland_test::render_setup(scene));
    EffectsRng rng(5);
    for (double t : {0.3, 0.6}) {
      const Frame f = noisy.capture(run.trajectory, t);
      cv::Mat expected = clean.render_linear(SceneState::from_sample(run.trajectory.sample(t)));
      apply_noise(expected, 2.0, gain, rng);
      ASSERT_EQ(f.image.type(), CV_8UC3);
      EXPECT_EQ(cv::norm(f.image, quantize(expected), cv::NORM_INF), 0.0)
          << "t = " << t << ", gain " << gain;
    }
  }
}

// Exposure blur is the mean of the sub-frames over the exposure centred on the capture time.
// capture() renders them one at a time into a reused buffer; here each is rendered on its own
// (render_linear) and averaged with average_frames, through distortion and supersampling.
TEST(Render, BlurredCaptureIsTheMeanOfItsSubFrames) {
  Scene scene = overhead_scene(2);
  scene.camera->distortion = {-0.2, 0.05, 0.0, 0.0, 0.0};
  scene.camera->exposure = 0.02;
  scene.effects.blur_subframes = 4;
  scene.effects.quantize = false;  // the float image, before rounding
  const sim::RunResult run = sim::run_spec(scene.sim);
  Renderer blurred(flatland_test::render_setup(scene)), single(flatland_test::render_setup(scene));
  for (double t : {0.3, 0.6}) {
    const Frame f = blurred.capture(run.trajectory, t);
    std::vector<cv::Mat> subs;
    for (int i = 0; i < 4; ++i)
      subs.push_back(single.render_linear(
          SceneState::from_sample(run.trajectory.sample(t - 0.01 + (i + 0.5) * 0.005))));
    const cv::Mat mean = average_frames(subs);
    ASSERT_EQ(f.image.size(), mean.size());
    ASSERT_EQ(f.image.type(), CV_32FC3);
    EXPECT_EQ(cv::norm(f.image, mean, cv::NORM_INF), 0.0) << "t = " << t;
    // The sub-frames differ (the disk moves during the exposure), so the mean is a blur.
    EXPECT_GT(cv::norm(subs.front(), subs.back(), cv::NORM_INF), 10.0);
  }
}

TEST(Render, OsmesaAndEglAgreeWithinOneLevel) {
  const Scene scene = overhead_scene(2);
  std::unique_ptr<Renderer> egl;
  try {
    egl = std::make_unique<Renderer>(flatland_test::render_setup(scene), GlBackend::kEgl);
  } catch (const std::runtime_error& e) {
    GTEST_SKIP() << "EGL is not available here: " << e.what();
  }
  Renderer osmesa(flatland_test::render_setup(scene), GlBackend::kOsmesa);
  const SceneState st = disk_at(0.1, 0.2, 0.7);
  const cv::Mat a = osmesa.render_8u(st), b = egl->render_8u(st);
  EXPECT_LE(cv::norm(a, b, cv::NORM_INF), 1.0);
}

TEST(Render, MissingBackendNamesItAndItsPackage) {
  const Scene scene = overhead_scene(1);
  setenv("FLATLAND_OSMESA_LIBRARY", "/nonexistent/libOSMesa.so.8", 1);
  try {
    Renderer r(flatland_test::render_setup(scene), GlBackend::kOsmesa);
    ADD_FAILURE() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("osmesa"), std::string::npos) << msg;
    EXPECT_NE(msg.find("libosmesa6"), std::string::npos) << msg;
  }
  unsetenv("FLATLAND_OSMESA_LIBRARY");
  EXPECT_THROW(parse_backend("vulkan"), std::invalid_argument);
}

TEST(Render, SceneWithoutCameraIsRejected) {
  Scene scene;
  EXPECT_THROW(Renderer r(flatland_test::render_setup(scene)), std::invalid_argument);
}

TEST(Render, CharucoBoardIsDetectedWhereItIs) {
  Scene scene = overhead_scene(3);
  scene.camera->position = {0.0, -0.05, 0.8};
  scene.camera->look_at = {0.0, 0.0, 0.0};
  TargetSpec board;
  board.kind = TargetSpec::Kind::kCharuco;
  board.squares_x = 7;
  board.squares_y = 5;
  board.square = 0.04;
  board.marker = 0.03;
  board.dictionary = "DICT_4X4_50";
  board.position = {-0.14, -0.1, 0.03};
  board.rotation = {0.2, -0.1, 0.05};
  scene.targets = {board};
  Renderer r(flatland_test::render_setup(scene));
  cv::Mat gray;
  cv::cvtColor(r.render_8u(disk_at(5.0, 5.0, 0.0)), gray, cv::COLOR_BGR2GRAY);
  const auto dict = cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  const auto cv_board =
      cv::aruco::CharucoBoard::create(board.squares_x, board.squares_y, 0.04f, 0.03f, dict);
  std::vector<std::vector<cv::Point2f>> marker_corners;
  std::vector<int> marker_ids;
  cv::aruco::detectMarkers(gray, dict, marker_corners, marker_ids);
  ASSERT_GE(marker_ids.size(), 10u);  // 7 x 5 squares hold 17 markers
  std::vector<cv::Point2f> corners;
  std::vector<int> ids;
  cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, cv_board, corners, ids);
  ASSERT_GE(ids.size(), 20u);  // of 24 inner corners
  // OpenCV 4.6's interpolated ChArUco corners sit about (+0.5, +0.5) px off (measured here:
  // cornerSubPix started from the true corners stays within 0.1 px of them); refine them as a
  // calibration pipeline would.
  cv::cornerSubPix(gray, corners, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  const std::vector<cv::Point2d> truth =
      r.camera().project(camera::corners_in_table(flatland::model::compile_target(board)));
  double sum = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const cv::Point2d d = cv::Point2d(corners[i]) - truth[ids[i]];
    sum += d.dot(d);
  }
  const double rms = std::sqrt(sum / ids.size());
  std::printf("charuco corner rms %.4f px over %zu corners\n", rms, ids.size());
  EXPECT_LT(rms, 0.2);
}
