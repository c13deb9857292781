// Disk tracker (tracker.hpp). Conventions: pixel centres at integer coordinates (OpenCV), all
// intensities in DN of a single-channel float image.
#include "flatland/vision/tracker.hpp"

#include "flatland/vision/mapping.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <vector>

namespace flatland::vision {

std::string to_string(TrackState s) {
  switch (s) {
    case TrackState::kFound:
      return "found";
    case TrackState::kTracking:
      return "tracking";
    case TrackState::kLost:
      return "lost";
  }
  return "lost";
}

std::string to_string(TrackMethod m) {
  switch (m) {
    case TrackMethod::kEdge:
      return "edge";
    case TrackMethod::kMoments:
      return "moments";
    case TrackMethod::kHough:
      return "hough";
    case TrackMethod::kContour:
      return "contour";
  }
  return "edge";
}

TrackMethod parse_track_method(const std::string& name) {
  if (name == "edge") return TrackMethod::kEdge;
  if (name == "moments") return TrackMethod::kMoments;
  if (name == "hough") return TrackMethod::kHough;
  if (name == "contour") return TrackMethod::kContour;
  throw std::invalid_argument("tracker method: expected edge, moments, hough or contour, got '" +
                              name + "'");
}

namespace {

// Grey in the frame's own depth: cvtColor on 8-bit pixels is a fixed-point SIMD pass, several
// times cheaper than converting three channels to float first and then making them grey.
cv::Mat gray_in_own_depth(const cv::Mat& frame) {
  if (frame.empty()) throw std::invalid_argument("tracker: empty frame");
  cv::Mat g;
  switch (frame.channels()) {
    case 1:
      return frame;
    case 3:
      cv::cvtColor(frame, g, cv::COLOR_BGR2GRAY);
      return g;
    case 4:
      cv::cvtColor(frame, g, cv::COLOR_BGRA2GRAY);
      return g;
    default:
      throw std::invalid_argument("tracker: frames must have 1, 3 or 4 channels");
  }
}

}  // namespace

cv::Mat to_gray_f32(const cv::Mat& frame) {
  const cv::Mat g = gray_in_own_depth(frame);
  if (g.depth() == CV_32F) return g;
  cv::Mat f;
  g.convertTo(f, CV_32F);
  return f;
}

cv::Mat to_gray_for_edge(const cv::Mat& frame) {
  const cv::Mat g = gray_in_own_depth(frame);
  if (g.depth() == CV_8U || g.depth() == CV_32F) return g;
  cv::Mat f;
  g.convertTo(f, CV_32F);
  return f;
}

cv::Mat to_gray_u8(const cv::Mat& frame) {
  const cv::Mat g = gray_in_own_depth(frame);
  if (g.depth() == CV_8U) return g;
  cv::Mat u8;
  g.convertTo(u8, CV_8U);
  return u8;
}

namespace {

constexpr double kPi = std::numbers::pi;

inline bool inside_image(const cv::Mat& g, double x, double y) {
  return x >= 0 && y >= 0 && x <= g.cols - 1.0 && y <= g.rows - 1.0;
}

// Bilinear sample of a point in the image (inside_image). A ray checks its two ends only: a segment
// between two points of the image lies in it, and c + rho d rounds monotonically in rho. Pixel:
// float, or unsigned char for an 8-bit frame's grey window (sampled as it is, which gives the
// same floats as its float copy would, from a quarter of the memory).
template <typename Pixel>
inline float sample_inside(const cv::Mat& g, double x, double y) {
  const int x0 = std::min(static_cast<int>(x), g.cols - 2 < 0 ? 0 : g.cols - 2);
  const int y0 = std::min(static_cast<int>(y), g.rows - 2 < 0 ? 0 : g.rows - 2);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const Pixel* r0 = g.ptr<Pixel>(y0);
  const Pixel* r1 = g.ptr<Pixel>(std::min(y0 + 1, g.rows - 1));
  const int x1 = std::min(x0 + 1, g.cols - 1);
  const float a = r0[x0], b = r0[x1], c = r1[x0], d = r1[x1];
  const float top = a + fx * (b - a);
  const float bottom = c + fx * (d - c);
  return top + fy * (bottom - top);
}

// Bilinear sample; NaN outside the image so that rays leaving the frame are simply dropped.
template <typename Pixel>
inline float sample(const cv::Mat& g, double x, double y) {
  if (!inside_image(g, x, y)) return std::numeric_limits<float>::quiet_NaN();
  return sample_inside<Pixel>(g, x, y);
}

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// Face and O-ring levels around a centre guess: the face is sampled on a circle at 0.8 of the edge
// radius (outside the marker, which spans 0.41..0.67 of it), the ring as each ray's minimum just
// beyond the edge. Medians over the rays ignore the marker, the hand and a few bad rays.
struct Levels {
  double face = 0, dark = 0;
  bool ok = false;
};

template <typename Pixel>
Levels disk_levels_of(const cv::Mat& g, cv::Point2d c, double re, int rays) {
  std::vector<double> face, dark;
  face.reserve(rays);
  dark.reserve(rays);
  for (int k = 0; k < rays; ++k) {
    const double a = 2 * kPi * k / rays, dx = std::cos(a), dy = std::sin(a);
    const float f = sample<Pixel>(g, c.x + 0.8 * re * dx, c.y + 0.8 * re * dy);
    if (std::isfinite(f)) face.push_back(f);
    double lo = std::numeric_limits<double>::infinity();
    double rho_last = 0.95 * re;  // the loop's last rho, summed as the loop sums it
    for (double rho = 0.95 * re; rho <= 1.2 * re + 2; rho += 0.5) rho_last = rho;
    if (inside_image(g, c.x + 0.95 * re * dx, c.y + 0.95 * re * dy) &&
        inside_image(g, c.x + rho_last * dx, c.y + rho_last * dy)) {
      for (double rho = 0.95 * re; rho <= 1.2 * re + 2; rho += 0.5) {
        const float v = sample_inside<Pixel>(g, c.x + rho * dx, c.y + rho * dy);
        if (std::isfinite(v)) lo = std::min(lo, static_cast<double>(v));
      }
    } else {
      for (double rho = 0.95 * re; rho <= 1.2 * re + 2; rho += 0.5) {
        const float v = sample<Pixel>(g, c.x + rho * dx, c.y + rho * dy);
        if (std::isfinite(v)) lo = std::min(lo, static_cast<double>(v));
      }
    }
    if (std::isfinite(lo)) dark.push_back(lo);
  }
  Levels l;
  if (face.size() < static_cast<std::size_t>(rays / 2) ||
      dark.size() < static_cast<std::size_t>(rays / 2))
    return l;
  l.face = median(face);
  l.dark = median(dark);
  l.ok = true;
  return l;
}

// The window's grey is 8-bit (an 8-bit frame's) or float.
Levels disk_levels(const cv::Mat& g, cv::Point2d c, double re, int rays) {
  return g.depth() == CV_8U ? disk_levels_of<unsigned char>(g, c, re, rays)
                            : disk_levels_of<float>(g, c, re, rays);
}

struct CircleFit {
  cv::Point2d c;
  double r = 0, sigma_r = 0;
  /// Each centre coordinate's sigma: the larger of the residuals' scatter propagated through the
  /// fit (sigma_noise) and the misfit the residuals' odd harmonics show (sigma_misfit).
  double sigma_c = 0, sigma_noise = 0, sigma_misfit = 0;
  int inliers = 0;
  bool ok = false;
};

// What the circle model misses, as an error of its centre. An error pattern e(theta) along the
// rim moves the fitted centre by its first harmonic (a1 cos + b1 sin), which the fit absorbs and
// the residuals therefore never show. Patterns that are symmetric about the centre (an ellipse
// from an oblique view, the stadium of a smear) hold even harmonics only and move nothing. A
// one-sided pattern (a lamp's highlight on the band, a shadow, the hand) holds the odd harmonics
// alike, so those the residuals do show, 3, 5 and 7, measure the first one's size: the mean of
// their six squared coefficients estimates each centre coordinate's squared error. Under white
// noise alone each coefficient has the variance of a centre coordinate too (2 s^2 / n for n
// points of scatter s), so the estimate is also right, if noisier (6 degrees of freedom), there.
double odd_harmonic_misfit(const std::vector<cv::Point2d>& p, cv::Point2d c, double r,
                           double scale) {
  constexpr std::array<int, 3> kOrders{3, 5, 7};
  std::array<double, 6> proj{};
  double sw = 0;
  for (const cv::Point2d& q : p) {
    const double dx = q.x - c.x, dy = q.y - c.y, d = std::hypot(dx, dy);
    if (d <= 0) continue;
    const double e = d - r, u = e / std::min(scale, 1e6);
    const double w = std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
    if (w <= 0) continue;
    const double th = std::atan2(dy, dx);
    for (std::size_t k = 0; k < kOrders.size(); ++k) {
      proj[2 * k] += w * e * std::cos(kOrders[k] * th);
      proj[2 * k + 1] += w * e * std::sin(kOrders[k] * th);
    }
    sw += w;
  }
  if (sw <= 0) return 0;
  double ss = 0;
  for (const double v : proj) ss += (2 * v / sw) * (2 * v / sw);
  return std::sqrt(ss / static_cast<double>(proj.size()));
}

// Geometric circle fit by iteratively reweighted Gauss-Newton (Tukey biweight). The robust scale
// has a floor (0.5 px in the image): exposure blur turns the edge into a stadium whose systematic
// residuals (about +-blur/4) must keep nearly symmetric weights, or noise would tilt the centre;
// genuine outliers (an occluded or wrongly chosen crossing) are several px off and still rejected.
CircleFit fit_circle(const std::vector<cv::Point2d>& p, cv::Point2d c0, double r0,
                     double scale_floor = 0.5) {
  CircleFit out;
  const int n = static_cast<int>(p.size());
  if (n < 5) return out;
  double cx = c0.x, cy = c0.y, r = r0;
  std::vector<double> e(n), w(n, 1.0);
  double scale = 1e9;
  for (int it = 0; it < 12; ++it) {
    for (int i = 0; i < n; ++i) e[i] = std::hypot(p[i].x - cx, p[i].y - cy) - r;
    if (it >= 1) {
      std::vector<double> a(n);
      for (int i = 0; i < n; ++i) a[i] = std::abs(e[i]);
      scale = std::max(scale_floor, 1.4826 * median(a)) * 4.685;
      for (int i = 0; i < n; ++i) {
        const double u = e[i] / scale;
        w[i] = std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
      }
    }
    cv::Matx33d A = cv::Matx33d::zeros();
    cv::Vec3d b(0, 0, 0);
    for (int i = 0; i < n; ++i) {
      const double dx = p[i].x - cx, dy = p[i].y - cy, d = std::hypot(dx, dy);
      if (d <= 0) continue;
      const cv::Vec3d J(-dx / d, -dy / d, -1.0);
      A += w[i] * J * J.t();
      b += w[i] * e[i] * J;
    }
    cv::Vec3d step;
    if (!cv::solve(A, -b, step, cv::DECOMP_CHOLESKY)) return out;
    cx += step[0];
    cy += step[1];
    r += step[2];
    if (std::abs(step[0]) + std::abs(step[1]) + std::abs(step[2]) < 1e-7 && it >= 3) break;
  }
  // Final weights, residual scale and the centre's covariance sigma^2 (J^T W J)^-1.
  cv::Matx33d A = cv::Matx33d::zeros();
  double sw = 0, swe2 = 0;
  int inl = 0;
  for (int i = 0; i < n; ++i) {
    const double dx = p[i].x - cx, dy = p[i].y - cy, d = std::hypot(dx, dy);
    if (d <= 0) continue;
    const double ei = d - r;
    const double u = ei / std::min(scale, 1e6);
    const double wi = std::abs(u) < 1 ? (1 - u * u) * (1 - u * u) : 0.0;
    if (wi <= 0) continue;
    const cv::Vec3d J(-dx / d, -dy / d, -1.0);
    A += wi * J * J.t();
    sw += wi;
    swe2 += wi * ei * ei;
    ++inl;
  }
  if (inl < 5) return out;
  out.c = {cx, cy};
  out.r = r;
  out.inliers = inl;
  out.sigma_r = std::sqrt(swe2 / std::max(1.0, sw - 3.0));
  const cv::Matx33d cov = A.inv(cv::DECOMP_CHOLESKY) * (out.sigma_r * out.sigma_r);
  out.sigma_noise = std::sqrt(std::max(0.0, 0.5 * (cov(0, 0) + cov(1, 1))));
  out.sigma_misfit = odd_harmonic_misfit(p, {cx, cy}, r, scale);
  out.sigma_c = std::max(out.sigma_noise, out.sigma_misfit);
  out.ok = std::isfinite(cx) && std::isfinite(cy) && std::isfinite(r) && r > 0;
  return out;
}

// Sub-pixel edge points: along each ray from the centre guess, the downward crossing of the
// face/ring mid-level nearest to the expected radius (the marker's edges are crossings too, but
// lie at most 0.67 of the radius out).
template <typename Pixel>
std::vector<cv::Point2d> edge_points_of(const cv::Mat& g, cv::Point2d c, double re,
                                        const Levels& lv, const TrackerConfig& cfg,
                                        int* rays_in_image) {
  const double level = 0.5 * (lv.face + lv.dark), inv = 1.0 / (lv.face - lv.dark);
  std::vector<cv::Point2d> pts;
  pts.reserve(cfg.rays);
  const double w = std::max(4.0, 0.3 * re);
  const double step = cfg.ray_step_px;
  const int m = static_cast<int>(std::ceil(2 * w / step)) + 1;
  std::vector<float> prof(m);
  int in_image = 0;
  for (int k = 0; k < cfg.rays; ++k) {
    const double a = 2 * kPi * (k + 0.5) / cfg.rays, dx = std::cos(a), dy = std::sin(a);
    const double rho0 = std::max(1.0, re - w);
    const double rho_end = rho0 + (m - 1) * step;
    if (!inside_image(g, c.x + rho0 * dx, c.y + rho0 * dy) ||
        !inside_image(g, c.x + rho_end * dx, c.y + rho_end * dy))
      continue;
    bool finite = true;  // a float frame may hold NaN: such a ray is dropped as one leaving it
    for (int j = 0; j < m; ++j) {
      const double rho = rho0 + j * step;
      prof[j] = sample_inside<Pixel>(g, c.x + rho * dx, c.y + rho * dy);
      finite &= std::isfinite(prof[j]);
    }
    if (!finite) continue;
    ++in_image;
    double best = -1, best_dist = 1e9;
    for (int j = 0; j + 1 < m; ++j) {
      if (prof[j] >= level && prof[j + 1] < level) {
        const double rho = rho0 + step * (j + (prof[j] - level) / (prof[j] - prof[j + 1]));
        if (std::abs(rho - re) < best_dist) {
          best_dist = std::abs(rho - re);
          best = rho;
        }
      }
    }
    // Area refinement: the position of the ideal step with the same integral of the normalised
    // profile over a window about the crossing. Unlike the linear crossing, which is off by up
    // to ~0.08 px depending on where a sharp edge falls within its pixel, the integral of a
    // box-filtered (anti-aliased) step is exact; the window stays within the 3 px O-ring band.
    const double h = cfg.edge_area_window_px;
    if (best > 0 && h > 0) {
      const int ja = static_cast<int>(std::lround((best - h - rho0) / step));
      const int jb = ja + static_cast<int>(std::lround(2 * h / step));
      if (ja >= 0 && jb < m) {
        double area = 0;
        for (int j = ja; j < jb; ++j) {
          const double a = std::clamp((prof[j] - lv.dark) * inv, 0.0, 1.0);
          const double b = std::clamp((prof[j + 1] - lv.dark) * inv, 0.0, 1.0);
          area += 0.5 * (a + b) * step;
        }
        best = rho0 + ja * step + area;
      }
    }
    if (best > 0) pts.emplace_back(c.x + best * dx, c.y + best * dy);
  }
  if (rays_in_image) *rays_in_image = in_image;
  return pts;
}

std::vector<cv::Point2d> edge_points(const cv::Mat& g, cv::Point2d c, double re, const Levels& lv,
                                     const TrackerConfig& cfg, int* rays_in_image) {
  return g.depth() == CV_8U ? edge_points_of<unsigned char>(g, c, re, lv, cfg, rays_in_image)
                            : edge_points_of<float>(g, c, re, lv, cfg, rays_in_image);
}

}  // namespace

TrackResult refine_edge(const cv::Mat& g, cv::Point2d guess, double re, const TrackerConfig& cfg,
                        cv::Point2d offset) {
  TrackResult res;
  cv::Point2d c = guess;
  double r = re;
  // A second pass, when the first fit's centre is far from the guess, casts its rays from that
  // centre, so that every ray meets the edge nearly at right angles and the crossings are
  // symmetric about the centre. From a guess within about a pixel one pass is as accurate
  // (docs/VISION.md) at half the cost.
  for (int pass = 0; pass < 2; ++pass) {
    const Levels lv = disk_levels(g, c, r, 48);
    if (!lv.ok || lv.face - lv.dark < cfg.min_contrast_dn) return res;
    int in_image = 0;
    const std::vector<cv::Point2d> pts = edge_points(g, c, r, lv, cfg, &in_image);
    if (static_cast<double>(pts.size()) < cfg.min_inlier_fraction * cfg.rays) return res;
    CircleFit f = fit_circle(pts, c, r);
    if (!f.ok || static_cast<double>(f.inliers) < cfg.min_inlier_fraction * cfg.rays) return res;
    c = f.c;
    r = f.r;
    if (cfg.camera) {
      // The same points on the table plane; the pixel fit gives the start and the metres per
      // pixel that scale the robust floor and the uncertainty.
      std::vector<cv::Point2d> full(pts);
      for (cv::Point2d& q : full) q += offset;
      std::vector<cv::Point2d> table = pixels_to_table(*cfg.camera, full, cfg.plane_z);
      std::erase_if(table, [](const cv::Point2d& q) { return !std::isfinite(q.x); });
      const std::vector<cv::Point2d> centre =
          pixels_to_table(*cfg.camera, {f.c + offset}, cfg.plane_z);
      if (table.size() < 5 || !std::isfinite(centre[0].x)) return res;
      double r_m = 0;
      for (const cv::Point2d& q : table) r_m += cv::norm(q - centre[0]);
      r_m /= static_cast<double>(table.size());
      const double m_per_px = r_m / f.r;
      const CircleFit fm = fit_circle(table, centre[0], r_m, 0.5 * m_per_px);
      if (!fm.ok || static_cast<double>(fm.inliers) < cfg.min_inlier_fraction * cfg.rays)
        return res;
      c = cfg.camera->project(cv::Point3d(fm.c.x, fm.c.y, cfg.plane_z)) - offset;
      if (!std::isfinite(c.x)) return res;
      f.inliers = fm.inliers;
      f.sigma_r = fm.sigma_r / m_per_px;
      f.sigma_c = fm.sigma_c / m_per_px;
    }
    const bool last_pass = pass == 1 || cv::norm(c - guess) <= cfg.second_pass_shift_px;
    if (last_pass) {
      res.state = TrackState::kTracking;
      res.center = c;
      res.radius_px = r;
      res.sigma_px = f.sigma_c;
      res.edge_points = f.inliers;
      // Quality: the share of rays that gave an inlier edge point, discounted by the residual
      // scale relative to a sharp edge (blur or a wrong shape raise it).
      const double share = static_cast<double>(f.inliers) / cfg.rays;
      res.quality = std::clamp(share * std::exp(-f.sigma_r / 2.0), 0.0, 1.0);
      break;
    }
  }
  return res;
}

namespace {

// Calls f(x, y, dx, dy, d2, value) for each pixel of the float image g within `radius` of c
// (dx, dy the pixel's offset from c, d2 its square distance).
template <typename F>
void for_each_pixel_within(const cv::Mat& g, cv::Point2d c, double radius, F&& f) {
  const int x0 = std::max(0, static_cast<int>(std::floor(c.x - radius)));
  const int x1 = std::min(g.cols - 1, static_cast<int>(std::ceil(c.x + radius)));
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y - radius)));
  const int y1 = std::min(g.rows - 1, static_cast<int>(std::ceil(c.y + radius)));
  for (int y = y0; y <= y1; ++y) {
    const float* row = g.ptr<float>(y);
    const double dy = y - c.y;
    for (int x = x0; x <= x1; ++x) {
      const double dx = x - c.x, d2 = dx * dx + dy * dy;
      if (d2 > radius * radius) continue;
      f(x, y, dx, dy, d2, row[x]);
    }
  }
}

