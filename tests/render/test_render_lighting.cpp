// The scene's lamp (section `lighting`) against what it must do, each computed here from the
// lamp's position and the bodies' geometry, not read from the renderer: the disk's shadow ends
// where the ray from the lamp grazing the disk's rim meets the table (to 1 px) and keeps only the
// ambient light inside, darkened once where both of the wall's sides cover a point; the table's
// brightness follows the inverse square and the cosine; the O-ring's two highlights (a torus seen
// from above) carry the Blinn-Phong light integrated over the band and sit where that integral
// puts them; without the section the table stays the old evenly lit plane. Checked to fail: the
// renderer's lamp moved 5 cm sideways from the scene's (the first four), the stencil off
// (darkened twice), the band shaded flat (no highlight).
#include "flatland/camera/camera_model.hpp"
#include "flatland/render/renderer.hpp"
#include "render_support.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

using namespace flatland;
using namespace flatland::render;

namespace {

// The overhead scene (render_support.hpp) with a lamp low and
// well off-axis so that the shadows are long.
Scene lit_scene(int supersample) {
  Scene s = flatland_test::overhead_scene(supersample);
  s.render.disk_thickness = 0.03;  // a tall disk: a shadow tens of pixels long
  LightingSpec lamp;
  lamp.position = {-0.15, 0.05, 0.6};
  lamp.ambient = 0.3;
  lamp.intensity = 0.7;
  s.lighting = lamp;
  return s;
}

SceneState disk_at(double x, double y) {
  SceneState st;
  st.hand_angle = 0.0;
  st.disk_center = {x, y};
  st.disk_angle = 0.3;
  return st;
}

cv::Mat grey(const cv::Mat& bgr_f32) {
  cv::Mat g;
  cv::cvtColor(bgr_f32, g, cv::COLOR_BGR2GRAY);
  return g;
}

double bilinear(const cv::Mat& g, cv::Point2d p) {
  cv::Mat patch;
  cv::getRectSubPix(g, cv::Size(1, 1), cv::Point2f(float(p.x), float(p.y)), patch, CV_32F);
  return patch.at<float>(0, 0);
}

cv::Point2d project(const camera::CameraModel& cam, const cv::Vec3d& p) {
  return cam.project(std::vector<cv::Point3d>{{p[0], p[1], p[2]}})[0];
}

// Whether the table point x (z = 0) is in the shadow of the upright cylinder of radius r and
// height t about c: the ray from x to the lamp L is at x + (L - x) z / L.z at height z, so it
// passes through the cylinder iff the segment of its horizontal trace over z in [0, t] comes
// within r of the axis.
bool in_cylinder_shadow(cv::Point2d x, cv::Point2d c, double r, double t, const cv::Vec3d& L) {
  const cv::Point2d a = x, b = x + (cv::Point2d(L[0], L[1]) - x) * (t / L[2]);
  const cv::Point2d ab = b - a;
  const double s = std::clamp((c - a).dot(ab) / ab.dot(ab), 0.0, 1.0);
  return cv::norm(a + s * ab - c) <= r;
}

}  // namespace

