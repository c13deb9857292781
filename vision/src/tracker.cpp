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
  }
  return "edge";
}

TrackMethod parse_track_method(const std::string& name) {
  if (name == "edge") return TrackMethod::kEdge;
  if (name == "moments") return TrackMethod::kMoments;
  if (name == "hough") return TrackMethod::kHough;
  throw std::invalid_argument("tracker method: expected edge, moments or hough, got '" + name +
                              "'");
}

cv::Mat to_gray_f32(const cv::Mat& frame) {
  if (frame.empty()) throw std::invalid_argument("tracker: empty frame");
  if (frame.type() == CV_32FC1) return frame;
  cv::Mat f;
  frame.convertTo(f, CV_32F);
  if (f.channels() == 3) {
    cv::cvtColor(f, f, cv::COLOR_BGR2GRAY);
  } else if (f.channels() == 4) {
    cv::cvtColor(f, f, cv::COLOR_BGRA2GRAY);
  } else if (f.channels() != 1) {
    throw std::invalid_argument("tracker: frames must have 1, 3 or 4 channels");
  }
  return f;
}

namespace {

constexpr double kPi = std::numbers::pi;

// Bilinear sample; NaN outside the image so that rays leaving the frame are simply dropped.
inline float sample(const cv::Mat& g, double x, double y) {
  if (!(x >= 0 && y >= 0 && x <= g.cols - 1.0 && y <= g.rows - 1.0))
    return std::numeric_limits<float>::quiet_NaN();
  const int x0 = std::min(static_cast<int>(x), g.cols - 2 < 0 ? 0 : g.cols - 2);
  const int y0 = std::min(static_cast<int>(y), g.rows - 2 < 0 ? 0 : g.rows - 2);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  const float* r0 = g.ptr<float>(y0);
  const float* r1 = g.ptr<float>(std::min(y0 + 1, g.rows - 1));
  const int x1 = std::min(x0 + 1, g.cols - 1);
  const float top = r0[x0] + fx * (r0[x1] - r0[x0]);
  const float bottom = r1[x0] + fx * (r1[x1] - r1[x0]);
  return top + fy * (bottom - top);
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

Levels disk_levels(const cv::Mat& g, cv::Point2d c, double re, int rays) {
  std::vector<double> face, dark;
  face.reserve(rays);
  dark.reserve(rays);
  for (int k = 0; k < rays; ++k) {
    const double a = 2 * kPi * k / rays, dx = std::cos(a), dy = std::sin(a);
    const float f = sample(g, c.x + 0.8 * re * dx, c.y + 0.8 * re * dy);
    if (std::isfinite(f)) face.push_back(f);
    double lo = std::numeric_limits<double>::infinity();
    for (double rho = 0.95 * re; rho <= 1.2 * re + 2; rho += 0.5) {
      const float v = sample(g, c.x + rho * dx, c.y + rho * dy);
      if (std::isfinite(v)) lo = std::min(lo, static_cast<double>(v));
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

struct CircleFit {
  cv::Point2d c;
  double r = 0, sigma_r = 0, sigma_c = 0;
  int inliers = 0;
  bool ok = false;
};

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
  out.sigma_c = std::sqrt(std::max(0.0, 0.5 * (cov(0, 0) + cov(1, 1))));
  out.ok = std::isfinite(cx) && std::isfinite(cy) && std::isfinite(r) && r > 0;
  return out;
}

// Sub-pixel edge points: along each ray from the centre guess, the downward crossing of the
// face/ring mid-level nearest to the expected radius (the marker's edges are crossings too, but
// lie at most 0.67 of the radius out).
std::vector<cv::Point2d> edge_points(const cv::Mat& g, cv::Point2d c, double re, const Levels& lv,
                                     const TrackerConfig& cfg, int* rays_in_image) {
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
    bool inside = true;
    for (int j = 0; j < m; ++j) {
      const double rho = rho0 + j * step;
      prof[j] = sample(g, c.x + rho * dx, c.y + rho * dy);
      if (!std::isfinite(prof[j])) inside = false;
    }
    if (!inside) continue;
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

}  // namespace

TrackResult refine_edge(const cv::Mat& g, cv::Point2d guess, double re, const TrackerConfig& cfg,
                        cv::Point2d offset) {
  TrackResult res;
  cv::Point2d c = guess;
  double r = re;
  // Two passes: the second casts its rays from the first fit's centre, so that every ray meets
  // the edge nearly at right angles and the crossings are symmetric about the centre.
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
    if (pass == 1) {
      res.state = TrackState::kTracking;
      res.center = c;
      res.radius_px = r;
      res.sigma_px = f.sigma_c;
      res.edge_points = f.inliers;
      // Quality: the share of rays that gave an inlier edge point, discounted by the residual
      // scale relative to a sharp edge (blur or a wrong shape raise it).
      const double share = static_cast<double>(f.inliers) / cfg.rays;
      res.quality = std::clamp(share * std::exp(-f.sigma_r / 2.0), 0.0, 1.0);
    }
  }
  return res;
}

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
  double sw = 0, n_band = 0;
  for (int it = 0; it < 4; ++it) {
    double sx = 0, sy = 0;
    sw = 0;
    n_band = 0;
    const int x0 = std::max(0, static_cast<int>(std::floor(c.x - outer)));
    const int x1 = std::min(g.cols - 1, static_cast<int>(std::ceil(c.x + outer)));
    const int y0 = std::max(0, static_cast<int>(std::floor(c.y - outer)));
    const int y1 = std::min(g.rows - 1, static_cast<int>(std::ceil(c.y + outer)));
    for (int y = y0; y <= y1; ++y) {
      const float* row = g.ptr<float>(y);
      const double dy = y - c.y;
      for (int x = x0; x <= x1; ++x) {
        const double dx = x - c.x, d2 = dx * dx + dy * dy;
        if (d2 > outer * outer) continue;
        double w = 1.0;
        if (d2 > inner * inner) {
          w = std::clamp((row[x] - lv.dark) * inv, 0.0, 1.0);
          n_band += 1;
        }
        sx += w * x;
        sy += w * y;
        sw += w;
      }
    }
    if (sw <= 0) return res;
    c = {sx / sw, sy / sw};
  }
  res.state = TrackState::kTracking;
  res.center = c;
  res.radius_px = std::sqrt(sw / kPi);
  // Noise propagation: each band pixel's coverage carries the image noise (estimated from the
  // face's spread is not available here; 2 DN assumed) times its lever arm ~ re.
  const double noise_dn = 2.0;
  res.sigma_px = noise_dn * inv * re * std::sqrt(std::max(1.0, n_band) / 2.0) / sw;
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
  res.sigma_px = 0.5;  // HoughCircles reports no uncertainty; its accumulator has 1 px cells
  res.quality = 0.5;
  return res;
}

TrackResult acquire(const cv::Mat& g, double expected_re) {
  TrackResult res;
  // Half resolution is plenty to find a ~70 px blob and keeps re-acquisition well under 3 ms.
  cv::Mat half;
  cv::resize(g, half, cv::Size(g.cols / 2, g.rows / 2), 0, 0, cv::INTER_AREA);
  cv::Mat u8;
  half.convertTo(u8, CV_8U);
  std::array<int, 256> hist{};
  for (int y = 0; y < u8.rows; ++y) {
    const unsigned char* row = u8.ptr<unsigned char>(y);
    for (int x = 0; x < u8.cols; ++x) ++hist[row[x]];
  }
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
    const double re = 2.0 * std::sqrt(area / kPi) + 1.0;
    if (fill < 0.6 || circ < 0.6) continue;
    if (expected_re > 0 && (re < 0.6 * expected_re || re > 1.5 * expected_re)) continue;
    // Rank by brightness first: the face (albedo 0.92) is the brightest surface in the scene,
    // while a lobe of the hand (0.6) can be as round and is larger, and from an oblique camera
    // its shading can lift parts of it over the threshold.
    const cv::Rect box = cv::boundingRect(ct);
    cv::Mat mask = cv::Mat::zeros(box.size(), CV_8U);
    cv::drawContours(mask, std::vector<std::vector<cv::Point>>{ct}, 0, cv::Scalar(255), cv::FILLED,
                     cv::LINE_8, cv::noArray(), 0, -box.tl());
    const double brightness = cv::mean(half(box), mask)[0];
    const double score = brightness * brightness * brightness * fill * circ;
    if (score > best_score) {
      const cv::Moments mo = cv::moments(ct);
      best_score = score;
      // Half-resolution pixel i covers full-resolution pixels 2i and 2i+1: centre 2i + 0.5.
      res.center = {2.0 * mo.m10 / mo.m00 + 0.5, 2.0 * mo.m01 / mo.m00 + 0.5};
      res.radius_px = re;
      res.state = TrackState::kFound;
      res.quality = std::clamp(fill * circ, 0.0, 1.0);
      res.sigma_px = 1.0;
    }
  }
  return res;
}

Tracker::Tracker(TrackerConfig config) : config_(config) {
  if (config_.rays < 16) throw std::invalid_argument("tracker: rays must be at least 16");
  if (!(config_.ray_step_px > 0)) throw std::invalid_argument("tracker: ray_step_px must be > 0");
}

void Tracker::reset() {
  have_track_ = false;
  history_ = 0;
  velocity_ = {0, 0};
}

TrackResult Tracker::locate(const cv::Mat& g, cv::Point2d guess, double radius, TrackState state,
                            cv::Point2d offset) {
  TrackResult r;
  switch (config_.method) {
    case TrackMethod::kEdge:
      r = refine_edge(g, guess, radius, config_, offset);
      break;
    case TrackMethod::kMoments:
      r = refine_moments(g, guess, radius, config_);
      if (r.ok()) r.radius_px = radius;  // moments give an area, not the edge radius
      break;
    case TrackMethod::kHough:
      r = refine_hough(g, guess, radius, config_);
      if (r.ok()) r.radius_px = radius;  // Hough may lock on the outer rim instead
      break;
  }
  if (!r.ok()) return r;
  const double expected = config_.edge_radius_px > 0 ? config_.edge_radius_px : radius;
  if (std::abs(r.radius_px - expected) > config_.max_radius_change * expected) return {};
  r.state = state;
  return r;
}

TrackResult Tracker::track(const cv::Mat& frame) {
  if (frame.empty()) throw std::invalid_argument("tracker: empty frame");
  const cv::Rect whole(0, 0, frame.cols, frame.rows);
  if (have_track_) {
    const cv::Point2d p = last_ + velocity_;
    const double half = radius_ * 1.2 + config_.roi_margin_px + cv::norm(velocity_);
    const cv::Rect roi =
        cv::Rect(static_cast<int>(std::floor(p.x - half)), static_cast<int>(std::floor(p.y - half)),
                 static_cast<int>(2 * half) + 2, static_cast<int>(2 * half) + 2) &
        whole;
    if (roi.width > 8 && roi.height > 8) {
      const cv::Mat g = to_gray_f32(frame(roi));
      const cv::Point2d off(roi.x, roi.y);
      TrackResult r = locate(g, p - off, radius_, TrackState::kTracking, off);
      if (r.ok()) {
        r.center += off;
        velocity_ = r.center - last_;
        last_ = r.center;
        ++history_;
        radius_ = 0.8 * radius_ + 0.2 * r.radius_px;
        return r;
      }
    }
  }
  // Whole-frame (re-)acquisition.
  const cv::Mat g = to_gray_f32(frame);
  const double expected = config_.edge_radius_px > 0 ? config_.edge_radius_px : radius_;
  const TrackResult a = acquire(g, expected);
  if (a.ok()) {
    TrackResult r = locate(g, a.center, expected > 0 ? expected : a.radius_px, TrackState::kFound);
    // A second pass from the refined centre and radius: the blob's radius is only approximate.
    if (r.ok()) {
      TrackResult r2 = locate(g, r.center, r.radius_px, TrackState::kFound);
      if (r2.ok()) r = r2;
    }
    if (r.ok()) {
      velocity_ = {0, 0};
      last_ = r.center;
      history_ = 1;
      radius_ = r.radius_px;
      have_track_ = true;
      return r;
    }
  }
  reset();
  return {};
}

}  // namespace flatland::vision