// The read noise of a grey window (DN), from the disk's face between 0.72 and 0.86 of the edge
// radius (outside the marker, inside the edge): the median absolute difference of horizontal
// neighbours, which a lamp's smooth shading hardly moves, as a normal sigma (1.4826 MAD / sqrt 2).
// Rounding to 8 bits alone leaves 1/sqrt(12) DN, the floor.
double face_noise_dn(const cv::Mat& g, cv::Point2d c, double re) {
  std::vector<double> d;
  const double lo = 0.72 * re, hi = 0.86 * re;
  const int y0 = std::max(0, static_cast<int>(std::floor(c.y - hi)));
  const int y1 = std::min(g.rows - 1, static_cast<int>(std::ceil(c.y + hi)));
  for (int y = y0; y <= y1; ++y) {
    const float* row = g.ptr<float>(y);
    const double dy = y - c.y;
    const int x0 = std::max(0, static_cast<int>(std::floor(c.x - hi)));
    const int x1 = std::min(g.cols - 2, static_cast<int>(std::ceil(c.x + hi)));
    for (int x = x0; x <= x1; ++x) {
      const double r0 = std::hypot(x - c.x, dy), r1 = std::hypot(x + 1 - c.x, dy);
      if (r0 < lo || r0 > hi || r1 < lo || r1 > hi) continue;
      d.push_back(std::abs(static_cast<double>(row[x + 1]) - row[x]));
    }
  }
  const double floor_dn = 1 / std::sqrt(12.0);
  if (d.size() < 16) return floor_dn;
  return std::max(floor_dn, 1.4826 * median(std::move(d)) / std::sqrt(2.0));
}

