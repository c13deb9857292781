// Text drawn over a frame (render --overlay, experiment --video): a block of lines placed in the
// image corner farthest from what it must not hide, the disk's image.
#pragma once

#include <opencv2/core.hpp>

#include <string>
#include <vector>

namespace flatland::render {

/// A circle in the image (px) that text must keep clear of: the disk's image.
struct KeepClear {
  cv::Point2d center;
  double radius = 0;
};

/// The disk's image: the circle through its projected centre and a point of its rim, both on
/// its top face (projected by the caller).
KeepClear disk_in_image(cv::Point2d center_px, cv::Point2d rim_px);

/// Where a block of `block` px goes in an image of `image` px: the one of the four corners
/// (`margin` px in from the edges) whose rectangle is farthest from every circle to keep clear
/// (the clearance between a rectangle and a circle: the distance from the circle's centre to
/// the rectangle, minus its radius). Ties and no circles: the top-left corner.
cv::Rect place_text_block(cv::Size image, cv::Size block, const std::vector<KeepClear>& keep,
                          int margin);

/// Draws `lines` (cv::FONT_HERSHEY_SIMPLEX at `font`, white, or `colours[i]` where given, on a
/// black outline) as one block placed by place_text_block; returns the block's rectangle.
cv::Rect draw_text_block(cv::Mat& bgr, const std::vector<std::string>& lines, double font,
                         int thickness, const std::vector<KeepClear>& keep,
                         const std::vector<cv::Scalar>& colours = {});

}  // namespace flatland::render