TEST(RenderLighting, DiskShadowEndsWhereTheLampsRayGrazingTheRimMeetsTheTable) {
  Scene scene = lit_scene(4);
  Renderer shaded(flatland_test::render_setup(scene));
  scene.lighting->shadows = false;
  Renderer unshaded(flatland_test::render_setup(scene));
  const cv::Point2d c(0.22, 0.2);
  const SceneState st = disk_at(c.x, c.y);
  // The shadow alone: the ratio of the frame with shadows to the one without (1 where nothing
  // changes: lit table, disk, hand).
  const cv::Mat with = grey(shaded.render_linear(st)), without = grey(unshaded.render_linear(st));
  cv::Mat ratio;
  cv::divide(with, cv::max(without, 1.0f), ratio);
  const double r = scene.sim.object.radius, t = scene.render.disk_thickness;
  const cv::Vec3d L(scene.lighting->position[0], scene.lighting->position[1],
                    scene.lighting->position[2]);
  const cv::Point2d away = cv::Point2d(c.x - L[0], c.y - L[1]) / std::hypot(c.x - L[0], c.y - L[1]);
  int checked = 0, inside_checked = 0;
  for (double turn = -0.9; turn <= 0.9; turn += 0.15) {  // rad about the direction from the lamp
    const cv::Point2d u(away.x * std::cos(turn) - away.y * std::sin(turn),
                        away.x * std::sin(turn) + away.y * std::cos(turn));
    // The shadow's edge along c + rho u, by bisection on the closed-form predicate.
    double inside = r, outside = r + 0.2;
    ASSERT_FALSE(in_cylinder_shadow(c + outside * u, c, r, t, L));
    for (int i = 0; i < 60; ++i) {
      const double mid = 0.5 * (inside + outside);
      (in_cylinder_shadow(c + mid * u, c, r, t, L) ? inside : outside) = mid;
    }
    const cv::Point2d edge_table = c + inside * u;
    const cv::Point2d edge_px = project(shaded.camera(), {edge_table.x, edge_table.y, 0.0});
    // The rendered edge: scanning the image inwards along the same table line from beyond the
    // shadow, where the ratio first falls halfway to its darkest on the line.
    const cv::Point2d far_px =
        project(shaded.camera(), {c.x + (inside + 0.02) * u.x, c.y + (inside + 0.02) * u.y, 0});
    const cv::Point2d near_px = project(shaded.camera(), {c.x + r * u.x, c.y + r * u.y, 0});
    const double length = cv::norm(far_px - near_px);
    const cv::Point2d step = (near_px - far_px) / length * 0.05;
    double darkest = 1;
    for (double s = 0; s <= length; s += 0.05)
      darkest = std::min(darkest, bilinear(ratio, far_px + step * (s / 0.05)));
    ASSERT_LT(darkest, 0.8) << "no shadow along direction " << turn;
    const double half = 0.5 * (1 + darkest);
    double previous = bilinear(ratio, far_px);
    cv::Point2d found(-1, -1);
    for (int k = 1; k * 0.05 <= length; ++k) {
      const double v = bilinear(ratio, far_px + step * k);
      if (v < half) {
        const double f = (previous - half) / (previous - v);  // between samples k-1 and k
        found = far_px + step * (k - 1 + f);
        break;
      }
      previous = v;
    }
    const double error = cv::norm(found - edge_px);
    EXPECT_LT(error, 1.0) << "direction " << turn << ": rendered edge " << found << ", projected "
                          << edge_px;
    // Inside, halfway between the disk's footprint and the edge, the table keeps only the ambient
    // light: the ratio is ambient / (ambient + I (h / d)^3) there, whatever the table's colour
    // (darkened once, however many of the wall's flattened triangles cover the pixel). Where the
    // shadow is too thin for a point 2 px clear of both its ends, the edge alone is checked.
    const cv::Point2d mid_table = c + 0.5 * (r + inside) * u;
    const cv::Point2d mid_px = project(shaded.camera(), {mid_table.x, mid_table.y, 0.0});
    if (std::min(cv::norm(mid_px - edge_px), cv::norm(mid_px - near_px)) >= 2.0) {
      const double d2 =
          std::pow(mid_table.x - L[0], 2) + std::pow(mid_table.y - L[1], 2) + L[2] * L[2];
      const double direct = scene.lighting->intensity * std::pow(L[2] * L[2] / d2, 1.5);
      const double expected = scene.lighting->ambient / (scene.lighting->ambient + direct);
      // 8-bit frames: the shadowed table is about 17 grey levels, so half a level is 3 % of the
      // ratio (0.014; measured: at most 0.004 off).
      EXPECT_NEAR(bilinear(ratio, mid_px), expected, 0.02)
          << "inside the shadow, direction " << turn;
      ++inside_checked;
    }
    ++checked;
  }
  EXPECT_GE(checked, 12);
  EXPECT_GE(inside_checked, 6);
}