// The moments' sigma, the larger of two (as the edge fit's): the image's noise carried through
// the moments (each band pixel's coverage moves a centre coordinate by its lever arm over the
// total weight), and the misfit of a disk that the band's coverage shows. For the latter each
// sector's coverage, less that of a sharp disk of radius r about c (which takes out the pixel
// lattice), becomes that sector's shift of the rim; a one-sided error (a highlight on the band, a
// shadow) moves the centre by the shifts' first harmonic and shows in their odd ones.
double moments_sigma(const cv::Mat& g, cv::Point2d c, double r, double inner, double outer,
                     const Levels& lv) {
  constexpr int kSectors = 48;
  std::array<double, kSectors> excess{};
  const double inv = 1.0 / (lv.face - lv.dark);
  double lever2 = 0, sw = kPi * r * r;
  for_each_pixel_within(g, c, outer, [&](int, int, double dx, double dy, double d2, float v) {
    if (d2 <= inner * inner) return;
    const double w = std::clamp((v - lv.dark) * inv, 0.0, 1.0);
    const double sharp = std::clamp(r + 0.5 - std::sqrt(d2), 0.0, 1.0);
    const int k = std::clamp(static_cast<int>((std::atan2(dy, dx) + kPi) / (2 * kPi) * kSectors), 0,
                             kSectors - 1);
    excess[k] += w - sharp;
    lever2 += 0.5 * d2;  // a coordinate's lever arm squared, on average over directions
  });
  const double sigma_noise = face_noise_dn(g, c, r) * inv * std::sqrt(lever2) / sw;
  std::vector<cv::Point2d> rim;
  rim.reserve(kSectors);
  const double sector = 2 * kPi / kSectors;
  for (int k = 0; k < kSectors; ++k) {
    const double a = -kPi + (k + 0.5) * sector;
    const double rk = r + excess[k] / (r * sector);
    rim.emplace_back(c.x + rk * std::cos(a), c.y + rk * std::sin(a));
  }
  return std::max(sigma_noise, odd_harmonic_misfit(rim, c, r, 1e9));
}

}  // namespace

