// Calibration pictures (see report.hpp).
#include "flatland/calibration/report.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

namespace flatland::calibration {

namespace {

constexpr int kCellsX = 8, kCellsY = 6;

cv::Mat to_bgr(const cv::Mat& image) {
  cv::Mat bgr;
  if (image.channels() == 1)
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  else
    bgr = image.clone();
  return bgr;
}

void caption(cv::Mat& image, const std::string& text, int line) {
  const double scale = std::max(0.45, image.cols / 1400.0);
  const cv::Point at(8, static_cast<int>((line + 1) * 26 * scale / 0.6));
  cv::putText(image, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 3,
              cv::LINE_AA);
  cv::putText(image, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
}

std::vector<std::vector<int>> cell_counts(const IntrinsicsResult& result,
                                          const std::vector<BoardView>& views) {
  std::vector<std::vector<int>> counts(kCellsY, std::vector<int>(kCellsX, 0));
  const cv::Size size = result.image_size;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (i >= result.used.size() || !result.used[i]) continue;
    for (const cv::Point2f& p : views[i].image_points) {
      const int cx = std::clamp(static_cast<int>(p.x * kCellsX / size.width), 0, kCellsX - 1);
      const int cy = std::clamp(static_cast<int>(p.y * kCellsY / size.height), 0, kCellsY - 1);
      ++counts[static_cast<std::size_t>(cy)][static_cast<std::size_t>(cx)];
    }
  }
  return counts;
}

}  // namespace

std::vector<cv::Point2f> reprojected_corners(const IntrinsicsResult& result,
                                             const std::vector<BoardView>& views, std::size_t i) {
  std::vector<cv::Point2f> out;
  if (views[i].object_points.empty()) return out;
  cv::projectPoints(views[i].object_points, result.rvecs[i], result.tvecs[i], result.K, result.dist,
                    out);
  return out;
}

cv::Mat draw_view_residuals(const cv::Mat& image, const IntrinsicsResult& result,
                            const std::vector<BoardView>& views, std::size_t i,
                            double arrow_scale) {
  cv::Mat out = to_bgr(image);
  const BoardView& v = views[i];
  const bool used = i < result.used.size() && result.used[i];
  char text[160];
  if (used) {
    const std::vector<cv::Point2f> proj = reprojected_corners(result, views, i);
    const double rms = result.view_rms_px[i];
    for (std::size_t k = 0; k < v.image_points.size(); ++k) {
      const cv::Point2f d = proj[k] - v.image_points[k];
      const bool large = std::hypot(d.x, d.y) > 3 * rms;
      cv::circle(out, v.image_points[k], 3, cv::Scalar(0, 200, 0), 1, cv::LINE_AA);
      cv::arrowedLine(
          out, v.image_points[k], v.image_points[k] + static_cast<float>(arrow_scale) * d,
          large ? cv::Scalar(0, 0, 255) : cv::Scalar(255, 160, 0), 1, cv::LINE_AA, 0, 0.2);
    }
    std::snprintf(text, sizeof text, "%s: %zu corners, RMS %.3f px", v.name.c_str(),
                  v.image_points.size(), rms);
    caption(out, text, 0);
    std::snprintf(text, sizeof text, "arrows: detected -> reprojected, x%g (red: > 3 x RMS)",
                  arrow_scale);
    caption(out, text, 1);
  } else {
    for (const cv::Point2f& p : v.image_points)
      cv::circle(out, p, 3, cv::Scalar(0, 0, 255), 1, cv::LINE_AA);
    std::string why = "not used";
    for (const std::string& r : result.rejected)
      if (r.rfind(v.name + ":", 0) == 0) why = r;
    caption(out, why, 0);
  }
  return out;
}

double coverage_fraction(const IntrinsicsResult& result, const std::vector<BoardView>& views) {
  int covered = 0;
  for (const auto& row : cell_counts(result, views))
    for (int c : row) covered += c > 0;
  return static_cast<double>(covered) / (kCellsX * kCellsY);
}

cv::Mat draw_coverage(const IntrinsicsResult& result, const std::vector<BoardView>& views) {
  const cv::Size size = result.image_size;
  cv::Mat out(size, CV_8UC3, cv::Scalar(40, 40, 40));
  const auto counts = cell_counts(result, views);
  int most = 1;
  for (const auto& row : counts)
    for (int c : row) most = std::max(most, c);
  for (int y = 0; y < kCellsY; ++y)
    for (int x = 0; x < kCellsX; ++x) {
      const cv::Rect cell(x * size.width / kCellsX, y * size.height / kCellsY,
                          (x + 1) * size.width / kCellsX - x * size.width / kCellsX,
                          (y + 1) * size.height / kCellsY - y * size.height / kCellsY);
      const int c = counts[static_cast<std::size_t>(y)][static_cast<std::size_t>(x)];
      const int shade = 40 + 120 * c / most;
      cv::rectangle(out, cell, c == 0 ? cv::Scalar(30, 30, 140) : cv::Scalar::all(shade),
                    cv::FILLED);
      cv::rectangle(out, cell, cv::Scalar(90, 90, 90), 1);
    }
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (i >= result.used.size() || !result.used[i]) continue;
    cv::Mat hue(1, 1, CV_8UC3, cv::Scalar(static_cast<int>(i * 37 % 180), 200, 255));
    cv::cvtColor(hue, hue, cv::COLOR_HSV2BGR);
    const cv::Vec3b c = hue.at<cv::Vec3b>(0, 0);
    for (const cv::Point2f& p : views[i].image_points)
      cv::circle(out, p, 2, cv::Scalar(c[0], c[1], c[2]), cv::FILLED, cv::LINE_AA);
  }
  char text[160];
  std::snprintf(text, sizeof text, "coverage: %.0f %% of %d x %d cells hold corners (%d views)",
                100 * coverage_fraction(result, views), kCellsX, kCellsY, result.views_used());
  caption(out, text, 0);
  caption(out, "empty cells red: the distortion is not constrained there", 1);
  return out;
}

}  // namespace flatland::calibration
