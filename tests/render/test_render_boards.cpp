// Renderer::set_boards against the independent way of drawing the same boards: a renderer made
// afresh from a scene with those boards. Moved boards must give the same frames and masks, pixel
// for pixel, with and without the lamp (whose table and boards are drawn once, beforehand); a
// board the scene file could not name is refused, naming it, and leaves the boards as they were.
// Checked to fail: set_boards without redrawing the lamp's background, and without clearing the
// old boards.
#include "flatland/render/renderer.hpp"
#include "render_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

using namespace flatland;
using namespace flatland::render;

namespace {

// Two boards the calibration session could film: a chessboard flat on the table and a ChArUco
// board tilted above it.
std::vector<TargetSpec> two_boards() {
  TargetSpec chess;
  chess.position = {-0.25, -0.15, 0.0};
  chess.rotation = {0.0, 0.0, 0.2};
  TargetSpec charuco;
  charuco.kind = TargetSpec::Kind::kCharuco;
  charuco.squares_x = 6;
  charuco.squares_y = 5;
  charuco.square = 0.03;
  charuco.marker = 0.022;
  charuco.position = {0.05, 0.05, 0.04};
  charuco.rotation = {0.3, -0.2, 0.1};
  return {chess, charuco};
}

Scene with_boards(Scene s, std::vector<TargetSpec> boards) {
  s.targets = std::move(boards);
  return s;
}

double largest_difference(const cv::Mat& a, const cv::Mat& b) {
  EXPECT_EQ(a.size(), b.size());
  EXPECT_EQ(a.type(), b.type());
  return cv::norm(a, b, cv::NORM_INF);
}

void expect_moved_boards_draw_as_a_new_renderer(const Scene& base) {
  SceneState st;
  st.hand_angle = 0.4;
  st.disk_center = {0.2, 0.15};
  const Scene filmed = with_boards(base, two_boards());
  Renderer fresh(flatland_test::render_setup(filmed));
  // Made with one other board, then given the two.
  TargetSpec elsewhere;
  elsewhere.position = {0.1, -0.3, 0.0};
  Renderer moved(flatland_test::render_setup(with_boards(base, {elsewhere})));
  moved.set_boards(flatland_test::render_setup(filmed).boards);
  EXPECT_EQ(largest_difference(moved.render_linear(st), fresh.render_linear(st)), 0.0);
  EXPECT_EQ(largest_difference(moved.render_mask(st), fresh.render_mask(st)), 0.0);
  // And then none.
  Renderer bare(flatland_test::render_setup(base));
  moved.set_boards({});
  EXPECT_EQ(largest_difference(moved.render_linear(st), bare.render_linear(st)), 0.0);
  EXPECT_EQ(largest_difference(moved.render_mask(st), bare.render_mask(st)), 0.0);
}

}  // namespace

TEST(RenderBoards, MovedBoardsDrawAsANewRenderersBoards) {
  expect_moved_boards_draw_as_a_new_renderer(flatland_test::overhead_scene(2));
}

TEST(RenderBoards, MovedBoardsDrawAsANewRenderersBoardsUnderTheLamp) {
  Scene lamp_lit = flatland_test::overhead_scene(2);
  LightingSpec lamp;
  lamp.position = {-0.15, 0.05, 0.6};
  lamp_lit.lighting = lamp;
  expect_moved_boards_draw_as_a_new_renderer(lamp_lit);
}

TEST(RenderBoards, ABoardTheSceneCouldNotNameIsRefusedAndNothingChanges) {
  const Scene filmed = with_boards(flatland_test::overhead_scene(1), two_boards());
  Renderer r(flatland_test::render_setup(filmed));
  SceneState st;
  st.disk_center = {0.2, 0.15};
  const cv::Mat before = r.render_linear(st);
  std::vector<camera::PlacedBoard> boards = flatland_test::render_setup(filmed).boards;
  boards[0].board.squares_x = 2;  // one column of inner corners: no board OpenCV can find
  try {
    r.set_boards(boards);
    ADD_FAILURE() << "a board of 2 squares was drawn";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()).rfind("boards[0]", 0), 0u) << e.what();
  }
  boards = flatland_test::render_setup(filmed).boards;
  boards[1].position[2] = std::nan("");
  EXPECT_THROW(r.set_boards(boards), std::invalid_argument);
  EXPECT_EQ(largest_difference(r.render_linear(st), before), 0.0);
}
