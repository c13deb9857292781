// The obvious OpenCV disk tracker, kept as the peer the edge fit is measured against
// (TrackMethod::kContour; docs/VISION.md, docs/BENCHMARKS.md): grey in the frame's own type,
// Otsu's threshold, cv::findContours, and cv::fitEllipse on the chosen outline. It is written as
// one would write it with OpenCV alone, so that the comparison is with what a user would
// otherwise do, not with a strawman: the whole frame at full resolution when there is no track, a
// window around the prediction when there is one.
#include "flatland/vision/tracker.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace flatland::vision {

TrackResult fit_contour(const cv::Mat& gray_u8, std::optional<cv::Point2d> prediction,
                        double expected_edge_radius_px) {
  if (gray_u8.type() != CV_8UC1)
    throw std::invalid_argument("fit_contour: expected an 8-bit single-channel image");
  TrackResult res;
  cv::Mat bin;
  cv::threshold(gray_u8, bin, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(bin, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  double best_score = -std::numeric_limits<double>::infinity();
  for (const std::vector<cv::Point>& outline : contours) {
    if (outline.size() < 20) continue;  // too few points for a meaningful ellipse
    const double area = cv::contourArea(outline);
    if (area < 30) continue;
    const cv::RotatedRect e = cv::fitEllipse(outline);
    const double a = 0.5 * std::max(e.size.width, e.size.height);
    const double b = 0.5 * std::min(e.size.width, e.size.height);
    if (!(b > 0) || b / a < 0.8) continue;  // the disk seen from above is round
    const double fill = area / (std::numbers::pi * a * b);
    if (fill < 0.8 || fill > 1.2) continue;  // a round outline, not a crescent or a lobe
    // The outline runs through the centres of the blob's boundary pixels, half a pixel inside
    // the edge.
    const double radius = 0.5 * (a + b) + 0.5;
    if (expected_edge_radius_px > 0 &&
        std::abs(radius - expected_edge_radius_px) > 0.25 * expected_edge_radius_px)
      continue;
    const cv::Point2d centre(e.center.x, e.center.y);
    const double score = prediction ? -cv::norm(centre - *prediction) : area * b / a;
    if (score <= best_score) continue;
    best_score = score;
    // The spread of the outline about the fitted circle, propagated to the centre of n points
    // spread evenly around it (sigma_r sqrt(2 / n) per coordinate).
    double sum2 = 0;
    for (const cv::Point& p : outline) {
      const double d = cv::norm(cv::Point2d(p.x, p.y) - centre) - (radius - 0.5);
      sum2 += d * d;
    }
    const double n = static_cast<double>(outline.size());
    res.state = TrackState::kTracking;
    res.center = centre;
    res.radius_px = radius;
    res.sigma_px = std::sqrt(sum2 / n) * std::sqrt(2.0 / n);
    res.quality = std::clamp(b / a, 0.0, 1.0);
    res.edge_points = static_cast<int>(outline.size());
  }
  return res;
}

}  // namespace flatland::vision