TEST(RenderLighting, WhereTheRayToTheLampCrossesBothWallsTheTableIsDarkenedOnce) {
  // A tall disk and a low lamp beyond it from the camera: the shadow, longer than the disk is
  // wide, falls towards the camera, where no wall hides the table in the image. Next to the
  // footprint the ray from a table point to the lamp passes through the wall twice under the
  // disk's top, so both walls' flattened triangles cover that point: it must still keep the
  // ambient light alone, ambient / (ambient + I (h / d)^3) of its lit level.
  Scene scene = lit_scene(2);
  scene.render.disk_thickness = 0.1;
  const cv::Point2d c(0.22, 0.2), camera_xy(0.05, 0.08);
  const cv::Point2d to_lamp = (c - camera_xy) / cv::norm(c - camera_xy);
  const cv::Point2d lamp_xy = c + 0.25 * to_lamp;
  const cv::Vec3d L(lamp_xy.x, lamp_xy.y, 0.2);
  scene.lighting->position = {L[0], L[1], L[2]};
  Renderer shaded(flatland_test::render_setup(scene));
  scene.lighting->shadows = false;
  Renderer unshaded(flatland_test::render_setup(scene));
  const SceneState st = disk_at(c.x, c.y);
  const cv::Mat with = grey(shaded.render_linear(st)), without = grey(unshaded.render_linear(st));
  cv::Mat ratio;
  cv::divide(with, cv::max(without, 1.0f), ratio);
  const double r = scene.sim.object.radius, t = scene.render.disk_thickness;
  const LightingSpec& lamp = *scene.lighting;
  int checked = 0;
  for (double turn = -0.3; turn <= 0.3; turn += 0.1) {
    const cv::Point2d away(-to_lamp.x * std::cos(turn) + to_lamp.y * std::sin(turn),
                           -to_lamp.x * std::sin(turn) - to_lamp.y * std::cos(turn));
    for (double rho = r + 0.004; rho < 3 * r; rho += 0.004) {
      const cv::Point2d x = c + rho * away;
      // Through both walls: the ray's trace over z in [0, t] starts and ends 2 mm or more
      // outside the cylinder and passes within r of its axis.
      const cv::Point2d top = x + (lamp_xy - x) * (t / L[2]);
      if (cv::norm(top - c) <= r + 0.002 || !in_cylinder_shadow(x, c, r, t, L)) continue;
      const cv::Point2d px = project(shaded.camera(), {x.x, x.y, 0.0});
      const double d2 = std::pow(x.x - L[0], 2) + std::pow(x.y - L[1], 2) + L[2] * L[2];
      const double direct = lamp.intensity * std::pow(L[2] * L[2] / d2, 1.5);
      // 8-bit frames: the shadowed table is about 15 grey levels (half a level: 0.02 of the
      // ratio; measured: at most 0.017 off); darkened twice it is 0.2 lower (measured).
      EXPECT_NEAR(bilinear(ratio, px), lamp.ambient / (lamp.ambient + direct), 0.03)
          << "table point " << x << " (" << rho << " m from the disk's centre)";
      ++checked;
    }
  }
  EXPECT_GE(checked, 50);
}

