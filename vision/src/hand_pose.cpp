// Hand pose from the moments of a sub-pixel coverage map measured in metric table coordinates.
//
// Why moments rather than a fitted contour: the centroid and the principal axis of a region are
// integrals, so pixel noise and quantisation average out over the whole face, and a uniform
// erosion or dilation of the outline (a threshold a little off) leaves the centroid of a
// centrally symmetric shape exactly where it is. Why in table coordinates: the perspective image
// of a plane is not an affine image, so the image-plane centroid of the face is not the image of
// its centroid. Every pixel is mapped to the plane of the top face and weighted by its footprint
// there, which removes that bias for any camera pose and lens distortion.
#include "flatland/vision/hand_pose.hpp"

#include "flatland/vision/mapping.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace flatland::vision {
namespace {

[[noreturn]] void fail(const std::string& what) {
  throw std::invalid_argument("measure_hand_pose: " + what);
}

cv::Mat to_gray_float(const cv::Mat& image) {
  if (image.empty()) fail("empty image");
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 1)
    gray = image;
  else
    fail("expected a 1- or 3-channel image, got " + std::to_string(image.channels()) + " channels");
  if (gray.depth() != CV_8U && gray.depth() != CV_32F) fail("expected an 8-bit or float image");
  cv::Mat f;
  gray.convertTo(f, CV_32F);
  return f;
}

double median_of(std::vector<float> v) {
  if (v.empty()) return 0;
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

std::vector<float> values_in(const cv::Mat& gray, const cv::Mat& mask) {
  std::vector<float> out;
  for (int y = 0; y < gray.rows; ++y) {
    const float* g = gray.ptr<float>(y);
    const std::uint8_t* m = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < gray.cols; ++x)
      if (m[x]) out.push_back(g[x]);
  }
  return out;
}

}  // namespace

double resolve_half_turn(double axis_angle, double expected) {
  const double pi = std::numbers::pi;
  return axis_angle + pi * std::round((expected - axis_angle) / pi);
}

