// A spatial scene's frames (render::SpatialBodies): the ball drawn through the camera model lands
// where the camera model projects it, with the silhouette a sphere has, and turns with its pose.
#include "flatland/model/compile.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/spatial.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <numbers>

namespace flatland::render {
namespace {

struct SpatialView {
  RenderSetup setup;
  cv::Vec3d ball{0.03, -0.02, 0.02};
  double radius = 0.02;
  SpatialView() {
    CameraSpec cam;
    cam.width = 320;
    cam.height = 240;
    cam.fx = cam.fy = 400;
    cam.cx = 159.5;
    cam.cy = 119.5;
    cam.position = {0.15, -0.35, 0.3};
    cam.look_at = {ball[0], ball[1], ball[2]};  // the ball's centre on the optical axis
    cam.up = {0, 0, 1};
    setup.camera = model::compile_camera(cam);
    setup.effects.supersample = 4;
    setup.render.table_extent = 0.3;
    setup.spatial = SpatialBodies{std::make_shared<sim::PlaneSurface>(
                                      sim::Vec3::Zero(), sim::Vec3::UnitX(), sim::Vec3::UnitY()),
                                  sim::uniform_ball(radius).surface,
                                  {{-0.3, -0.3}, {0.3, 0.3}}};
  }
  SceneState at(const cv::Vec3d& centre, double turn = 0) const {
    SceneState st;
    SpatialPose pose;
    pose.object_position = centre;
    const double c = std::cos(turn), s = std::sin(turn);
    pose.object_rotation = cv::Matx33d(c, -s, 0, s, c, 0, 0, 0, 1);
    st.spatial = pose;
    return st;
  }
};

TEST(RenderSpatial, TheBallLandsWhereTheCameraModelProjectsItWithASpheresSilhouette) {
  const SpatialView v;
  Renderer renderer(v.setup);
  const cv::Mat with = renderer.render_8u(v.at(v.ball));
  // The same view with the ball under the plate (hidden by it): the difference is the ball.
  const cv::Mat without = renderer.render_8u(v.at({0, 0, -0.5}));
  cv::Mat diff, gray, mask;
  cv::absdiff(with, without, diff);
  cv::cvtColor(diff, gray, cv::COLOR_BGR2GRAY);
  cv::threshold(gray, mask, 8, 255, cv::THRESH_BINARY);
  const cv::Moments m = cv::moments(mask, true);
  ASSERT_GT(m.m00, 100);
  const cv::Point2d centroid(m.m10 / m.m00, m.m01 / m.m00);
  const cv::Point2d expected =
      renderer.camera().project(cv::Point3d(v.ball[0], v.ball[1], v.ball[2]));
  EXPECT_NEAR(expected.x, 159.5, 1e-9);  // on the optical axis
  EXPECT_NEAR(centroid.x, expected.x, 0.3);
  EXPECT_NEAR(centroid.y, expected.y, 0.3);
  // On the axis a sphere's silhouette is a circle of radius f r / sqrt(D^2 - r^2).
  const cv::Vec3d eye(0.15, -0.35, 0.3);
  const double D = cv::norm(eye - v.ball);
  const double rho = 400 * v.radius / std::sqrt(D * D - v.radius * v.radius);
  EXPECT_NEAR(m.m00 / (std::numbers::pi * rho * rho), 1.0, 0.03) << "radius " << rho << " px";
  const FrameTruth truth = renderer.truth(v.at(v.ball));
  EXPECT_NEAR(truth.disk_center_px.x, expected.x, 1e-9);
  EXPECT_NEAR(truth.disk_center_px.y, expected.y, 1e-9);
}

TEST(RenderSpatial, TheBallsCellsTurnWithItsPose) {
  const SpatialView v;
  Renderer renderer(v.setup);
  const cv::Mat a = renderer.render_8u(v.at(v.ball, 0.0));
  const cv::Mat b = renderer.render_8u(v.at(v.ball, 0.3));
  // A quarter turn of its 8 cells along the equator (pi/4 each) brings the pattern back.
  const cv::Mat c = renderer.render_8u(v.at(v.ball, std::numbers::pi / 2));
  cv::Mat d_ab, d_ac;
  cv::absdiff(a, b, d_ab);
  cv::absdiff(a, c, d_ac);
  EXPECT_GT(cv::norm(d_ab, cv::NORM_L1), 50.0 * cv::norm(d_ac, cv::NORM_L1) + 1e4);
  // A spatial frame without poses is refused.
  EXPECT_THROW(renderer.render_8u(SceneState{}), std::invalid_argument);
}

}  // namespace
}  // namespace flatland::render