TEST(RenderLighting, ShadowsFallOnTheTableNotOnABoardHeldAboveIt) {
  // A chessboard held flat 0.15 m above the hand: the table under it is hidden, and so is the
  // hand's shadow there; the board itself shows no shadow (none is cast on boards). The board's
  // depth is in the frame, so the disk's shadow on the table is drawn through the depth test.
  Scene scene = lit_scene(2);
  TargetSpec board;
  board.position = {-0.2, -0.1, 0.15};
  scene.targets = {board};
  Renderer shaded(flatland_test::render_setup(scene));
  scene.lighting->shadows = false;
  Renderer unshaded(flatland_test::render_setup(scene));
  const cv::Point2d c(0.22, 0.2);
  const SceneState st = disk_at(c.x, c.y);
  const cv::Mat with = grey(shaded.render_linear(st)), without = grey(unshaded.render_linear(st));
  // The board's squares, 5 mm in from their edge, in the image.
  const double inset = 0.005, w = board.squares_x * board.square,
               h = board.squares_y * board.square;
  std::vector<cv::Point> corners;
  for (const cv::Point2d& q : {cv::Point2d(inset, inset), cv::Point2d(w - inset, inset),
                               cv::Point2d(w - inset, h - inset), cv::Point2d(inset, h - inset)}) {
    const cv::Point2d px = project(
        shaded.camera(), {board.position[0] + q.x, board.position[1] + q.y, board.position[2]});
    corners.emplace_back(static_cast<int>(std::lround(px.x)), static_cast<int>(std::lround(px.y)));
  }
  cv::Mat on_board = cv::Mat::zeros(with.size(), CV_8U);
  cv::fillConvexPoly(on_board, corners, cv::Scalar(255));
  ASSERT_GT(cv::countNonZero(on_board), 10000);
  cv::Mat difference = cv::abs(with - without);
  double most = 0;
  cv::minMaxLoc(difference, nullptr, &most, nullptr, nullptr, on_board);
  EXPECT_EQ(most, 0.0) << "a shadow drawn on the board held above the table";
  // The disk's shadow on the table, straight away from the lamp, halfway between the footprint
  // and the shadow's end: the table keeps its ambient light.
  const double r = scene.sim.object.radius, t = scene.render.disk_thickness;
  const cv::Vec3d L(scene.lighting->position[0], scene.lighting->position[1],
                    scene.lighting->position[2]);
  const cv::Point2d away = cv::Point2d(c.x - L[0], c.y - L[1]) / std::hypot(c.x - L[0], c.y - L[1]);
  double inside = r, outside = r + 0.2;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (inside + outside);
    (in_cylinder_shadow(c + mid * away, c, r, t, L) ? inside : outside) = mid;
  }
  const cv::Point2d x = c + 0.5 * (r + inside) * away;
  const double d2 = std::pow(x.x - L[0], 2) + std::pow(x.y - L[1], 2) + L[2] * L[2];
  const double direct = scene.lighting->intensity * std::pow(L[2] * L[2] / d2, 1.5);
  const cv::Point2d px = project(shaded.camera(), {x.x, x.y, 0.0});
  EXPECT_NEAR(bilinear(with, px) / bilinear(without, px),
              scene.lighting->ambient / (scene.lighting->ambient + direct), 0.02);
}

TEST(RenderLighting, TableBrightnessFollowsTheInverseSquareAndTheCosine) {
  // Against the same lamp taken as distant (falloff off: the table lit evenly at the level under
  // the lamp), the ratio at a table point x is (ambient + I h^2 cos / d^2) / (ambient + I) with
  // cos = h / d: the table's colour cancels.
  Scene scene = lit_scene(1);
  scene.lighting->shadows = false;
  Renderer near_lamp(flatland_test::render_setup(scene));
  scene.lighting->falloff = false;
  Renderer distant(flatland_test::render_setup(scene));
  // The hand lies within 0.23 m of the pivot and the disk's shadow is off: table points beyond.
  const SceneState st = disk_at(0.12, 0.21);
  const cv::Mat a = near_lamp.render_linear(st), b = distant.render_linear(st);
  const LightingSpec& lamp = *scene.lighting;
  const cv::Vec3d L(lamp.position[0], lamp.position[1], lamp.position[2]);
  double lowest = 1;
  for (const cv::Point2d x :
       {cv::Point2d(-0.28, 0.32), cv::Point2d(-0.28, -0.16), cv::Point2d(0.38, 0.32),
        cv::Point2d(0.38, -0.16), cv::Point2d(0.38, 0.08), cv::Point2d(-0.05, 0.33)}) {
    const double d = std::sqrt(std::pow(x.x - L[0], 2) + std::pow(x.y - L[1], 2) + L[2] * L[2]);
    const double g = std::pow(L[2] / d, 3);  // h^2 / d^2 times cos = h / d
    lowest = std::min(lowest, g);
    const double expected = (lamp.ambient + lamp.intensity * g) / (lamp.ambient + lamp.intensity);
    const cv::Point2d px = project(near_lamp.camera(), {x.x, x.y, 0.0});
    const cv::Point ip(static_cast<int>(std::lround(px.x)), static_cast<int>(std::lround(px.y)));
    ASSERT_TRUE(cv::Rect(0, 0, a.cols, a.rows).contains(ip));
    for (int ch = 0; ch < 3; ++ch) {
      // Both frames come from 8-bit GL colour: each value within half a level.
      const double lit = a.at<cv::Vec3f>(ip)[ch], even = b.at<cv::Vec3f>(ip)[ch];
      EXPECT_NEAR(lit, expected * even, 0.5 + 0.5 * expected + 1e-3)
          << "table point " << x << " channel " << ch;
    }
  }
  EXPECT_LT(lowest, 0.6);  // the points span a strong fall-off: the test can tell it apart
}