TrackResult refine_moments(const cv::Mat& g, cv::Point2d guess, double re,
                           const TrackerConfig& cfg) {
  TrackResult res;
  cv::Point2d c = guess;
  const Levels lv = disk_levels(g, c, re, 48);
  if (!lv.ok || lv.face - lv.dark < cfg.min_contrast_dn) return res;
  const double inv = 1.0 / (lv.face - lv.dark);
  // Coverage-weighted moments: inside 0.8 of the edge radius the face counts as fully covered
  // (this fills the marker); in the band up to the middle of the O-ring each pixel counts by its
  // coverage (I - ring) / (face - ring). The band stops inside the ring so that neither the table
  // nor the hand beyond it contributes. A few fixed-point iterations re-centre the window.
  const double inner = 0.8 * re, outer = re + 0.043 * re + 0.5;
  double sw = 0;
  for (int it = 0; it < 4; ++it) {
    double sx = 0, sy = 0;
    sw = 0;
    for_each_pixel_within(g, c, outer, [&](int x, int y, double, double, double d2, float v) {
      // Inside 0.8 of the edge radius the face counts as fully covered (the marker filled in).
      const double w = d2 > inner * inner ? std::clamp((v - lv.dark) * inv, 0.0, 1.0) : 1.0;
      sx += w * x;
      sy += w * y;
      sw += w;
    });
    if (sw <= 0) return res;
    c = {sx / sw, sy / sw};
  }
  res.state = TrackState::kTracking;
  res.center = c;
  res.radius_px = std::sqrt(sw / kPi);
  res.sigma_px = moments_sigma(g, c, res.radius_px, inner, outer, lv);
  res.quality = std::clamp(sw / (kPi * re * re), 0.0, 1.0);
  return res;
}

