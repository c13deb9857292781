// Pixel -> table -> hand -> s_h (mapping.hpp).
#include "flatland/vision/mapping.hpp"

#include "flatland/sim/roots.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace flatland::vision {

cv::Point2d undistort_pixel(const camera::CameraModel& camera, cv::Point2d px) {
  const std::vector<cv::Point2d> in{px};
  std::vector<cv::Point2d> out;
  // Without distortion the inverse is exact in closed form; cv::undistortPoints' iteration
  // would only add its own tolerance.
  if (!camera.distorted()) {
    const cv::Matx33d& K = camera.K;
    const double y = (px.y - K(1, 2)) / K(1, 1);
    return {(px.x - K(0, 2) - K(0, 1) * y) / K(0, 0), y};
  }
  // Many iterations: the default 5 leave ~1e-3 px errors for strong distortion near the corners.
  cv::undistortPoints(
      in, out, cv::Mat(camera.K), cv::Mat(camera.dist), cv::noArray(), cv::noArray(),
      cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 100, 1e-14));
  return out[0];
}

std::optional<cv::Point2d> pixel_to_table(const camera::CameraModel& camera, cv::Point2d px,
                                          double plane_z) {
  const cv::Point2d n = undistort_pixel(camera, px);
  // Camera centre and ray direction in the table frame: x_table = R^T (x_cam - t).
  const cv::Matx33d Rt = camera.R.t();
  const cv::Vec3d origin = -(Rt * camera.t);
  const cv::Vec3d dir = Rt * cv::Vec3d(n.x, n.y, 1.0);
  if (std::abs(dir[2]) < 1e-12) return std::nullopt;
  const double lambda = (plane_z - origin[2]) / dir[2];
  if (!(lambda > 0)) return std::nullopt;
  return cv::Point2d(origin[0] + lambda * dir[0], origin[1] + lambda * dir[1]);
}

std::vector<cv::Point2d> pixels_to_table(const camera::CameraModel& camera,
                                         const std::vector<cv::Point2d>& px, double plane_z) {
  std::vector<cv::Point2d> n;
  if (px.empty()) return n;
  if (camera.distorted()) {
    // A fixed 30 iterations without the EPS test (which reprojects every point each iteration
    // and tripled the tracker's cost): the fixed-point iteration contracts by about
    // |3 k1 r^2| per step, far below 1 within the image of any usable lens.
    cv::undistortPoints(px, n, cv::Mat(camera.K), cv::Mat(camera.dist), cv::noArray(),
                        cv::noArray(), cv::TermCriteria(cv::TermCriteria::COUNT, 30, 0));
  } else {
    n.reserve(px.size());
    for (const cv::Point2d& p : px) n.push_back(undistort_pixel(camera, p));
  }
  const cv::Matx33d Rt = camera.R.t();
  const cv::Vec3d origin = -(Rt * camera.t);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<cv::Point2d> out;
  out.reserve(n.size());
  for (const cv::Point2d& q : n) {
    const cv::Vec3d dir = Rt * cv::Vec3d(q.x, q.y, 1.0);
    const double lambda = std::abs(dir[2]) < 1e-12 ? -1.0 : (plane_z - origin[2]) / dir[2];
    out.push_back(lambda > 0 ? cv::Point2d(origin[0] + lambda * dir[0], origin[1] + lambda * dir[1])
                             : cv::Point2d(nan, nan));
  }
  return out;
}

cv::Point2d table_to_hand(cv::Point2d p_table, cv::Point2d axis_table, double theta) {
  const double c = std::cos(theta), s = std::sin(theta);
  const cv::Point2d d = p_table - axis_table;
  return {c * d.x + s * d.y, -s * d.x + c * d.y};
}

namespace {

// Squared distance from p to the offset point of piece `piece` at s.
double offset_distance2(const sim::HandCurve& hand, double r, const sim::Vec2& p, double s,
                        int piece) {
  const sim::CurveGeometry g = hand.geometry(s, piece);
  return (g.point + r * g.normal - p).squaredNorm();
}

}  // namespace

namespace {
// The open hand's scale of s: s per metre along the curve at s.
double parameter_per_metre(const sim::HandCurve& hand, double s) {
  return 1.0 / hand.geometry(s, hand.piece_at(s, +1)).speed;
}
}  // namespace

