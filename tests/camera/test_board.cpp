// camera::Board and PlacedBoard: the corners in the table frame against an independent
// construction, the scene's targets compiled to the same boards, and one ArUco dictionary table:
// every name the scene loader accepts is one OpenCV's aruco module knows, and the reverse.
#include "flatland/camera/board.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

namespace {

using namespace flatland;

const std::string kScene = R"(gravity: {g: 9.8}
hand: {shape: polynomial, a: 0.18, b: -0.18, c: -0.252, d: 0.216}
object: {type: disk, radius: 0.051}
motion: {type: butterfly, period: 1.181, k: -1.1393}
)";

std::string target_scene(const std::string& dictionary) {
  return kScene + "targets:\n  - type: charuco\n    cols: 5\n    rows: 4\n    square: 0.04\n" +
         "    dictionary: " + dictionary + "\n";
}

TEST(Board, EveryDictionaryNameIsOpenCvsAndTheScenesAndNoOther) {
  const auto& names = camera::aruco_dictionary_names();
  ASSERT_EQ(names.size(), 21u);
  for (std::size_t i = 0; i < names.size(); ++i) {
    EXPECT_EQ(camera::aruco_dictionary_id(names[i]), static_cast<int>(i));
    // OpenCV's enum value i is the dictionary of that name: DICT_4X4_* have 4x4 bits, and so on.
    const auto dict =
        cv::aruco::getPredefinedDictionary(cv::aruco::PREDEFINED_DICTIONARY_NAME(int(i)));
    if (names[i].rfind("DICT_", 0) == 0 && names[i][5] >= '4' && names[i][5] <= '7') {
      EXPECT_EQ(dict->markerSize, names[i][5] - '0') << names[i];
    }
    // The scene loader accepts it, and the compile step turns it into the same board.
    const Scene s = parse_scene(target_scene(names[i]), "x.yaml");
    EXPECT_EQ(model::compile_target(s.targets.at(0)).board.dictionary, names[i]);
  }
  EXPECT_FALSE(camera::aruco_dictionary_id("DICT_3X3_50").has_value());
  EXPECT_THROW(parse_scene(target_scene("DICT_3X3_50"), "x.yaml"), SceneError);
  TargetSpec unknown;
  unknown.dictionary = "DICT_3X3_50";
  EXPECT_THROW(model::compile_target(unknown), std::invalid_argument);
}

TEST(Board, CornersInTableAreTheBoardsObjectPointsPlaced) {
  camera::PlacedBoard placed;
  placed.board = camera::Board::parse("chessboard:5x4:0.03");
  placed.position = {0.1, -0.2, 0.004};
  placed.rotation = {0.1, -0.2, 0.7};
  const std::vector<cv::Point3d> corners = camera::corners_in_table(placed);
  const std::vector<cv::Point3f> object = placed.board.corners();  // OpenCV's board frame
  ASSERT_EQ(corners.size(), 20u);
  ASSERT_EQ(object.size(), 20u);
  // OpenCV's frame runs y down the print, ours up it: flip y about the board's height, then
  // place with the rotation and position.
  cv::Matx33d R;
  cv::Rodrigues(placed.rotation, R);
  const double height = placed.board.squares_y * placed.board.square;
  // Board::corners() is in float (cv::Point3f, as OpenCV's object points): 2e-8 m.
  for (std::size_t k = 0; k < corners.size(); ++k) {
    const cv::Vec3d ours(object[k].x, height - object[k].y, 0);
    const cv::Vec3d expected = R * ours + placed.position;
    EXPECT_NEAR(corners[k].x, expected[0], 2e-8);
    EXPECT_NEAR(corners[k].y, expected[1], 2e-8);
    EXPECT_NEAR(corners[k].z, expected[2], 2e-8);
  }
  // Neighbours along a row are one square apart.
  EXPECT_NEAR(cv::norm(corners[1] - corners[0]), 0.03, 1e-12);
}

TEST(Board, SceneTargetCompilesToTheSameBoardAsItsNotation) {
  const Scene s = parse_scene(kScene +
                                  "targets:\n  - type: chessboard\n    cols: 9\n    rows: 6\n"
                                  "    square: 0.025\n    position: [0.1, 0.2, 0.001]\n",
                              "x.yaml");
  const camera::PlacedBoard placed = model::compile_target(s.targets.at(0));
  const camera::Board notation = camera::Board::parse("chessboard:9x6:0.025");
  EXPECT_EQ(placed.board.notation(), notation.notation());
  EXPECT_EQ(placed.board.squares_x, notation.squares_x);
  EXPECT_EQ(placed.board.squares_y, notation.squares_y);
  EXPECT_EQ(placed.position, cv::Vec3d(0.1, 0.2, 0.001));
}

}  // namespace
