// Overlay text placed clear of the disk (see overlay_text.hpp).
#include "flatland/render/overlay_text.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace flatland::render {

KeepClear disk_in_image(cv::Point2d center_px, cv::Point2d rim_px) {
  return {center_px, cv::norm(rim_px - center_px)};
}

cv::Rect place_text_block(cv::Size image, cv::Size block, const std::vector<KeepClear>& keep,
                          int margin) {
  const int left = margin, top = margin;
  const int right = std::max(margin, image.width - margin - block.width);
  const int bottom = std::max(margin, image.height - margin - block.height);
  const std::array<cv::Rect, 4> corners = {cv::Rect(left, top, block.width, block.height),
                                           cv::Rect(right, top, block.width, block.height),
                                           cv::Rect(left, bottom, block.width, block.height),
                                           cv::Rect(right, bottom, block.width, block.height)};
  cv::Rect best = corners[0];
  double best_clearance = -std::numeric_limits<double>::infinity();
  for (const cv::Rect& r : corners) {
    double clearance = std::numeric_limits<double>::infinity();
    for (const KeepClear& k : keep) {
      if (!std::isfinite(k.center.x) || !std::isfinite(k.center.y)) continue;
      const double dx = std::max({r.x - k.center.x, 0.0, k.center.x - (r.x + r.width)});
      const double dy = std::max({r.y - k.center.y, 0.0, k.center.y - (r.y + r.height)});
      clearance = std::min(clearance, std::hypot(dx, dy) - k.radius);
    }
    if (clearance > best_clearance) {
      best_clearance = clearance;
      best = r;
    }
  }
  return best;
}

cv::Rect draw_text_block(cv::Mat& bgr, const std::vector<std::string>& lines, double font,
                         int thickness, const std::vector<KeepClear>& keep,
                         const std::vector<cv::Scalar>& colours) {
  // Each line's box as cv::putText draws it, the outline (thickness + 2) included.
  const int outline = thickness + 2;
  int width = 0, line_height = 0, baseline = 0;
  for (const std::string& line : lines) {
    const cv::Size s = cv::getTextSize(line, cv::FONT_HERSHEY_SIMPLEX, font, outline, &baseline);
    width = std::max(width, s.width + outline);
    line_height = std::max(line_height, s.height + baseline + outline);
  }
  const int gap = std::max(2, line_height / 4);
  const int height = static_cast<int>(lines.size()) * (line_height + gap) - gap;
  const int margin = std::max(4, line_height / 3);
  const cv::Rect block = place_text_block(bgr.size(), cv::Size(width, height), keep, margin);
  const cv::Scalar black(0, 0, 0), white(255, 255, 255);
  for (std::size_t i = 0; i < lines.size(); ++i) {
    // putText's origin is the baseline's left end: below the ascent, above the descent.
    const cv::Point at(block.x + outline / 2, block.y + static_cast<int>(i) * (line_height + gap) +
                                                  line_height - baseline - outline / 2);
    const cv::Scalar fg = i < colours.size() ? colours[i] : white;
    cv::putText(bgr, lines[i], at, cv::FONT_HERSHEY_SIMPLEX, font, black, outline, cv::LINE_AA);
    cv::putText(bgr, lines[i], at, cv::FONT_HERSHEY_SIMPLEX, font, fg, thickness, cv::LINE_AA);
  }
  return block;
}

}  // namespace flatland::render