ContactEstimate contact_parameter(const sim::HandCurve& hand, double disk_radius,
                                  cv::Point2d p_hand, double guess, double half_window) {
  const sim::Vec2 p(p_hand.x, p_hand.y);
  const double lo = guess - half_window, hi = guess + half_window;
  // The grid is fine enough that the offset curve cannot fold between two nodes for the paper's
  // hand (its tip has curvature radius of a few cm, the offset distance 5 cm; a 400th of the
  // period is 0.01 in s, about 3 mm along it), so the best node's cell brackets the minimum. An
  // open hand has no period: a 20th of the disk's radius along the curve (2.6 mm for the paper's
  // disk).
  const double period = hand.period();
  const double h =
      std::isfinite(period) ? period / 400 : 0.05 * disk_radius * parameter_per_metre(hand, guess);
  const int n = std::max(2, static_cast<int>(std::ceil((hi - lo) / h)));
  double best_s = guess, best_d = std::numeric_limits<double>::infinity();
  for (int i = 0; i <= n; ++i) {
    const double s = lo + (hi - lo) * i / n;
    const double d = offset_distance2(hand, disk_radius, p, s, hand.piece_at(s, +1));
    if (d < best_d) {
      best_d = d;
      best_s = s;
    }
  }
  const double step = (hi - lo) / n;
  // Each piece's formula is valid a little beyond its ends, so the cell [s-step, s+step] can be
  // minimised with the formula of each piece it touches; the better result wins.
  ContactEstimate out;
  out.s_h = best_s;
  out.distance = std::sqrt(best_d);
  out.piece = hand.piece_at(best_s, +1);
  const double a = best_s - step, b = best_s + step;
  for (int piece : {hand.piece_at(a, +1), hand.piece_at(b, -1)}) {
    const sim::PieceInterval iv = hand.piece_interval(piece);
    const double pa = std::max(a, iv.lo), pb = std::min(b, iv.hi);
    if (!(pb > pa)) continue;
    const sim::MinResult m = sim::brent_minimize(
        [&](double s) { return offset_distance2(hand, disk_radius, p, s, piece); }, pa, pb, 1e-12,
        200);
    if (std::sqrt(std::max(0.0, m.fx)) <= out.distance) {
      out.s_h = m.x;
      out.distance = std::sqrt(std::max(0.0, m.fx));
      out.piece = piece;
    }
  }
  return out;
}

std::optional<ContactEstimate> pixel_to_contact(const HandMapping& m, cv::Point2d px, double theta,
                                                double guess, double half_window) {
  const std::optional<cv::Point2d> table = pixel_to_table(m.camera, px, m.plane_z);
  if (!table) return std::nullopt;
  return contact_parameter(*m.hand, m.disk_radius, table_to_hand(*table, m.axis_table, theta),
                           guess, half_window);
}

std::optional<ContactEstimate> follow_contact(const HandMapping& m, cv::Point2d px, double theta,
                                              double previous_s_h) {
  const double period = m.hand->period();
  if (std::isfinite(period))
    return std::isfinite(previous_s_h) ? pixel_to_contact(m, px, theta, previous_s_h, period / 8)
                                       : pixel_to_contact(m, px, theta, 0.0, period / 2);
  // An open hand: no wrap, and no period to search over; the nearest point of the curve to the
  // centre is the contact's for a disk touching a curve without concave parts tighter than it.
  const std::optional<cv::Point2d> table = pixel_to_table(m.camera, px, m.plane_z);
  if (!table) return std::nullopt;
  const cv::Point2d p = table_to_hand(*table, m.axis_table, theta);
  const double guess =
      std::isfinite(previous_s_h) ? previous_s_h : m.hand->nearest(sim::Vec2(p.x, p.y));
  return contact_parameter(*m.hand, m.disk_radius, p, guess,
                           3 * m.disk_radius * parameter_per_metre(*m.hand, guess));
}

double contact_sigma(const HandMapping& m, cv::Point2d px, double sigma_px, double theta,
                     double s_h) {
  const double sp = std::max(sigma_px, 0.02);
  const auto cx = pixel_to_contact(m, px + cv::Point2d(sp, 0), theta, s_h, 0.05);
  const auto cy = pixel_to_contact(m, px + cv::Point2d(0, sp), theta, s_h, 0.05);
  if (!cx || !cy) return 1e-4;
  return std::max(std::hypot(cx->s_h - s_h, cy->s_h - s_h), 1e-6);
}

}  // namespace flatland::vision