TEST(RenderLighting, BandHighlightsSitWhereTheTorusNormalBisectsLampAndCamera) {
  // 4 x 4 samples a pixel: at shininess 200 the highlight is an arc a fraction of a pixel wide
  // across the band, which 2 x 2 samples alias (its centroid 0.7 px off at 2 x 2, 0.3 px at 3 x 3).
  Scene scene = lit_scene(4);
  scene.render.disk_thickness = 0.006;
  scene.lighting->shadows = false;
  scene.lighting->position = {0.2, 0.25, 1.2};
  scene.lighting->face.specular = 0;  // only the band shines
  scene.lighting->hand.specular = 0;
  scene.lighting->band = {0.8, 200.0};
  Renderer glossy(flatland_test::render_setup(scene));
  scene.lighting->specular = false;
  Renderer matte(flatland_test::render_setup(scene));
  const cv::Point2d c(-0.2, 0.28);  // clear of the hand (within 0.23 m of the pivot)
  const SceneState st = disk_at(c.x, c.y);
  const cv::Mat highlight = grey(glossy.render_linear(st)) - grey(matte.render_linear(st));
  // The O-ring's top as a torus over the band (its outer 8 % of the radius, drawn flat at the
  // disk's top): at azimuth phi and u in [-1, 1] across the band, the normal is
  // (u e_r, sqrt(1 - u^2)). Its highlight is ks E (n . h)^shininess, with h the half-vector of
  // the directions to the lamp and to the camera and E the lamp's direct light there (the inverse
  // square, 1 under the lamp). A torus seen from above shows two highlights: on the band's outer
  // half on the side towards h, and on its inner half on the far side, where the normal, tilted
  // towards the centre, faces h as well (n(phi, u) = n(phi + pi, -u)). Predicted here, for each
  // side: that light integrated over the band's area (its total, in grey levels, and its
  // centroid projected into the image). A pixel's value is the mean over its area, so the frame's
  // sum and centroid over the pixels are the same integrals.
  const double r = scene.sim.object.radius, t = scene.render.disk_thickness;
  const double band_mid = r * (1 - 0.04), band_half = r * 0.04;
  const LightingSpec& lamp = *scene.lighting;
  const cv::Vec3d L(lamp.position[0], lamp.position[1], lamp.position[2]);
  const cv::Vec3d E(0.05, 0.08, 1.0);
  const cv::Vec3d top_center(c.x, c.y, t);
  const cv::Vec3d h_center =
      cv::normalize(cv::normalize(L - top_center) + cv::normalize(E - top_center));
  const int n_phi = 3600, n_u = 400;
  // Straight down from E: a table-parallel area A covers A (f / (E.z - t))^2 pixels.
  const double pixel_area = std::pow((E[2] - t) / 900.0, 2);
  const double sample_area = (2 * band_half / n_u) * (2 * std::numbers::pi / n_phi);
  double total[2] = {0, 0};  // grey levels x pixels; [0]: the side towards h, [1]: the far side
  cv::Point2d moment[2];
  for (int i = 0; i < n_phi; ++i) {
    const double phi = 2 * std::numbers::pi * (i + 0.5) / n_phi;
    const cv::Vec3d er(std::cos(phi), std::sin(phi), 0);
    const int side = er.dot(h_center) >= 0 ? 0 : 1;
    std::vector<cv::Point3d> points(n_u);
    std::vector<double> level(n_u);
    for (int j = 0; j < n_u; ++j) {
      const double u = -1 + (j + 0.5) * 2 / n_u;
      const double rho = band_mid + u * band_half;
      const cv::Vec3d p = top_center + rho * er;
      const cv::Vec3d n = u * er + cv::Vec3d(0, 0, std::sqrt(1 - u * u));
      const cv::Vec3d to_lamp = L - p;
      const cv::Vec3d h = cv::normalize(cv::normalize(to_lamp) + cv::normalize(E - p));
      const double direct = lamp.intensity * L[2] * L[2] / to_lamp.dot(to_lamp);
      level[j] = 255 * lamp.band.specular * direct *
                 std::pow(std::max(n.dot(h), 0.0), lamp.band.shininess) * rho * sample_area /
                 pixel_area;
      points[j] = {p[0], p[1], p[2]};
    }
    const std::vector<cv::Point2d> px = glossy.camera().project(points);
    for (int j = 0; j < n_u; ++j) {
      total[side] += level[j];
      moment[side] += level[j] * px[j];
    }
  }
  // The frame's, split by the same line through the disk's centre.
  const cv::Point2d center_px = project(glossy.camera(), top_center);
  const cv::Point2d towards_px = moment[0] / total[0] - center_px;
  const double reach = 3 * cv::norm(towards_px);  // nothing else shines: the disk's surroundings
  double sum[2] = {0, 0}, peak[2] = {0, 0};
  cv::Point2d rendered_moment[2];
  for (int y = 0; y < highlight.rows; ++y)
    for (int x = 0; x < highlight.cols; ++x) {
      const double v = highlight.at<float>(y, x);
      const cv::Point2d q(x, y);
      if (v <= 0 || cv::norm(q - center_px) > reach) continue;
      const int side = (q - center_px).dot(towards_px) >= 0 ? 0 : 1;
      sum[side] += v;
      rendered_moment[side] += v * q;
      peak[side] = std::max(peak[side], v);
    }
  for (int side = 0; side < 2; ++side) {
    ASSERT_GT(peak[side], 20.0) << "no highlight on the band's side " << side;
    // 8-bit frames: each sample of the glossy and of the matte frame is rounded, which loses the
    // highlight's long faint tails along the arc where they fall under half a level, and shifts
    // its centroid along the arc by up to 0.3 px (measured at five disk positions: 0.02-0.31 px).
    EXPECT_NEAR(sum[side] / total[side], 1.0, 0.03) << "side " << side;
    const cv::Point2d rendered = rendered_moment[side] / sum[side];
    const cv::Point2d predicted = moment[side] / total[side];
    EXPECT_LT(cv::norm(rendered - predicted), 0.5)
        << "side " << side << ": rendered highlight " << rendered << ", predicted " << predicted;
  }
}