HandPose measure_hand_pose(const cv::Mat& image, const camera::CameraModel& camera,
                           double plate_height, const HandPoseOptions& options) {
  const cv::Mat gray = to_gray_float(image);
  if (gray.cols != camera.width || gray.rows != camera.height) {
    std::ostringstream s;
    s << "image is " << gray.cols << "x" << gray.rows << " but the camera is " << camera.width
      << "x" << camera.height;
    fail(s.str());
  }
  if (!std::isfinite(plate_height) || plate_height < 0)
    fail("plate height must be finite and >= 0");

  // 1. Segment: Otsu separates the bright aluminium (and a disk face) from the table and from the
  //    hand's side walls, which are never lit brighter than ~0.36 against the face's ~0.6.
  cv::Mat gray8;
  gray.convertTo(gray8, CV_8U);
  cv::Mat bright;
  const double otsu = cv::threshold(gray8, bright, 0, 255, cv::THRESH_BINARY | cv::THRESH_OTSU);
  {
    // A flat image (no hand, lens cap on) has no two grey levels to separate.
    const double dark = cv::mean(gray, ~bright)[0], light = cv::mean(gray, bright)[0];
    if (cv::countNonZero(bright) == 0 || cv::countNonZero(~bright) == 0 || light - dark < 10)
      fail("no hand found (the image has no bright region against the table)");
  }
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(bright, labels, stats, centroids, 8, CV_32S);
  int best = -1, best_area = 0;
  for (int i = 1; i < n; ++i)
    if (stats.at<int>(i, cv::CC_STAT_AREA) > best_area) {
      best_area = stats.at<int>(i, cv::CC_STAT_AREA);
      best = i;
    }
  if (best < 0 || best_area < options.min_area_px)
    fail("no hand found (largest bright blob " + std::to_string(best_area) + " px < " +
         std::to_string(options.min_area_px) + " px)");
  const cv::Rect box(stats.at<int>(best, cv::CC_STAT_LEFT), stats.at<int>(best, cv::CC_STAT_TOP),
                     stats.at<int>(best, cv::CC_STAT_WIDTH),
                     stats.at<int>(best, cv::CC_STAT_HEIGHT));
  constexpr int kMargin = 3;  // px: the coverage band reaches 2 px beyond the blob
  if (box.x < kMargin || box.y < kMargin || box.x + box.width > gray.cols - kMargin ||
      box.y + box.height > gray.rows - kMargin)
    fail("the hand touches the image border (its centroid would be biased)");

  // 2. The solid face: the blob with its holes (the darker pivot cap) filled, since the face
  //    under the cap is aluminium too.
  cv::Mat blob = labels == best;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(blob, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  cv::Mat solid = cv::Mat::zeros(gray.size(), CV_8U);
  cv::drawContours(solid, contours, -1, cv::Scalar(255), cv::FILLED);
  const cv::Mat k3 = cv::getStructuringElement(cv::MORPH_RECT, {3, 3});
  cv::Mat interior, band_outer, far_outer;
  cv::erode(solid, interior, k3, {-1, -1}, 2);
  cv::dilate(solid, band_outer, k3, {-1, -1}, 2);
  cv::dilate(solid, far_outer, k3, {-1, -1}, 8);

  // 3. Levels: the face from the interior (bright pixels only, so the pivot cap does not count),
  //    the table from a ring around the hand (local, so vignetting does not matter).
  double hand_level = 0, table_level = 0;
  if (options.hand_level) {
    hand_level = *options.hand_level;
  } else {
    cv::Mat face = interior & (gray > otsu);
    hand_level = median_of(values_in(gray, face));
  }
  cv::Mat table_ring;
  cv::dilate(solid, table_ring, k3, {-1, -1}, 20);
  table_ring &= ~far_outer;
  const std::vector<float> table_values = values_in(gray, table_ring);
  table_level = options.table_level ? *options.table_level : median_of(table_values);
  if (!(hand_level - table_level > 10))
    fail("no hand found (face " + std::to_string(hand_level) +
         " DN is not brighter than the table " + std::to_string(table_level) + " DN)");
  // Noise from the table ring (robust: median absolute deviation), for the reported sigmas.
  double noise_dn = 0;
  {
    std::vector<float> v = table_values;
    for (float& x : v) x = static_cast<float>(std::abs(x - table_level));
    noise_dn = 1.4826 * median_of(std::move(v));
    noise_dn = std::max(noise_dn, 1.0 / std::sqrt(12.0));  // at least the quantisation noise
  }

  // 4. Coverage: 1 inside, the intensity rescaled between the levels in a 2-pixel band on either
  //    side of the outline (clipped to [0, 1]: the highlight on the face and the dimmer side walls
  //    do not count), 0 elsewhere.
  const cv::Rect roi(box.x - kMargin, box.y - kMargin, box.width + 2 * kMargin,
                     box.height + 2 * kMargin);
  // The coverage counts from `floor` of the face-table contrast up, not from the table: where the
  // camera sees a side wall of the plate (walls facing the camera's foot point), the face's edge
  // borders the wall, lit at up to ~0.32 of the contrast, and counting it as part face moves that
  // side's edge outwards (0.19 mm centroid bias with an oblique camera, measured; 0.065 mm with the
  // floor). The floor erodes every edge by about the same amount elsewhere, which leaves the
  // centroid of the centrally symmetric face where it is.
  const double floor = std::clamp(options.coverage_floor, 0.0, 0.9);
  const double scale = 1.0 / ((1.0 - floor) * (hand_level - table_level));
  // The face is not evenly bright: the aluminium's highlight brightens it towards the light by
  // ~10 %, and a global level would count the bright side's edge pixels as fully covered too early
  // (a centroid bias of up to 0.26 mm towards the light, measured). A quadratic in the pixel
  // coordinates, fitted to the face's interior, gives the face level at each edge pixel.
  cv::Vec6d level_fit(hand_level, 0, 0, 0, 0, 0);
  const cv::Point2d fit_origin(box.x + 0.5 * box.width, box.y + 0.5 * box.height);
  const double fit_scale = 2.0 / std::max(box.width, box.height);
  auto basis = [&](int ix, int iy) {
    const double u = (ix - fit_origin.x) * fit_scale, v = (iy - fit_origin.y) * fit_scale;
    return cv::Vec6d(1, u, v, u * u, u * v, v * v);
  };
  if (!options.hand_level) {
    cv::Mat face = interior & (gray > otsu);
    cv::Matx66d AtA = cv::Matx66d::zeros();
    cv::Vec6d Atb(0, 0, 0, 0, 0, 0);
    int used = 0;
    for (int y = box.y; y < box.y + box.height; ++y)
      for (int x = box.x; x < box.x + box.width; ++x)
        if (face.at<std::uint8_t>(y, x)) {
          const cv::Vec6d b = basis(x, y);
          AtA += b * b.t();
          Atb += b * static_cast<double>(gray.at<float>(y, x));
          ++used;
        }
    cv::Vec6d sol;
    if (used > 50 && cv::solve(AtA, Atb, sol, cv::DECOMP_CHOLESKY)) level_fit = sol;
  }
  auto face_level = [&](int ix, int iy) { return level_fit.dot(basis(ix, iy)); };

  // 5. Footprints on the plane z = plate_height: map the pixel corners of the ROI through the
  //    lens and the table pose (pixels_to_table), then each pixel is the quadrilateral of its four
  //    corners (area and centroid by the shoelace formula).
  const int cw = roi.width + 1, ch = roi.height + 1;
  std::vector<cv::Point2d> corners_px;
  corners_px.reserve(static_cast<std::size_t>(cw) * ch);
  for (int y = 0; y < ch; ++y)
    for (int x = 0; x < cw; ++x) corners_px.emplace_back(roi.x + x - 0.5, roi.y + y - 0.5);
  const std::vector<cv::Point2d> plane = pixels_to_table(camera, corners_px, plate_height);
  for (const cv::Point2d& p : plane)
    if (!std::isfinite(p.x))
      fail("a pixel's ray does not meet the table plane (is the table pose right?)");

  // Accumulate moments about a reference point near the centroid (better conditioned sums).
  const cv::Point2d ref = plane[static_cast<std::size_t>(ch / 2) * cw + cw / 2];
  struct Px {
    double c, a, x, y;
    bool partial;
  };
  std::vector<Px> px;
  double m0 = 0, mx = 0, my = 0, mxx = 0, mxy = 0, myy = 0;
  for (int y = 0; y < roi.height; ++y)
    for (int x = 0; x < roi.width; ++x) {
      const int ix = roi.x + x, iy = roi.y + y;
      if (!band_outer.at<std::uint8_t>(iy, ix)) continue;
      const bool inside = interior.at<std::uint8_t>(iy, ix) != 0;
      double c = 1.0;
      if (!inside) {
        const double A = face_level(ix, iy), T = table_level + floor * (A - table_level);
        c = std::clamp((gray.at<float>(iy, ix) - T) / std::max(A - T, 1.0), 0.0, 1.0);
      }
      if (c <= 0) continue;
      const cv::Point2d& p0 = plane[static_cast<std::size_t>(y) * cw + x];
      const cv::Point2d& p1 = plane[static_cast<std::size_t>(y) * cw + x + 1];
      const cv::Point2d& p2 = plane[static_cast<std::size_t>(y + 1) * cw + x + 1];
      const cv::Point2d& p3 = plane[static_cast<std::size_t>(y + 1) * cw + x];
      // Shoelace area and centroid of the quadrilateral p0 p1 p2 p3 (relative to ref).
      const cv::Point2d q[4] = {p0 - ref, p1 - ref, p2 - ref, p3 - ref};
      double a2 = 0, cx = 0, cy = 0;
      for (int k = 0; k < 4; ++k) {
        const cv::Point2d& u = q[k];
        const cv::Point2d& v = q[(k + 1) % 4];
        const double cr = u.x * v.y - v.x * u.y;
        a2 += cr;
        cx += (u.x + v.x) * cr;
        cy += (u.y + v.y) * cr;
      }
      if (std::abs(a2) < 1e-18) continue;  // a degenerate footprint (never for a real camera)
      const double area = std::abs(0.5 * a2);
      cx /= 3.0 * a2;
      cy /= 3.0 * a2;
      const double w = c * area;
      m0 += w;
      mx += w * cx;
      my += w * cy;
      mxx += w * cx * cx;
      mxy += w * cx * cy;
      myy += w * cy * cy;
      px.push_back({c, area, cx, cy, !inside && c < 1.0});
    }
  if (!(m0 > 0)) fail("no hand found (empty coverage)");

  HandPose pose;
  const double gx = mx / m0, gy = my / m0;
  pose.center_table = {ref.x + gx, ref.y + gy};
  const double sxx = mxx / m0 - gx * gx, sxy = mxy / m0 - gx * gy, syy = myy / m0 - gy * gy;
  double angle = 0.5 * std::atan2(2 * sxy, sxx - syy);  // (-pi/2, pi/2]
  if (angle <= -std::numbers::pi / 2) angle += std::numbers::pi;
  pose.angle = angle;
  const double tr = sxx + syy, det = sxx * syy - sxy * sxy;
  const double disc = std::sqrt(std::max(0.0, 0.25 * tr * tr - det));
  const double l1 = 0.5 * tr + disc, l2 = 0.5 * tr - disc;
  pose.elongation = l2 > 0 ? std::sqrt(l1 / l2) : 0;
  pose.area = m0;
  pose.hand_level = hand_level;
  pose.table_level = table_level;
  pose.pixels = static_cast<int>(px.size());

  // Noise propagation: only the partial (band) pixels carry image noise, each coverage with
  // sigma = noise / (hand - table). First-order derivatives of the centroid and the angle.
  const double sc = noise_dn * scale;
  double vcx = 0, vcy = 0, vang = 0;
  const double denom = (sxx - syy) * (sxx - syy) + 4 * sxy * sxy;
  for (const Px& p : px) {
    if (!p.partial) continue;
    const double dx = p.x - gx, dy = p.y - gy;
    const double dw = sc * p.a;  // sigma of this pixel's weight
    vcx += (dw * dx / m0) * (dw * dx / m0);
    vcy += (dw * dy / m0) * (dw * dy / m0);
    // d(angle)/dw from angle = atan2(2 sxy, sxx - syy) / 2 with second moments about the centroid.
    const double dsxx = (dx * dx - sxx) / m0, dsyy = (dy * dy - syy) / m0,
                 dsxy = (dx * dy - sxy) / m0;
    const double num = (sxx - syy) * 2 * dsxy - 2 * sxy * (dsxx - dsyy);
    const double dang = denom > 0 ? 0.5 * num / denom : 0;
    vang += (dw * dang) * (dw * dang);
  }
  pose.sigma_center = std::sqrt(0.5 * (vcx + vcy));
  pose.sigma_angle = std::sqrt(vang);
  return pose;
}

}  // namespace flatland::vision
