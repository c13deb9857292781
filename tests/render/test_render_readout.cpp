// The camera's readout and the segmentation mask against what they must be, each computed here
// from a global-shutter renderer of the same scene or from the camera's projection, not read from
// the code under test: an interlaced frame's fields are each a global frame at their own time; a
// rolling-shutter row is a global frame's row at its row's time (exactly, and with bands at its
// band's time); the truth's state time is the row where the disk's centre is; the mask's disk
// outline lies on the projected rim circle (to 1 px), its hand, table and board ids where the
// bodies are, and it follows the same rows' times.
#include "flatland/camera/camera_model.hpp"
#include "flatland/render/renderer.hpp"
#include "render_support.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

using namespace flatland;
using namespace flatland::render;

namespace {

using flatland_test::overhead_scene;

// A fast world: the disk crosses the image at 0.6 m/s (540 px/s) and turns, the hand turns, so
// that times a field or a few rows apart give different pixels.
SceneState world_at(double t) {
  SceneState st;
  st.t = t;
  st.hand_angle = 0.3 * t;
  st.disk_center = {-0.1 + 0.6 * t, 0.16 - 0.2 * t};
  st.disk_angle = 4.0 * t;
  return st;
}

const Renderer::StateAt kWorld = world_at;

Scene with_readout(Scene s, const std::string& mode) {
  s.camera->readout.mode = mode;
  if (mode == "rolling") s.camera->readout.time = 0.025;
  return s;
}

double max_row_difference(const cv::Mat& a, const cv::Mat& b, int row) {
  return cv::norm(a.row(row), b.row(row), cv::NORM_INF);
}

}  // namespace

// Each field's rows are, bit for bit, the rows of a global frame at the field's time: with a plain
// camera (the 8-bit path) and with distortion, supersampling and exposure blur (float frames).
TEST(RenderReadout, InterlacedFieldsAreGlobalFramesAtTheirTimes) {
  for (const bool effects : {false, true}) {
    for (const std::string order : {"even_first", "odd_first"}) {
      SCOPED_TRACE(std::string(effects ? "distortion, supersampling, blur; " : "plain; ") + order);
      Scene scene = effects ? overhead_scene(2, -0.15) : overhead_scene(1);
      if (effects) {
        scene.camera->exposure = 0.008;
        scene.effects.blur_subframes = 3;
        scene.effects.quantize = false;
      }
      Scene interlaced = with_readout(scene, "interlaced");
      interlaced.camera->readout.field_order = order;
      Renderer fields(flatland_test::render_setup(interlaced));
      Renderer global(flatland_test::render_setup(scene));
      const double t = 0.2, field = 1.0 / 60.0;
      const Frame f = fields.capture(kWorld, t);
      const Frame first = global.capture(kWorld, t), second = global.capture(kWorld, t + field);
      ASSERT_EQ(f.image.type(), first.image.type());
      const int first_parity = order == "even_first" ? 0 : 1;
      int differing = 0;
      for (int v = 0; v < f.image.rows; ++v) {
        const Frame& expected = v % 2 == first_parity ? first : second;
        ASSERT_EQ(max_row_difference(f.image, expected.image, v), 0.0) << "row " << v;
        if (max_row_difference(first.image, second.image, v) > 0) ++differing;
      }
      // The fields are different images: the disk moved 9 px between them.
      EXPECT_GT(differing, 50);
      EXPECT_EQ(f.truth.t, t);
      EXPECT_NEAR(f.truth.t_state, t + 0.5 * field, 1e-15);
      EXPECT_DOUBLE_EQ(fields.readout_duration(), field);
    }
  }
}

// Row y of a rolling-shutter frame is row y of a global frame at t + y * time / height: sampled
// rows, among them every row the disk crosses, through distortion, supersampling and blur.
TEST(RenderReadout, RollingRowsAreGlobalFramesAtTheirRowsTimes) {
  for (const bool effects : {false, true}) {
    SCOPED_TRACE(effects ? "distortion, supersampling, blur" : "plain");
    Scene scene = effects ? overhead_scene(2, -0.15) : overhead_scene(1);
    if (effects) {
      scene.camera->exposure = 0.008;
      scene.effects.blur_subframes = 3;
      scene.effects.quantize = false;
    }
    const Scene rolling = with_readout(scene, "rolling");
    Renderer rows(flatland_test::render_setup(rolling));
    Renderer global(flatland_test::render_setup(scene));
    const double t = 0.3, line = 0.025 / 480;
    const Frame f = rows.capture(kWorld, t);
    const cv::Point2d disk = global.truth(world_at(t)).disk_center_px;
    std::vector<int> sampled = {0, 1, 2, 77, 240, 401, 478, 479};
    for (int v = static_cast<int>(disk.y) - 60; v <= static_cast<int>(disk.y) + 60; v += 3)
      sampled.push_back(v);
    for (const int v : sampled) {
      const Frame g = global.capture(kWorld, t + v * line);
      ASSERT_EQ(max_row_difference(f.image, g.image, v), 0.0) << "row " << v;
    }
    // Not a global frame: rows across the disk differ from the frame at t.
    const Frame at_t = global.capture(kWorld, t);
    EXPECT_GT(max_row_difference(f.image, at_t.image, static_cast<int>(disk.y) + 40), 0.0);
  }
}

