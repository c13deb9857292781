#include "flatland/sim/curve.hpp"
#include "infinity.hpp"
#include "rolling_terms.hpp"

#include "flatland/sim/format.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>
#include <stdexcept>

namespace flatland::sim {

namespace {

// Newton's method on f(s) = (c(s) - p) . c'(s) = 0 from s, each step at most `max_step`, the
// piece re-chosen at each iterate: the nearest point of a smooth curve from a good start.
double refine_nearest(const Curve& curve, const Vec2& p, double s, double max_step) {
  for (int i = 0; i < 8; ++i) {
    const CurveJet j = curve.jet(s, curve.piece_at(s, +1));
    const Vec2 d = j.c - p;
    const double f = d.dot(j.d1), fs = j.d1.squaredNorm() + d.dot(j.d2);
    if (!(fs > 0)) break;  // not a minimum here: keep the sampled start
    const double step = std::clamp(-f / fs, -max_step, max_step);
    s += step;
    if (std::abs(step) <= 1e-15 * (1.0 + std::abs(s))) break;
  }
  return s;
}

// Index of the sample nearest to p.
std::size_t nearest_sample(const std::vector<Vec2>& pts, const Vec2& p) {
  std::size_t best = 0;
  double d2 = (pts[0] - p).squaredNorm();
  for (std::size_t i = 1; i < pts.size(); ++i) {
    const double e = (pts[i] - p).squaredNorm();
    if (e < d2) d2 = e, best = i;
  }
  return best;
}

constexpr int kOutlineSamples = 1024;  // over the polynomial hand's closed outline
}  // namespace

CurveGeometry geometry_from_jet(const CurveJet& jet, int normal_side) {
  return detail::geometry_of(jet, normal_side);
}

CurveGeometry Curve::geometry(double s, int piece) const {
  return geometry_from_jet(jet(s, piece), normal_side());
}

// ---------------------------------------------------------------------------------------------
PolynomialHand::PolynomialHand(double a, double b, double c, double d)
    : a_(a),
      b_(b),
      c_(c),
      d_(d),
      e_(detail::polynomial_coefficients(a, b, c, d).e),
      f_(detail::polynomial_coefficients(a, b, c, d).f) {
  for (double v : {a, b, c, d})
    if (!std::isfinite(v)) throw std::invalid_argument("hand: shape coefficients must be finite");
  outline_.reserve(kOutlineSamples);
  for (int i = 0; i < kOutlineSamples; ++i) {
    const double s = -1.0 + 4.0 * i / kOutlineSamples;
    outline_.push_back(jet(s, piece_at(s, +1)).c);
    reach_ = std::max(reach_, outline_.back().norm());
  }
  // The longest chord between neighbouring coarse samples (nearest()).
  for (int i = 0; i < kOutlineSamples; i += 8)
    coarse_spacing_ =
        std::max(coarse_spacing_, (outline_[(i + 8) % kOutlineSamples] - outline_[i]).norm());
}

double PolynomialHand::nearest(const Vec2& p) const {
  // Coarse to fine: every 8th sample first; the true nearest point lies within half a coarse
  // spacing of a coarse sample no farther than the nearest coarse one plus that half spacing, so
  // only around those is the fine outline scanned; then Newton on the curve itself.
  constexpr int kStride = 8;
  const int n = static_cast<int>(outline_.size());
  double best_coarse = std::numeric_limits<double>::infinity();  // squared distances
  std::array<double, kOutlineSamples / kStride> d2{};
  for (int i = 0; i < n; i += kStride) {
    d2[i / kStride] = (outline_[i] - p).squaredNorm();
    best_coarse = std::min(best_coarse, d2[i / kStride]);
  }
  const double reach = std::sqrt(best_coarse) + 0.5 * coarse_spacing_;
  const double reach2 = reach * reach;
  int best = 0;
  double best_d2 = std::numeric_limits<double>::infinity();
  for (int c = 0; c < n / kStride; ++c) {
    if (d2[c] > reach2) continue;
    for (int k = -kStride; k <= kStride; ++k) {
      const int i = ((c * kStride + k) % n + n) % n;
      const double e = (outline_[i] - p).squaredNorm();
      if (e < best_d2) best_d2 = e, best = i;
    }
  }
  const double spacing = 4.0 / kOutlineSamples;
  const double s = refine_nearest(*this, p, -1.0 + spacing * best, spacing);
  return std::remainder(s - 1.0, 4.0) + 1.0;  // into [-1, 3)
}

int PolynomialHand::piece_at(double s, int direction) const {
  const double x = (s + 1.0) / 2.0;
  int m = static_cast<int>(std::floor(x));
  if (direction < 0 && x == std::floor(x)) --m;  // exactly on breakpoint 2m - 1, moving down
  return m;
}

PieceInterval PolynomialHand::piece_interval(int piece) const {
  return {2.0 * piece - 1.0, 2.0 * piece + 1.0};
}

CurveJet PolynomialHand::jet(double s, int piece) const {
  return detail::polynomial_hand_jet(detail::PolynomialCoefficients<double>{a_, b_, c_, d_, e_, f_},
                                     s, piece);
}

std::string PolynomialHand::describe() const {
  return "polynomial hand a=" + format_significant(a_) + " b=" + format_significant(b_) +
         " c=" + format_significant(c_) + " d=" + format_significant(d_) + " m";
}

// ---------------------------------------------------------------------------------------------
LineCurve::LineCurve(Vec2 origin, Vec2 direction) : origin_(origin), direction_(direction) {
  const double n = direction_.norm();
  if (!(n > 0) || !origin.allFinite() || !direction.allFinite())
    throw std::invalid_argument("line: direction must be finite and non-zero");
  direction_ /= n;
}
PieceInterval LineCurve::piece_interval(int) const { return {-kInf, kInf}; }
double LineCurve::reach() const { return kInf; }
double LineCurve::period() const { return kInf; }
CurveJet LineCurve::jet(double s, int) const {
  return {origin_ + s * direction_, direction_, Vec2::Zero(), Vec2::Zero()};
}
std::string LineCurve::describe() const { return "straight line"; }

// ---------------------------------------------------------------------------------------------
CircleCurve::CircleCurve(Vec2 center, double radius, Side side)
    : center_(center), radius_(radius), side_(side) {
  if (!(radius > 0) || !std::isfinite(radius))
    throw std::invalid_argument("circle: radius must be positive and finite, got " +
                                format_significant(radius));
}
PieceInterval CircleCurve::piece_interval(int) const { return {-kInf, kInf}; }
CurveJet CircleCurve::jet(double s, int) const {
  const double cs = std::cos(s), sn = std::sin(s), r = radius_;
  if (side_ == Side::kConvexBody)
    return {center_ + r * Vec2(cs, sn), r * Vec2(-sn, cs), r * Vec2(-cs, -sn), r * Vec2(sn, -cs)};
  return {center_ + r * Vec2(sn, -cs), r * Vec2(cs, sn), r * Vec2(-sn, cs), r * Vec2(-cs, -sn)};
}
double CircleCurve::nearest(const Vec2& p) const {
  const Vec2 d = p - center_;
  return side_ == Side::kConvexBody ? std::atan2(d.y(), d.x()) : std::atan2(d.x(), -d.y());
}
std::string CircleCurve::describe() const {
  return std::string(side_ == Side::kConvexBody ? "circle" : "circular well") + " of radius " +
         format_significant(radius_) + " m";
}

// ---------------------------------------------------------------------------------------------
CircleWellHand::CircleWellHand(Vec2 center, double radius)
    : center_(center), well_(center, radius, CircleCurve::Side::kConcaveWell) {
  if (!center.allFinite()) throw std::invalid_argument("circular well: centre must be finite");
}
double CircleWellHand::period() const { return 2.0 * std::numbers::pi; }

// ---------------------------------------------------------------------------------------------
EllipseCurve::EllipseCurve(double ax, double ay) : ax_(ax), ay_(ay) {
  if (!(ax > 0) || !(ay > 0) || !std::isfinite(ax) || !std::isfinite(ay))
    throw std::invalid_argument("ellipse: semi-axes must be positive and finite");
}
PieceInterval EllipseCurve::piece_interval(int) const { return {-kInf, kInf}; }
CurveJet EllipseCurve::jet(double s, int) const {
  const double cs = std::cos(s), sn = std::sin(s);
  return {Vec2(ax_ * cs, ay_ * sn), Vec2(-ax_ * sn, ay_ * cs), Vec2(-ax_ * cs, -ay_ * sn),
          Vec2(ax_ * sn, -ay_ * cs)};
}
double EllipseCurve::nearest(const Vec2& p) const {
  std::vector<Vec2> pts(64);
  for (std::size_t i = 0; i < pts.size(); ++i)
    pts[i] = jet(2.0 * std::numbers::pi * static_cast<double>(i) / 64.0, 0).c;
  const double spacing = 2.0 * std::numbers::pi / 64.0;
  return refine_nearest(*this, p, spacing * static_cast<double>(nearest_sample(pts, p)), spacing);
}
std::string EllipseCurve::describe() const {
  return "ellipse " + format_significant(ax_) + " x " + format_significant(ay_) + " m";
}

// ---------------------------------------------------------------------------------------------
namespace {
bool segments_intersect(const Vec2& p1, const Vec2& p2, const Vec2& q1, const Vec2& q2) {
  const double d1 = cross2(q2 - q1, p1 - q1), d2 = cross2(q2 - q1, p2 - q1);
  const double d3 = cross2(p2 - p1, q1 - p1), d4 = cross2(p2 - p1, q2 - p1);
  return ((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0));
}
std::string where(double s, const Vec2& p) {
  return "at s_h=" + format_significant(s) + " (x=" + format_significant(p.x()) +
         " m, y=" + format_significant(p.y()) + " m)";
}
}  // namespace

namespace {

void check_disk_radius(double disk_radius) {
  if (!(disk_radius > 0) || !std::isfinite(disk_radius))
    throw std::invalid_argument("object.radius: must be positive and finite, got " +
                                format_significant(disk_radius));
}

// One sample of the outline: no cusp (speed above `min_speed`) and, for a disk (radius > 0), no
// concave part tighter than it.
void check_outline_sample(const CurveGeometry& g, double s, double min_speed, double disk_radius) {
  if (!(g.speed > min_speed))
    throw std::invalid_argument("hand: outline has a cusp (zero parametric speed) " +
                                where(s, g.point));
  if (disk_radius > 0 && g.curvature < 0 && !(disk_radius * -g.curvature < 1.0))
    throw std::invalid_argument("hand: concave part too tight for the disk (curvature radius " +
                                format_significant(-1.0 / g.curvature) + " m <= disk radius " +
                                format_significant(disk_radius) + " m) " + where(s, g.point));
}

// The first pair (in outline order) of crossing segments of the polyline through every
// `stride`-th point (closed: the last joined to the first), or none. Only the segment pairs whose
// x ranges overlap are tested (a sweep over the segments sorted by their left end: about 1 % of
// all pairs on the paper's hand); the pair found is the first in outline order, as a test of every
// pair would find.
std::optional<std::pair<int, int>> first_crossing(const std::vector<Vec2>& pts, int stride,
                                                  bool closed) {
  const int points = static_cast<int>(pts.size());
  const int segments = closed ? points / stride : (points - 1) / stride;
  auto end_of = [&](int k) { return pts[static_cast<std::size_t>(((k + 1) * stride) % points)]; };
  auto start_of = [&](int k) { return pts[static_cast<std::size_t>(k * stride)]; };
  std::vector<double> x_lo(segments), x_hi(segments);
  std::vector<int> by_left(segments);
  for (int k = 0; k < segments; ++k) {
    x_lo[k] = std::min(start_of(k).x(), end_of(k).x());
    x_hi[k] = std::max(start_of(k).x(), end_of(k).x());
    by_left[k] = k;
  }
  std::sort(by_left.begin(), by_left.end(), [&](int a, int b) { return x_lo[a] < x_lo[b]; });
  std::pair<int, int> first{segments, segments};
  for (int p = 0; p < segments; ++p) {
    const int a = by_left[p];
    for (int q = p + 1; q < segments && x_lo[by_left[q]] <= x_hi[a]; ++q) {
      const int i = std::min(a, by_left[q]), j = std::max(a, by_left[q]);
      if (j - i < 2 || (closed && i == 0 && j == segments - 1)) continue;  // neighbours
      if (segments_intersect(start_of(i), end_of(i), start_of(j), end_of(j)))
        first = std::min(first, {i, j});
    }
  }
  if (first.first == segments) return std::nullopt;
  return std::pair{first.first * stride, first.second * stride};
}

void check_wells(const HandCurve& hand, int piece_at_wells) {
  for (double s : {-1.0, 1.0}) {
    const CurveGeometry g =
        hand.geometry(s, piece_at_wells < 0 ? hand.piece_at(s, +1) : piece_at_wells);
    if (!(g.curvature < 0))
      throw std::invalid_argument(std::string("hand: no well at the ") + (s < 0 ? "palm" : "back") +
                                  " (the outline must be concave there, curvature " +
                                  format_significant(g.curvature) + " 1/m) " + where(s, g.point));
  }
}

void validate_polynomial_hand(const PolynomialHand& hand, double disk_radius) {
  if (!(hand.a() > 0))
    throw std::invalid_argument("hand.a: the tip x(0) = a must be positive, got " +
                                format_significant(hand.a()));
  // The right half is sampled densely; the left half is its mirror, so the checks below cover
  // the whole outline.
  constexpr int kSamples = 2000;
  std::vector<Vec2> pts(kSamples + 1);
  for (int i = 0; i <= kSamples; ++i) {
    const double s = -1.0 + 2.0 * i / kSamples;
    const CurveGeometry g = hand.geometry(s, 0);
    pts[i] = g.point;
    if (!(g.speed > 1e-9 * std::abs(hand.a())))
      throw std::invalid_argument("hand: outline has a cusp (zero parametric speed) " +
                                  where(s, g.point));
    if (i > 0 && i < kSamples && !(g.point.x() > 0))
      throw std::invalid_argument(
          "hand: outline self-intersects (right half reaches its mirror image, x <= 0) " +
          where(s, g.point));
    check_outline_sample(g, s, 1e-9 * std::abs(hand.a()), disk_radius);
  }
  // Self-intersection of the right half on a coarser polyline.
  if (const auto crossing = first_crossing(pts, 4, false)) {
    const auto [i, j] = *crossing;
    throw std::invalid_argument("hand: outline self-intersects between " +
                                where(-1.0 + 2.0 * i / kSamples, pts[i]) + " and " +
                                where(-1.0 + 2.0 * j / kSamples, pts[j]));
  }
  check_wells(hand, 0);
}

// Any other closed outline, over its whole period from s = -1; a disk radius of 0 skips the
// disk's checks.
void validate_closed_outline(const HandCurve& hand, double disk_radius) {
  const double period = hand.period();
  if (!std::isfinite(period) || !(period > 0))
    throw std::invalid_argument("hand: " + hand.describe() +
                                " is not a closed outline (its checks need a finite period)");
  constexpr int kSamples = 4000;
  const double min_speed = 1e-9 * hand.reach();
  std::vector<Vec2> pts(kSamples);
  for (int i = 0; i < kSamples; ++i) {
    const double s = -1.0 + period * i / kSamples;
    const CurveGeometry g = hand.geometry(s);
    pts[i] = g.point;
    check_outline_sample(g, s, min_speed, disk_radius);
  }
  if (const auto crossing = first_crossing(pts, 1, true)) {
    const auto [i, j] = *crossing;
    throw std::invalid_argument("hand: outline self-intersects between " +
                                where(-1.0 + period * i / kSamples, pts[i]) + " and " +
                                where(-1.0 + period * j / kSamples, pts[j]));
  }
}

}  // namespace

void validate_hand_for_disk(const HandCurve& hand, double disk_radius) {
  check_disk_radius(disk_radius);
  if (const auto* polynomial = dynamic_cast<const PolynomialHand*>(&hand))
    return validate_polynomial_hand(*polynomial, disk_radius);
  validate_closed_outline(hand, disk_radius);
  if (hand.has_palm_and_back()) check_wells(hand, -1);
}

void validate_hand_outline(const HandCurve& hand) { validate_closed_outline(hand, 0.0); }

}  // namespace flatland::sim