TrackResult refine_hough(const cv::Mat& g, cv::Point2d guess, double re, const TrackerConfig& cfg) {
  (void)cfg;
  TrackResult res;
  const double outer = re / 0.92;
  const int half = static_cast<int>(std::ceil(outer * 1.6 + 8));
  cv::Rect roi(static_cast<int>(guess.x) - half, static_cast<int>(guess.y) - half, 2 * half + 1,
               2 * half + 1);
  roi &= cv::Rect(0, 0, g.cols, g.rows);
  if (roi.width < 8 || roi.height < 8) return res;
  cv::Mat u8;
  g(roi).convertTo(u8, CV_8U);
  cv::GaussianBlur(u8, u8, cv::Size(5, 5), 1.2);
  std::vector<cv::Vec3f> circles;
  cv::HoughCircles(u8, circles, cv::HOUGH_GRADIENT, 1, 2 * outer, 100, 15,
                   static_cast<int>(std::floor(0.85 * re)),
                   static_cast<int>(std::ceil(1.15 * outer)));
  if (circles.empty()) return res;
  res.state = TrackState::kTracking;
  res.center = {circles[0][0] + roi.x, circles[0][1] + roi.y};
  res.radius_px = circles[0][2];
  res.quality = 0.5;
  // HoughCircles reports no uncertainty. Its error is what sets it apart from the sub-pixel edge
  // fit from its circle (an order of magnitude more accurate, and right about its own sigma), so
  // that distance, per coordinate, is its sigma. Where the edge fit finds no disk there, the
  // accumulator's 1 px cells are all that is known.
  const TrackResult edge = refine_edge(g, res.center, re, TrackerConfig{});
  res.sigma_px =
      edge.ok() ? std::hypot(cv::norm(res.center - edge.center) / std::sqrt(2.0), edge.sigma_px)
                : 0.5;
  return res;
}