// With bands of rows, a row is a global frame's row at its band's middle row's time: at most
// (band_rows - 1) / 2 line times from its own.
TEST(RenderReadout, RollingBandsAreGlobalFramesAtTheirBandsTimes) {
  const Scene scene = overhead_scene(1);
  Scene banded = with_readout(scene, "rolling");
  banded.camera->readout.band_rows = 8;
  Renderer rows(flatland_test::render_setup(banded)), global(flatland_test::render_setup(scene));
  const double t = 0.3, line = 0.025 / 480;
  const Frame f = rows.capture(kWorld, t);
  for (const int v : {0, 7, 8, 130, 131, 135, 200, 479}) {
    const int first = v / 8 * 8;
    const double band_time = t + (first + 3.5) * line;
    EXPECT_LE(std::abs(band_time - (t + v * line)), 3.5 * line + 1e-15);
    const Frame g = global.capture(kWorld, band_time);
    EXPECT_EQ(max_row_difference(f.image, g.image, v), 0.0) << "row " << v;
  }
}

// The truth of a rolling frame holds at the time of the row where the disk's centre is: that row,
// projected here from the state at the truth's time, is read at that time.
TEST(RenderReadout, RollingTruthIsTheDiskRowsTime) {
  for (const double k1 : {0.0, -0.15}) {
    const Scene scene = with_readout(overhead_scene(1, k1), "rolling");
    Renderer r(flatland_test::render_setup(scene));
    const double t = 0.25, line = 0.025 / 480;
    const Frame f = r.capture(kWorld, t);
    const SceneState at = world_at(f.truth.t_state);
    const double z = scene.render.disk_thickness;
    const cv::Point2d centre =
        r.camera().project(cv::Point3d(at.disk_center.x, at.disk_center.y, z));
    EXPECT_NEAR(f.truth.t_state, t + centre.y * line, 1e-12) << "k1 = " << k1;
    EXPECT_NEAR(f.truth.disk_center_px.y, centre.y, 1e-9);
    EXPECT_NEAR(f.truth.disk_center_table.x, at.disk_center.x, 1e-15);
    EXPECT_EQ(f.truth.t, t);
    EXPECT_GT(f.truth.t_state - t, 100 * line);  // the disk is well down the image
  }
}

namespace {

// Along the ray from `centre` in `dir` (0.05 px steps), the farthest pixel whose id is `id`: its
// centre's distance along the ray (a pixel's centre, not its edge, is what the mask samples).
double outline_radius(const cv::Mat& mask, cv::Point2d centre, cv::Point2d dir, int id,
                      double max_r) {
  double last = -1;
  for (double r = 0; r <= max_r; r += 0.05) {
    const cv::Point2d p = centre + r * dir;
    const int u = static_cast<int>(std::lround(p.x)), v = static_cast<int>(std::lround(p.y));
    if (u < 0 || v < 0 || u >= mask.cols || v >= mask.rows) break;
    if (mask.at<unsigned char>(v, u) == id) last = (cv::Point2d(u, v) - centre).dot(dir);
  }
  return last;
}

// The mask's disk outline against the projected rim circle of the disk's top face: along rays
// from the projected centre, the last disk pixel lies within 1 px of the rim's projection.
void expect_disk_outline(const cv::Mat& mask, const camera::CameraModel& cam, const SceneState& st,
                         double radius, double z) {
  const cv::Point2d centre = cam.project(cv::Point3d(st.disk_center.x, st.disk_center.y, z));
  double worst = 0;
  for (int k = 0; k < 72; ++k) {
    const double a = 2 * std::numbers::pi * k / 72;
    const cv::Point2d rim = cam.project(cv::Point3d(st.disk_center.x + radius * std::cos(a),
                                                    st.disk_center.y + radius * std::sin(a), z));
    const double rim_r = cv::norm(rim - centre);
    const cv::Point2d dir = (rim - centre) / rim_r;
    const double found = outline_radius(mask, centre, dir, kMaskDisk, rim_r + 10);
    worst = std::max(worst, std::abs(found - rim_r));
  }
  std::printf("mask: disk outline at most %.3f px from the projected rim\n", worst);
  EXPECT_LE(worst, 1.0) << "the mask's disk outline is off the projected rim by " << worst << " px";
}

}  // namespace