TEST(RenderLighting, WithoutTheSectionTheTableIsEvenAndWithItItIsNot) {
  Scene scene = lit_scene(1);
  const SceneState st = disk_at(0.3, 0.3);
  Renderer lit(flatland_test::render_setup(scene));
  scene.lighting.reset();
  Renderer plain(flatland_test::render_setup(scene));
  const cv::Point2d corners[] = {{5, 5}, {634, 5}, {5, 474}, {634, 474}};
  const cv::Mat a = grey(plain.render_linear(st)), b = grey(lit.render_linear(st));
  for (const cv::Point2d& p : corners) {
    EXPECT_EQ(a.at<float>(cv::Point(p)), a.at<float>(5, 5)) << "unlit corner " << p;
  }
  double lo = 255, hi = 0;
  for (const cv::Point2d& p : corners) {
    lo = std::min<double>(lo, b.at<float>(cv::Point(p)));
    hi = std::max<double>(hi, b.at<float>(cv::Point(p)));
  }
  EXPECT_GT(hi - lo, 5.0) << "the lamp lights the table's corners unevenly";
}

TEST(RenderLighting, ALampBelowTheHandsTopIsRefusedNamingTheField) {
  Scene scene = lit_scene(1);
  scene.lighting->position = {0.0, 0.0, 0.01};
  try {
    Renderer r(flatland_test::render_setup(scene));
    FAIL() << "a lamp under the hand's top was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("lighting.position"), std::string::npos) << e.what();
  }
}
