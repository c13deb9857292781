// Overlay text (render --overlay, experiment --video) stays clear of the disk: the block goes to
// the corner farthest from the disk's image, checked against the disk projected through a camera
// 1.2 m above the table, wherever the disk is in view (the top of the frame included).
#include "flatland/camera/camera_model.hpp"
#include "flatland/render/overlay_text.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <string>
#include <vector>

using namespace flatland;

namespace {

// 640 x 480, f = 900 px, looking straight down from 1.2 m: x_cam = x, y_cam = -y, z_cam = 1.2 - z.
camera::CameraModel overhead_camera() {
  camera::CameraModel c;
  c.K = cv::Matx33d(900, 0, 319.5, 0, 900, 239.5, 0, 0, 1);
  c.R = cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1);
  c.t = cv::Vec3d(0, 0, 1.2);
  return c;
}

}  // namespace

TEST(OverlayText, TheBlockGoesToTheCornerFarthestFromTheCircle) {
  const cv::Size image(640, 480), block(200, 60);
  // No circle: the top-left corner.
  EXPECT_EQ(render::place_text_block(image, block, {}, 5), cv::Rect(5, 5, 200, 60));
  // A circle near the top-left: the bottom-right corner, the farthest.
  EXPECT_EQ(render::place_text_block(image, block, {{{60, 40}, 30}}, 5),
            cv::Rect(435, 415, 200, 60));
  // Near the top-right: the bottom-left.
  EXPECT_EQ(render::place_text_block(image, block, {{{600, 30}, 30}}, 5),
            cv::Rect(5, 415, 200, 60));
}

TEST(OverlayText, TextNeverCoversTheProjectedDisk) {
  const camera::CameraModel camera = overhead_camera();
  constexpr double kRadius = 0.051, kTop = 0.006;  // the paper's disk, its top face
  const std::vector<std::string> lines = {"t = 1.234 s", "s_h = +0.123  rolling",
                                          "f/(m g sin tilt) = 0.912 (n +0.900, t -0.100)"};
  int placements = 0;
  // Disk centres over the whole view: x in [-0.36, 0.36], y in [-0.26, 0.26] m.
  for (double x = -0.36; x <= 0.36 + 1e-9; x += 0.06)
    for (double y = -0.26; y <= 0.26 + 1e-9; y += 0.052) {
      const cv::Point2d centre = camera.project(cv::Point3d(x, y, kTop));
      const render::KeepClear disk =
          render::disk_in_image(centre, camera.project(cv::Point3d(x + kRadius, y, kTop)));
      cv::Mat bgr(480, 640, CV_8UC3, cv::Scalar::all(0));
      const cv::Rect block = render::draw_text_block(bgr, lines, 0.42, 1, {disk});
      // Every drawn pixel is in the block, and none within the disk's image.
      cv::Mat drawn;
      cv::cvtColor(bgr, drawn, cv::COLOR_BGR2GRAY);
      for (int r = 0; r < drawn.rows; ++r)
        for (int c = 0; c < drawn.cols; ++c) {
          if (drawn.at<unsigned char>(r, c) == 0) continue;
          EXPECT_TRUE(block.contains(cv::Point(c, r))) << "pixel " << c << ", " << r;
          ASSERT_GT(std::hypot(c - centre.x, r - centre.y), disk.radius)
              << "text over the disk at (" << x << ", " << y << ") m, pixel " << c << ", " << r;
        }
      ++placements;
    }
  EXPECT_EQ(placements, 13 * 11);
}