// The mask's disk, hand, table and board ids, each where the camera's projection of the body puts
// it, through a distorted, supersampled camera (the mask takes the nearest sample).
TEST(RenderMask, IdsLieWhereTheProjectedBodiesAre) {
  for (const int supersample : {1, 2}) {
    SCOPED_TRACE("supersample " + std::to_string(supersample));
    Scene scene = overhead_scene(supersample, -0.15);
    TargetSpec board;  // a chessboard on the table, beside the hand
    board.kind = TargetSpec::Kind::kChessboard;
    board.squares_x = 6;
    board.squares_y = 5;
    board.square = 0.02;
    board.position = {0.2, -0.15, 0.001};
    scene.targets.push_back(board);
    Renderer r(flatland_test::render_setup(scene));
    const SceneState st = world_at(0.1);  // the disk clear of the hand (which would hide a part)
    const cv::Mat mask = r.render_mask(st);
    ASSERT_EQ(mask.type(), CV_8UC1);
    ASSERT_EQ(mask.size(), cv::Size(640, 480));
    const camera::CameraModel& cam = r.camera();
    expect_disk_outline(mask, cam, st, scene.sim.object.radius, scene.render.disk_thickness);
    const auto id_at = [&](double x, double y, double z) {
      const cv::Point2d p = cam.project(cv::Point3d(x, y, z));
      return int(mask.at<unsigned char>(int(std::lround(p.y)), int(std::lround(p.x))));
    };
    // The board's centre square, and its margin.
    EXPECT_EQ(id_at(0.2 + 0.06, -0.15 + 0.05, 0.001), kMaskFirstBoard);
    EXPECT_EQ(id_at(0.2 - 0.01, -0.15 - 0.01, 0.001), kMaskFirstBoard);
    // Over a grid of table points: the hand's id well inside its outline (its top face), the
    // table's well outside it, the disk and the board.
    const std::vector<cv::Point2d> outline =
        hand_plate_outline(*flatland_test::render_setup(scene).hand, scene.render.table_extent);
    std::vector<cv::Point2f> turned;
    const double c = std::cos(st.hand_angle), s = std::sin(st.hand_angle);
    for (const cv::Point2d& p : outline)
      turned.emplace_back(float(c * p.x - s * p.y), float(s * p.x + c * p.y));
    int hand = 0, table = 0;
    for (double x = -0.25; x <= 0.35; x += 0.02)
      for (double y = -0.15; y <= 0.3; y += 0.02) {
        const double inside = cv::pointPolygonTest(turned, cv::Point2f(float(x), float(y)), true);
        const bool near_disk = std::hypot(x - st.disk_center.x, y - st.disk_center.y) <
                               scene.sim.object.radius + 0.005;
        // The board's squares and its one square of white margin, and 5 mm more.
        const bool near_board = x > 0.175 && x < 0.345 && y > -0.175 && y < -0.025;
        if (near_disk || near_board || std::abs(inside) < 0.004) continue;
        if (inside > 0) {
          EXPECT_EQ(id_at(x, y, scene.render.hand_thickness), kMaskHand) << x << ", " << y;
          ++hand;
        } else {
          EXPECT_EQ(id_at(x, y, 0.0), kMaskTable) << x << ", " << y;
          ++table;
        }
      }
    EXPECT_GT(hand, 10);
    EXPECT_GT(table, 100);
  }
}

// With a readout, the captured mask's rows are the global mask's rows at their own times.
TEST(RenderMask, FollowsTheReadoutsRowTimes) {
  const Scene scene = overhead_scene(2, -0.15);
  Renderer global(flatland_test::render_setup(scene));
  CaptureOptions with_mask;
  with_mask.mask = true;
  const double t = 0.3;
  {
    Renderer rows(flatland_test::render_setup(with_readout(scene, "rolling")));
    const Frame f = rows.capture(kWorld, t, with_mask);
    ASSERT_EQ(f.mask.type(), CV_8UC1);
    const double line = 0.025 / 480;
    for (int v = 0; v < 480; v += 7) {
      const cv::Mat g = global.render_mask(world_at(t + v * line));
      ASSERT_EQ(max_row_difference(f.mask, g, v), 0.0) << "row " << v;
    }
  }
  {
    Renderer fields(flatland_test::render_setup(with_readout(scene, "interlaced")));
    const Frame f = fields.capture(kWorld, t, with_mask);
    const cv::Mat first = global.render_mask(world_at(t)),
                  second = global.render_mask(world_at(t + 1.0 / 60));
    for (int v = 0; v < 480; ++v)
      ASSERT_EQ(max_row_difference(f.mask, v % 2 ? second : first, v), 0.0) << "row " << v;
    EXPECT_GT(cv::norm(first, second, cv::NORM_L1), 0.0);
  }
  // A global capture's mask is the mask at its time; none unless asked for.
  const Frame g = global.capture(kWorld, t, with_mask);
  EXPECT_EQ(cv::norm(g.mask, global.render_mask(world_at(t)), cv::NORM_INF), 0.0);
  EXPECT_TRUE(global.capture(kWorld, t).mask.empty());
}

// Values the scene's rules refuse are refused by a setup put together by hand too.
TEST(RenderReadout, BadReadoutInASetupIsRefused) {
  Scene scene = overhead_scene(1);
  RenderSetup setup = flatland_test::render_setup(scene);
  setup.readout.mode = "rolling";
  setup.readout.time = 0.0;
  try {
    Renderer r(setup);
    FAIL() << "a rolling readout without a time was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("camera.readout_time"), std::string::npos) << e.what();
  }
}