namespace {

// A frame made grey and f times smaller, with its histogram.
struct SmallGray {
  cv::Mat u8;
  std::array<int, 256> hist{};
};

// 8-bit frames of Channels channels (1: grey, 3: BGR, 4: BGRA), in one pass that reads two of
// every f rows: each small pixel is the mean of the central 2 x 2 pixels of its f x f block (the
// whole block for f = 2), so that it is centred where its block is, made grey with OpenCV's
// BGR2GRAY weights in 16-bit fixed point (0.114, 0.587, 0.299 of the four pixels' sums). A blob
// search needs no more than that, and the frame is read once, on this thread, at a fraction of
// the cost of a full-size grey or float copy.
template <int Channels>
void small_gray_u8(const cv::Mat& frame, int f, SmallGray& s) {
  const int o = f / 2 - 1;  // the first of a block's two central rows and columns
  for (int y = 0; y < s.u8.rows; ++y) {
    const unsigned char* a = frame.ptr<unsigned char>(f * y + o);
    const unsigned char* b = frame.ptr<unsigned char>(f * y + o + 1);
    unsigned char* out = s.u8.ptr<unsigned char>(y);
    for (int x = 0; x < s.u8.cols; ++x) {
      const int i = (f * x + o) * Channels;
      int v = 0;
      if constexpr (Channels == 1) {
        v = (a[i] + a[i + 1] + b[i] + b[i + 1] + 2) >> 2;
      } else {
        const int blue = a[i] + a[i + Channels] + b[i] + b[i + Channels];
        const int green = a[i + 1] + a[i + 1 + Channels] + b[i + 1] + b[i + 1 + Channels];
        const int red = a[i + 2] + a[i + 2 + Channels] + b[i + 2] + b[i + 2 + Channels];
        v = (blue * 1868 + green * 9617 + red * 4899 + (1 << 15)) >> 16;
      }
      out[x] = static_cast<unsigned char>(v);
    }
  }
}

// The histogram of an 8-bit image, counted in four interleaved tables: runs of equal values (a
// uniform table) would otherwise make each count wait on the previous one.
std::array<int, 256> histogram_u8(const cv::Mat& u8) {
  std::array<std::array<int, 256>, 4> part{};
  for (int y = 0; y < u8.rows; ++y) {
    const unsigned char* row = u8.ptr<unsigned char>(y);
    int x = 0;
    for (; x + 4 <= u8.cols; x += 4) {
      ++part[0][row[x]];
      ++part[1][row[x + 1]];
      ++part[2][row[x + 2]];
      ++part[3][row[x + 3]];
    }
    for (; x < u8.cols; ++x) ++part[0][row[x]];
  }
  std::array<int, 256> hist{};
  for (int i = 0; i < 256; ++i) hist[i] = part[0][i] + part[1][i] + part[2][i] + part[3][i];
  return hist;
}

SmallGray small_gray(const cv::Mat& frame, int f) {
  SmallGray s;
  const cv::Size size(frame.cols / f, frame.rows / f);
  s.u8.create(size, CV_8U);
  if (frame.depth() == CV_8U && frame.channels() == 1) {
    small_gray_u8<1>(frame, f, s);
  } else if (frame.depth() == CV_8U && frame.channels() == 3) {
    small_gray_u8<3>(frame, f, s);
  } else if (frame.depth() == CV_8U && frame.channels() == 4) {
    small_gray_u8<4>(frame, f, s);
  } else {
    // Float or 16-bit frames: OpenCV's area average over the blocks, then grey.
    cv::Mat small;
    cv::resize(frame(cv::Rect(0, 0, size.width * f, size.height * f)), small, size, 0, 0,
               cv::INTER_AREA);
    s.u8 = to_gray_u8(small);
  }
  s.hist = histogram_u8(s.u8);
  return s;
}

// The blob search on the frame made f times smaller.
TrackResult acquire_at(const cv::Mat& frame, int f, double expected_re) {
  TrackResult res;
  const SmallGray small = small_gray(frame, f);
  const cv::Mat& u8 = small.u8;
  const std::array<int, 256>& hist = small.hist;
  const long total = static_cast<long>(u8.total());
  auto percentile = [&](double q) {
    long acc = 0;
    for (int i = 0; i < 256; ++i) {
      acc += hist[i];
      if (acc >= q * total) return i;
    }
    return 255;
  };
  const int p_med = percentile(0.5), p_hi = percentile(0.998);
  if (p_hi - p_med < 40) return res;
  // The face (0.92) is the brightest surface; the aluminium hand (0.60) the next. Three quarters
  // of the way from the table to the brightest level lies between them, so a touching hand does
  // not merge with the face blob.
  const double thr = p_med + 0.75 * (p_hi - p_med);
  cv::Mat bin;
  cv::threshold(u8, bin, thr, 255, cv::THRESH_BINARY);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(bin, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  double best_score = 0;
  for (const auto& ct : contours) {
    const double area = cv::contourArea(ct);
    if (area < 30) continue;
    const double perim = cv::arcLength(ct, true);
    cv::Point2f cc;
    float rr = 0;
    cv::minEnclosingCircle(ct, cc, rr);
    const double fill = area / (kPi * rr * rr);
    const double circ = 4 * kPi * area / (perim * perim);
    // The outline runs through the boundary pixels' centres, half a small pixel inside the edge.
    const double re = f * (std::sqrt(area / kPi) + 0.5);
    if (fill < 0.6 || circ < 0.6) continue;
    if (expected_re > 0 && (re < 0.6 * expected_re || re > 1.5 * expected_re)) continue;
    // Rank by brightness first: the face (albedo 0.92) is the brightest surface in the scene,
    // while a lobe of the hand (0.6) can be as round and is larger, and from an oblique camera
    // its shading can lift parts of it over the threshold.
    const cv::Rect box = cv::boundingRect(ct);
    cv::Mat mask = cv::Mat::zeros(box.size(), CV_8U);
    cv::drawContours(mask, std::vector<std::vector<cv::Point>>{ct}, 0, cv::Scalar(255), cv::FILLED,
                     cv::LINE_8, cv::noArray(), 0, -box.tl());
    const double brightness = cv::mean(u8(box), mask)[0];
    const double score = brightness * brightness * brightness * fill * circ;
    if (score > best_score) {
      const cv::Moments mo = cv::moments(ct);
      best_score = score;
      // Small pixel i stands for the frame's pixels f i .. f i + f - 1: centre f i + (f - 1) / 2.
      const double half_span = 0.5 * (f - 1);
      res.center = {f * mo.m10 / mo.m00 + half_span, f * mo.m01 / mo.m00 + half_span};
      res.radius_px = re;
      res.state = TrackState::kFound;
      res.quality = std::clamp(fill * circ, 0.0, 1.0);
      res.sigma_px = 1.0;
    }
  }
  return res;
}

}  // namespace

TrackResult acquire(const cv::Mat& frame, double expected_re) {
  // A quarter-size image is plenty to find the face of a disk whose edge radius is 24 px or more
  // (a blob of 6 px radius or more there), and reading two rows in four halves what the search
  // reads from memory. A smaller or unknown radius falls back to half size, where the face of a
  // disk of 12 px edge radius still fills the 30 pixels the search asks of a blob.
  if (frame.empty()) throw std::invalid_argument("tracker: empty frame");
  for (const int f : {4, 2}) {
    if (frame.cols < 16 * f || frame.rows < 16 * f) continue;
    if (f == 4 && expected_re > 0 && expected_re < 24) continue;
    const TrackResult r = acquire_at(frame, f, expected_re);
    if (r.ok()) return r;
  }
  return {};
}

double image_time_variance_frames2(double exposure_s, double frame_interval_s, bool interlaced,
                                   double camera_frame_interval_s) {
  if (!(frame_interval_s > 0))
    throw std::invalid_argument("tracker: the interval between frames must be > 0");
  const double e = exposure_s / frame_interval_s;
  const double field = interlaced ? 0.25 * camera_frame_interval_s / frame_interval_s : 0.0;
  return e * e / 12 + field * field;
}

Tracker::Tracker(TrackerConfig config) : config_(config) {
  if (config_.rays < 16) throw std::invalid_argument("tracker: rays must be at least 16");
  if (!(config_.ray_step_px > 0)) throw std::invalid_argument("tracker: ray_step_px must be > 0");
  if (!(config_.second_pass_shift_px >= 0))
    throw std::invalid_argument("tracker: second_pass_shift_px must be >= 0");
  if (!(config_.image_time_variance_frames2 >= 0) ||
      !std::isfinite(config_.image_time_variance_frames2))
    throw std::invalid_argument("tracker: image_time_variance_frames2 must be finite and >= 0");
}

void Tracker::reset() {
  have_track_ = false;
  have_acceleration_ = false;
  history_ = 0;
  velocity_ = {0, 0};
}

void Tracker::skip() {
  if (!have_track_) return;
  last_ += velocity_;  // where the skipped frame would have shown it
  have_acceleration_ = false;
  history_ = 0;  // the next centre's velocity spans the predicted step: not a measurement
}

namespace {

// The window of half-size `half` about `centre`, clipped to the frame.
cv::Rect window_about(cv::Point2d centre, double half, const cv::Size& frame) {
  return cv::Rect(static_cast<int>(std::floor(centre.x - half)),
                  static_cast<int>(std::floor(centre.y - half)), static_cast<int>(2 * half) + 2,
                  static_cast<int>(2 * half) + 2) &
         cv::Rect(0, 0, frame.width, frame.height);
}

}  // namespace

// One fit with the configured method in the window `roi` of the frame (only the window is made
// grey); guess and result in the frame's pixels.
TrackResult Tracker::locate(const cv::Mat& frame, const cv::Rect& roi, cv::Point2d guess,
                            double radius, TrackState state) {
  if (roi.width <= 8 || roi.height <= 8) return {};
  const cv::Point2d off(roi.x, roi.y);
  const double expected = config_.edge_radius_px > 0 ? config_.edge_radius_px : radius;
  TrackResult r;
  switch (config_.method) {
    case TrackMethod::kEdge:
      r = refine_edge(to_gray_for_edge(frame(roi)), guess - off, radius, config_, off);
      break;
    case TrackMethod::kMoments:
      r = refine_moments(to_gray_f32(frame(roi)), guess - off, radius, config_);
      if (r.ok()) r.radius_px = radius;  // moments give an area, not the edge radius
      break;
    case TrackMethod::kHough:
      r = refine_hough(to_gray_f32(frame(roi)), guess - off, radius, config_);
      if (r.ok()) r.radius_px = radius;  // Hough may lock on the outer rim instead
      break;
    case TrackMethod::kContour:
      r = fit_contour(to_gray_u8(frame(roi)), guess - off, expected);
      break;
  }
  if (!r.ok()) return r;
  if (std::abs(r.radius_px - expected) > config_.max_radius_change * expected) return {};
  r.center += off;
  r.state = state;
  return r;
}

// Whole-frame (re-)acquisition: the blob search on a smaller copy, then one fit at full
// resolution in a window about the blob (a second pass follows when the blob's centre was off by
// more than second_pass_shift_px, as it usually is). The contour peer searches the whole frame at
// full resolution, as it would be written without flatland.
TrackResult Tracker::reacquire(const cv::Mat& frame) {
  const double expected = config_.edge_radius_px > 0 ? config_.edge_radius_px : radius_;
  if (config_.method == TrackMethod::kContour) {
    TrackResult r = fit_contour(to_gray_u8(frame), std::nullopt, expected);
    if (r.ok()) r.state = TrackState::kFound;
    return r;
  }
  const TrackResult a = acquire(frame, expected);
  if (!a.ok()) return a;
  const double radius = expected > 0 ? expected : a.radius_px;
  // The blob's centre is good to about a pixel of the small copy (4 px at most).
  const double half = radius * 1.2 + config_.roi_margin_px + 4;
  return locate(frame, window_about(a.center, half, frame.size()), a.center, radius,
                TrackState::kFound);
}

TrackResult Tracker::track(const cv::Mat& frame) {
  if (frame.empty()) throw std::invalid_argument("tracker: empty frame");
  if (have_track_) {
    const cv::Point2d p = last_ + velocity_;
    const double half = radius_ * 1.2 + config_.roi_margin_px + cv::norm(velocity_);
    TrackResult r =
        locate(frame, window_about(p, half, frame.size()), p, radius_, TrackState::kTracking);
    if (r.ok()) {
      const cv::Point2d velocity = r.center - last_;
      if (history_ >= 2) {
        acceleration_change_ =
            have_acceleration_ ? velocity - velocity_ - acceleration_ : cv::Point2d(0, 0);
        acceleration_ = velocity - velocity_;
        have_acceleration_ = true;
      }
      velocity_ = velocity;
      last_ = r.center;
      ++history_;
      radius_ = 0.8 * radius_ + 0.2 * r.radius_px;
      return at_time_stamp(r);
    }
  }
  // The window failed (or there is no track): search the same frame whole.
  const TrackResult r = reacquire(frame);
  if (r.ok()) {
    velocity_ = {0, 0};
    have_acceleration_ = false;
    last_ = r.center;
    history_ = 1;
    radius_ = r.radius_px;
    have_track_ = true;
    return r;
  }
  reset();
  return {};
}

// The image shows the disk where it was on average over the times the frame averages; its
// position at the time stamp differs from that mean by acceleration x variance / 2 (a path that
// curves, as over the hand's tip, or speeds up). The track's last three centres give the
// acceleration (per frame interval squared); how much that changed from the frame before is
// what is not known of it here, and goes into sigma.
TrackResult Tracker::at_time_stamp(TrackResult r) const {
  const double v = config_.image_time_variance_frames2;
  if (!(v > 0) || !have_acceleration_) return r;
  r.center -= 0.5 * v * acceleration_;
  r.sigma_px = std::hypot(r.sigma_px, 0.5 * v * cv::norm(acceleration_change_) / std::sqrt(2.0));
  return r;
}

}  // namespace flatland::vision
