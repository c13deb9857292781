#include "flatland/sim/hand_shapes.hpp"
#include "infinity.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <unsupported/Eigen/Splines>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <system_error>

namespace flatland::sim {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr int kDegree = 5;  // quintic: C4, so the jet to d3 (the dynamics' dK/ds) is C1
constexpr double kFactorial[6] = {1, 1, 2, 6, 24, 120};

// ---------------------------------------------------------------------------------------------
// A periodic quintic spline with its knots at the data's parameters, in piecewise-polynomial
// form. Written here rather than taken from a library: Eigen's Splines module (used below for the
// B-spline basis) interpolates only, without periodicity or smoothing, and the sim module links
// Eigen alone (GSL's B-splines, which Debian 12 has as 2.7, offer neither either).

/// Taylor coefficients per span: coefficient k of dimension d at index d * 6 + k.
struct PeriodicSpline {
  std::vector<double> knots;  ///< n span starts, then the first plus the period
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> taylor;  ///< n x 6 D
};

using KnotVector = Eigen::Array<double, 1, Eigen::Dynamic>;
using BasisSpline = Eigen::Spline<double, 1, kDegree>;

/// The knots t_0 < ... < t_{n-1} < t_0 + period continued periodically by `kDegree` each side.
KnotVector extended_knots(const std::vector<double>& t, double period) {
  const int n = static_cast<int>(t.size());
  KnotVector u(n + 2 * kDegree + 1);
  for (int k = 0; k < u.size(); ++k) {
    const int i = k - kDegree;
    const int wraps = i >= 0 ? i / n : -((-i + n - 1) / n);
    u[k] = t[static_cast<std::size_t>(i - wraps * n)] + wraps * period;
  }
  return u;
}

/// The spline minimising mean |c(t_i) - v_i|^2 + weight * (1/period) int |c'''|^2 over a period
/// (weight 0: interpolation), for the rows of `values` at the parameters t (strictly increasing,
/// spanning less than `period`, at least 6). Throws std::invalid_argument (`field`) when the
/// system is singular.
PeriodicSpline fit_periodic_spline(const std::vector<double>& t, const Eigen::MatrixXd& values,
                                   double period, double weight, const std::string& field) {
  const int n = static_cast<int>(t.size());
  const int dims = static_cast<int>(values.cols());
  const KnotVector u = extended_knots(t, period);
  // Basis function j of the extended vector is periodic control point j mod n; on span i (knots
  // u[i], u[i + 1]) the non-zero ones are i - 5 .. i.
  auto control = [n](int span, int j) { return (span - kDegree + j) % n; };
  std::vector<Eigen::Triplet<double>> collocation, penalty;
  for (int i = 0; i < n; ++i) {
    const int span = i + kDegree;
    const auto basis = BasisSpline::BasisFunctionDerivatives(t[i], 0, kDegree, u);
    for (int j = 0; j <= kDegree; ++j)
      if (basis(0, j) != 0) collocation.emplace_back(i, control(span, j), basis(0, j));
  }
  Eigen::SparseMatrix<double> B(n, n);
  B.setFromTriplets(collocation.begin(), collocation.end());
  Eigen::MatrixXd coefficients;
  if (weight == 0) {
    Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(B);
    if (lu.info() == Eigen::Success) coefficients = lu.solve(values);
    if (lu.info() != Eigen::Success || !coefficients.allFinite())
      throw std::invalid_argument(field + ": the interpolating spline is singular");
  } else {
    // Gauss-Legendre with 3 nodes integrates the product of two quadratics (c''') exactly.
    const double node = std::sqrt(0.6), gauss_x[3] = {-node, 0, node};
    const double gauss_w[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
    for (int i = 0; i < n; ++i) {
      const int span = i + kDegree;
      const double lo = u[span], hi = u[span + 1], half = 0.5 * (hi - lo);
      for (int g = 0; g < 3; ++g) {
        const auto d =
            BasisSpline::BasisFunctionDerivatives(lo + half * (1 + gauss_x[g]), 3, kDegree, u);
        for (int a = 0; a <= kDegree; ++a)
          for (int b = 0; b <= kDegree; ++b)
            penalty.emplace_back(control(span, a), control(span, b),
                                 weight / period * gauss_w[g] * half * d(3, a) * d(3, b));
      }
    }
    Eigen::SparseMatrix<double> A(n, n);
    A.setFromTriplets(penalty.begin(), penalty.end());
    A += (1.0 / n) * Eigen::SparseMatrix<double>(B.transpose() * B);
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(A);
    if (ldlt.info() == Eigen::Success)
      coefficients = ldlt.solve((1.0 / n) * (B.transpose() * values));
    if (ldlt.info() != Eigen::Success || !coefficients.allFinite())
      throw std::invalid_argument(field + ": the smoothing spline is singular");
  }
  PeriodicSpline s;
  s.knots = t;
  s.knots.push_back(t.front() + period);
  s.taylor.resize(n, 6 * dims);
  for (int i = 0; i < n; ++i) {
    const auto d = BasisSpline::BasisFunctionDerivatives(t[i], kDegree, kDegree, u);
    for (int dim = 0; dim < dims; ++dim)
      for (int k = 0; k <= kDegree; ++k) {
        double v = 0;
        for (int j = 0; j <= kDegree; ++j)
          v += d(k, j) * coefficients(control(i + kDegree, j), dim);
        s.taylor(i, dim * 6 + k) = v / kFactorial[k];
      }
  }
  return s;
}

/// Value and first three derivatives of the Taylor polynomial c[0..5] at offset h.
std::array<double, 4> taylor_jet(const double* c, double h) {
  return {((((c[5] * h + c[4]) * h + c[3]) * h + c[2]) * h + c[1]) * h + c[0],
          (((5 * c[5] * h + 4 * c[4]) * h + 3 * c[3]) * h + 2 * c[2]) * h + c[1],
          ((20 * c[5] * h + 12 * c[4]) * h + 6 * c[3]) * h + 2 * c[2],
          (60 * c[5] * h + 24 * c[4]) * h + 6 * c[3]};
}

/// The integral of the bump 2772 x^5 (1 - x)^5 (of unit integral over [0, 1], its derivatives to
/// the 4th zero at both ends) from 0 to x, and its first three derivatives (the bump, its first
/// and second derivatives).
/// Coefficients of 2772 x^5 (1 - x)^5 = sum_j c_j x^(5 + j), j = 0 .. 5, divided by `divisor(j)`.
template <class Divisor>
constexpr std::array<double, 6> bump_coefficients(Divisor divisor) {
  constexpr double kBinomial[6] = {1, 5, 10, 10, 5, 1};
  std::array<double, 6> c{};
  for (int j = 0; j <= 5; ++j) c[j] = (j % 2 ? -2772.0 : 2772.0) * kBinomial[j] / divisor(j);
  return c;
}

std::array<double, 4> unit_bump(double x) {
  // Each of the four is x^p times a quintic in x, by Horner's rule on coefficients fixed at
  // compile time (this runs in every evaluation of the hand's jet).
  static constexpr auto kIntegral = bump_coefficients([](int j) { return 6.0 + j; });
  static constexpr auto kBump = bump_coefficients([](int) { return 1.0; });
  static constexpr auto kSlope = bump_coefficients([](int j) { return 1.0 / (5.0 + j); });
  static constexpr auto kCurve =
      bump_coefficients([](int j) { return 1.0 / ((5.0 + j) * (4.0 + j)); });
  auto quintic = [x](const std::array<double, 6>& c) {
    return ((((c[5] * x + c[4]) * x + c[3]) * x + c[2]) * x + c[1]) * x + c[0];
  };
  const double x2 = x * x, x3 = x2 * x, x4 = x2 * x2;
  return {quintic(kIntegral) * x4 * x2, quintic(kBump) * x4 * x, quintic(kSlope) * x4,
          quintic(kCurve) * x3};
}

/// Equal cells over [knots.front(), knots.back()), each holding the index of the span its start
/// lies in: a span is then found in constant time plus a short search.
std::vector<int> span_lookup(const std::vector<double>& knots) {
  const int spans = static_cast<int>(knots.size()) - 1;
  std::vector<int> cells(static_cast<std::size_t>(4 * spans + 1));
  const double lo = knots.front(), width = (knots.back() - lo) / (4 * spans);
  int span = 0;
  for (std::size_t c = 0; c < cells.size(); ++c) {
    const double x = lo + width * static_cast<double>(c);
    while (span + 1 < spans && knots[span + 1] <= x) ++span;
    cells[c] = span;
  }
  return cells;
}

int find_span(const std::vector<double>& knots, const std::vector<int>& cells, double u) {
  const int spans = static_cast<int>(knots.size()) - 1;
  const double lo = knots.front(), width = (knots.back() - lo) / (4 * spans);
  const int c = std::clamp(static_cast<int>((u - lo) / width), 0, 4 * spans - 1);
  // The span holding u lies between the spans of the cell's two ends.
  const auto first = knots.begin() + cells[c], last = knots.begin() + cells[c + 1] + 1;
  const int i = static_cast<int>(std::upper_bound(first, last, u) - knots.begin()) - 1;
  return std::clamp(i, 0, spans - 1);
}

/// Newton's method on (c(s) - p) . c'(s) = 0 from a sampled start, each step at most `max_step`.
double refine_nearest_on_outline(const Curve& curve, const Vec2& p, double s, double max_step) {
  for (int i = 0; i < 8; ++i) {
    const CurveJet j = curve.jet(s, 0);
    const Vec2 d = j.c - p;
    const double f = d.dot(j.d1), fs = j.d1.squaredNorm() + d.dot(j.d2);
    if (!(fs > 0)) break;
    const double step = std::clamp(-f / fs, -max_step, max_step);
    s += step;
    if (std::abs(step) <= 1e-15 * (1.0 + std::abs(s))) break;
  }
  return s;
}

/// The parameter of the sample nearest to p, then refined: samples at `step` from s = -1.
double nearest_on_outline(const Curve& curve, const std::vector<Vec2>& outline, const Vec2& p) {
  std::size_t best = 0;
  double best_d2 = kInf;
  for (std::size_t i = 0; i < outline.size(); ++i) {
    const double e = (outline[i] - p).squaredNorm();
    if (e < best_d2) best_d2 = e, best = i;
  }
  const double step = 4.0 / static_cast<double>(outline.size());
  const double s =
      refine_nearest_on_outline(curve, p, -1.0 + step * static_cast<double>(best), step);
  return std::remainder(s - 1.0, 4.0) + 1.0;  // into [-1, 3)
}

std::vector<Vec2> sample_outline(const Curve& curve, int samples, double* reach) {
  std::vector<Vec2> out(static_cast<std::size_t>(samples));
  *reach = 0;
  for (int i = 0; i < samples; ++i) {
    out[static_cast<std::size_t>(i)] = curve.jet(-1.0 + 4.0 * i / samples, 0).c;
    *reach = std::max(*reach, out[static_cast<std::size_t>(i)].norm());
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// The points hand's data: the closed outline's points with their parameters over [-1, 3).

struct OutlineData {
  std::vector<Vec2> points;         ///< in outline order, the palm's first
  std::vector<std::size_t> origin;  ///< each point's index in the spec (mirrored: the original)
  std::vector<double> s;            ///< parameters, strictly increasing from -1, below 3
  std::size_t back = 0, tip = 0, other_tip = 0;  ///< indices into points
};

std::string index_text(std::size_t i) { return "point " + std::to_string(i); }

/// Chord-length parameters over the whole closed outline from the palm (0), and its length.
double chord_parameters(OutlineData& d) {
  const std::size_t n = d.points.size();
  d.s.assign(n, 0);
  for (std::size_t i = 1; i < n; ++i) d.s[i] = d.s[i - 1] + (d.points[i] - d.points[i - 1]).norm();
  return d.s.back() + (d.points.front() - d.points.back()).norm();
}

double signed_area(const std::vector<Vec2>& p) {
  double a = 0;
  for (std::size_t i = 0; i < p.size(); ++i) a += cross2(p[i], p[(i + 1) % p.size()]);
  return 0.5 * a;
}

/// The largest (sign +1) or smallest (-1) x of the data points strictly between indices lo and hi.
std::size_t extreme_x_point(const std::vector<Vec2>& p, std::size_t lo, std::size_t hi, int sign) {
  std::size_t best = lo + 1;
  for (std::size_t i = lo + 1; i < hi; ++i)
    if (sign * p[i].x() > sign * p[best].x()) best = i;
  return best;
}

/// Open outline: the right half mirrored x -> -x about the axis, its ends put on the axis.
OutlineData open_outline(const PointsHandSpec& spec) {
  const std::vector<Vec2>& p = spec.points;
  const std::size_t m = p.size();
  if (m < 4)
    throw std::invalid_argument(
        "hand.points: an open outline needs at least 4 points (palm, "
        "tip, back and one more), got " +
        std::to_string(m));
  OutlineData d;
  for (std::size_t i = 0; i < m; ++i) {
    d.points.push_back(i == 0 || i + 1 == m ? Vec2(0.0, p[i].y()) : p[i]);
    d.origin.push_back(i);
  }
  for (std::size_t i = m - 2; i >= 1; --i) {
    d.points.emplace_back(-p[i].x(), p[i].y());
    d.origin.push_back(i);
  }
  d.back = m - 1;
  d.tip = extreme_x_point(d.points, 0, d.back, +1);
  d.other_tip = 2 * (m - 1) - d.tip;
  if (!(signed_area(d.points) < 0))
    throw std::invalid_argument(
        "hand.points: an open outline runs clockwise from the palm's middle over the tip to the "
        "back's middle (the palm above the back, the tip at x > 0); these points do not");
  return d;
}

/// Where the closed polygon crosses the axis x = 0: the data point nearer the axis on the crossing
/// edge, for the crossing with the largest y (sign +1) or the smallest (-1).
std::optional<std::size_t> axis_crossing(const std::vector<Vec2>& p, int sign) {
  std::optional<std::size_t> best;
  double best_y = -kInf;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Vec2 &a = p[i], &b = p[(i + 1) % p.size()];
    if ((a.x() > 0) == (b.x() > 0)) continue;
    const double y = a.y() + (b.y() - a.y()) * a.x() / (a.x() - b.x());
    if (sign * y > best_y) {
      best_y = sign * y;
      best = std::abs(a.x()) <= std::abs(b.x()) ? i : (i + 1) % p.size();
    }
  }
  return best;
}

OutlineData closed_outline(const PointsHandSpec& spec) {
  const std::size_t n = spec.points.size();
  if (n < 6)
    throw std::invalid_argument("hand.points: a closed outline needs at least 6 points, got " +
                                std::to_string(n));
  if (spec.palm_point.has_value() != spec.back_point.has_value())
    throw std::invalid_argument("hand.palm_point: give both palm_point and back_point, or neither");
  std::vector<std::size_t> order(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = i;
  if (signed_area(spec.points) > 0) std::reverse(order.begin(), order.end());  // now clockwise
  std::vector<Vec2> clockwise(n);
  for (std::size_t i = 0; i < n; ++i) clockwise[i] = spec.points[order[i]];
  std::size_t palm, back;  // positions in `clockwise`
  if (spec.palm_point) {
    for (const auto& [index, field] :
         {std::pair{*spec.palm_point, "hand.palm_point"}, {*spec.back_point, "hand.back_point"}})
      if (index >= n)
        throw std::invalid_argument(std::string(field) + ": " + std::to_string(index) +
                                    " is not a point's index (0 to " + std::to_string(n - 1) + ")");
    palm = static_cast<std::size_t>(std::find(order.begin(), order.end(), *spec.palm_point) -
                                    order.begin());
    back = static_cast<std::size_t>(std::find(order.begin(), order.end(), *spec.back_point) -
                                    order.begin());
  } else {
    const auto upper = axis_crossing(clockwise, +1), lower = axis_crossing(clockwise, -1);
    if (!upper || !lower || *upper == *lower)
      throw std::invalid_argument(
          "hand.points: a closed outline that does not cross the axis x = 0 twice needs "
          "hand.palm_point and hand.back_point");
    palm = *upper, back = *lower;
  }
  OutlineData d;
  for (std::size_t i = 0; i < n; ++i) {
    d.points.push_back(clockwise[(palm + i) % n]);
    d.origin.push_back(order[(palm + i) % n]);
  }
  d.back = (back + n - palm) % n;
  if (d.back < 2 || d.back + 2 > n)
    throw std::invalid_argument(
        "hand.palm_point: the palm and the back need a point between them on each side, and the "
        "tip (largest x) on the clockwise way from the palm to the back");
  d.tip = extreme_x_point(d.points, 0, d.back, +1);
  d.other_tip = extreme_x_point(d.points, d.back, n, -1);
  return d;
}

// ---------------------------------------------------------------------------------------------

/// The spline of the outline's points at their chord-length parameters d.s, period `length`.
PeriodicSpline fit_outline(const OutlineData& d, double length, double smoothing) {
  Eigen::MatrixXd values(static_cast<Eigen::Index>(d.points.size()), 2);
  for (std::size_t i = 0; i < d.points.size(); ++i)
    values.row(static_cast<Eigen::Index>(i)) = d.points[i].transpose();
  const double spacing = length / static_cast<double>(d.points.size());
  return fit_periodic_spline(d.s, values, length, smoothing * std::pow(spacing, 6), "hand.points");
}

/// The parameter in [lo, hi] where the spline's x is largest (sign +1) or smallest (-1): the
/// best of 8 samples per span, refined by Newton's method on x' = 0.
double extreme_x_parameter(const PeriodicSpline& sp, double lo, double hi, int sign) {
  double best_s = lo, best = -kInf;
  const std::size_t spans = sp.knots.size() - 1;
  for (std::size_t i = 0; i < spans; ++i) {
    if (sp.knots[i + 1] < lo || sp.knots[i] > hi) continue;
    for (int k = 0; k < 8; ++k) {
      const double s = std::clamp(sp.knots[i] + (sp.knots[i + 1] - sp.knots[i]) * k / 8, lo, hi);
      const double x = taylor_jet(&sp.taylor(static_cast<Eigen::Index>(i), 0), s - sp.knots[i])[0];
      if (sign * x > best) best = sign * x, best_s = s;
    }
  }
  for (int it = 0; it < 20; ++it) {
    const auto i = static_cast<std::size_t>(
        std::upper_bound(sp.knots.begin(), sp.knots.end() - 1, best_s) - sp.knots.begin() - 1);
    const auto j = taylor_jet(&sp.taylor(static_cast<Eigen::Index>(i), 0), best_s - sp.knots[i]);
    if (!(sign * j[2] < 0)) break;
    const double next = std::clamp(best_s - j[1] / j[2], lo, hi);
    if (std::abs(next - best_s) < 1e-15) break;
    best_s = next;
  }
  return best_s;
}

/// The chord-length parameters of the palm, the tip (the spline's largest x between palm and
/// back), the back, the other tip (smallest x between back and palm) and the palm again.
std::array<double, 5> anchors(const OutlineData& d, const PeriodicSpline& sp, double length) {
  const double back = d.s[d.back];
  const std::array<double, 5> at = {0.0, extreme_x_parameter(sp, 0.0, back, +1), back,
                                    extreme_x_parameter(sp, back, length, -1), length};
  for (int a = 0; a < 4; ++a)
    if (!(at[a + 1] - at[a] > 1e-6 * length))
      throw std::invalid_argument(
          "hand.points: the outline needs a tip (its largest x) strictly between the palm and the "
          "back, and its smallest x strictly between the back and the palm");
  return at;
}

void check_points_spec(const PointsHandSpec& spec) {
  if (!(spec.smoothing >= 0) || !std::isfinite(spec.smoothing))
    throw std::invalid_argument("hand.smoothing: must be >= 0 and finite, got " +
                                format_significant(spec.smoothing));
  if (spec.points.size() > 100000)
    throw std::invalid_argument("hand.points: more than 100000 points");
  for (std::size_t i = 0; i < spec.points.size(); ++i)
    if (!spec.points[i].allFinite())
      throw std::invalid_argument("hand.points: " + index_text(i) + " is not finite");
  if (!spec.closed && (spec.palm_point || spec.back_point))
    throw std::invalid_argument(
        "hand.palm_point: only a closed outline states its palm and back (an open one runs from "
        "the palm to the back)");
}

void check_distinct_neighbours(const OutlineData& d) {
  for (std::size_t i = 0; i < d.points.size(); ++i) {
    const std::size_t j = (i + 1) % d.points.size();
    if (d.origin[i] != d.origin[j] && d.points[i] == d.points[j])
      throw std::invalid_argument("hand.points: " + index_text(d.origin[i]) + " and " +
                                  index_text(d.origin[j]) + " coincide");
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
PointsHand::PointsHand(std::vector<double> knots, std::vector<std::array<double, 12>> spans,
                       std::array<double, 5> anchors, HandFitReport fit, std::string source,
                       bool closed)
    : knots_(std::move(knots)),
      spans_(std::move(spans)),
      lookup_(span_lookup(knots_)),
      anchors_(anchors),
      fit_(fit),
      source_(std::move(source)),
      closed_(closed) {
  shortest_arc_ = anchors_[1] - anchors_[0];
  for (int a = 1; a < 4; ++a)
    shortest_arc_ = std::min(shortest_arc_, anchors_[a + 1] - anchors_[a]);
  outline_ =
      sample_outline(*this, std::max<int>(1024, 8 * static_cast<int>(spans_.size())), &reach_);
}

PieceInterval PointsHand::piece_interval(int) const { return {-kInf, kInf}; }

CurveJet PointsHand::jet(double s, int) const {
  // s -> the chord-length parameter tau (arc a of the four, x in [0, 1) along it): tau' is
  // shortest + (arc - shortest) * bump(x), whose integral over each arc is that arc's length.
  const double sigma = s + 1.0 - 4.0 * std::floor((s + 1.0) / 4.0);
  const int a = std::min(static_cast<int>(sigma), 3);
  const double x = sigma - a;
  const double arc = anchors_[a + 1] - anchors_[a], extra = arc - shortest_arc_;
  const std::array<double, 4> bump = unit_bump(x);
  const double tau = anchors_[a] + shortest_arc_ * x + extra * bump[0];
  const double t1 = shortest_arc_ + extra * bump[1], t2 = extra * bump[2], t3 = extra * bump[3];
  const int i = find_span(knots_, lookup_, tau);
  const double h = tau - knots_[static_cast<std::size_t>(i)];
  const auto& c = spans_[static_cast<std::size_t>(i)];
  const auto px = taylor_jet(c.data(), h), py = taylor_jet(c.data() + 6, h);
  const Vec2 c1(px[1], py[1]), c2(px[2], py[2]), c3(px[3], py[3]);
  // The chain rule to the third derivative (Faa di Bruno).
  return {Vec2(px[0], py[0]), c1 * t1, c2 * (t1 * t1) + c1 * t2,
          c3 * (t1 * t1 * t1) + c2 * (3 * t1 * t2) + c1 * t3};
}

std::string PointsHand::describe() const {
  return std::string("points hand (") + (closed_ ? "closed" : "open") + " outline of " +
         std::to_string(fit_.points) + " points" + (source_.empty() ? "" : " from " + source_) +
         ", fit rms " + format_significant(fit_.rms, 3) + " m, worst " +
         format_significant(fit_.worst, 3) + " m)";
}

double PointsHand::nearest(const Vec2& p) const { return nearest_on_outline(*this, outline_, p); }

namespace {

std::shared_ptr<const PointsHand> fit_points_hand(const PointsHandSpec& spec) {
  check_points_spec(spec);
  OutlineData d = spec.closed ? closed_outline(spec) : open_outline(spec);
  check_distinct_neighbours(d);
  const double length = chord_parameters(d);
  const PeriodicSpline sp = fit_outline(d, length, spec.smoothing);
  const std::array<double, 5> at = anchors(d, sp, length);
  std::vector<std::array<double, 12>> spans(sp.knots.size() - 1);
  for (std::size_t i = 0; i < spans.size(); ++i)
    for (int k = 0; k < 12; ++k)
      spans[i][static_cast<std::size_t>(k)] = sp.taylor(static_cast<Eigen::Index>(i), k);
  // The fit's distances are measured on the finished curve: one built without the report first.
  const PointsHand unreported(sp.knots, spans, at, HandFitReport{}, spec.source, spec.closed);
  HandFitReport fit;
  fit.points = spec.points.size();
  double sum2 = 0;
  for (std::size_t i = 0; i < spec.points.size(); ++i) {
    const double s = unreported.nearest(spec.points[i]);
    const double e = (unreported.jet(s, 0).c - spec.points[i]).norm();
    sum2 += e * e;
    if (e > fit.worst || i == 0)
      fit.worst = e, fit.worst_index = i, fit.worst_point = spec.points[i], fit.worst_s = s;
  }
  fit.rms = std::sqrt(sum2 / static_cast<double>(spec.points.size()));
  auto hand = std::make_shared<const PointsHand>(sp.knots, std::move(spans), at, fit, spec.source,
                                                 spec.closed);
  validate_hand_outline(*hand);
  return hand;
}

}  // namespace

std::shared_ptr<const PointsHand> make_points_hand(const PointsHandSpec& spec) {
  try {
    return fit_points_hand(spec);
  } catch (const std::invalid_argument& e) {
    // Say which file: "hand.points: ..." and the outline checks' "hand: ..." become
    // "hand.points (file): ...".
    const std::string what = e.what();
    for (const std::string prefix : {"hand.points:", "hand:"})
      if (what.rfind(prefix, 0) == 0)
        throw std::invalid_argument("hand.points" +
                                    (spec.source.empty() ? "" : " (" + spec.source + ")") + ":" +
                                    what.substr(prefix.size()));
    throw;
  }
}

// ---------------------------------------------------------------------------------------------
std::vector<Vec2> read_hand_points_csv(const std::string& path, double scale_to_m) {
  if (!(scale_to_m > 0) || !std::isfinite(scale_to_m))
    throw std::invalid_argument("hand.units: the scale to metres must be positive and finite");
  constexpr std::uintmax_t kMaxBytes = 16u << 20;
  constexpr std::size_t kMaxRows = 100000;
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec) throw std::invalid_argument(path + ": cannot be read (" + ec.message() + ")");
  if (size > kMaxBytes)
    throw std::invalid_argument(path + ": larger than 16 MiB (" + std::to_string(size) +
                                " bytes); a hand outline needs far fewer points");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::invalid_argument(path + ": cannot be opened");
  std::vector<Vec2> points;
  std::string line;
  bool header_allowed = true;
  for (long number = 1; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const auto first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    std::vector<std::string> fields;
    for (std::size_t start = 0;;) {
      const std::size_t comma = line.find(',', start);
      std::string f =
          line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
      const auto b = f.find_first_not_of(" \t"), e = f.find_last_not_of(" \t");
      fields.push_back(b == std::string::npos ? "" : f.substr(b, e - b + 1));
      if (comma == std::string::npos) break;
      start = comma + 1;
    }
    const std::string where = path + ":" + std::to_string(number) + ": ";
    double v[2];
    bool numeric[2] = {false, false};
    for (std::size_t k = 0; k < std::min<std::size_t>(fields.size(), 2); ++k) {
      const std::string& f = fields[k];
      const auto [end, err] = std::from_chars(f.data(), f.data() + f.size(), v[k]);
      numeric[k] = err == std::errc() && end == f.data() + f.size() && !f.empty();
    }
    if (header_allowed && fields.size() == 2 && !numeric[0] && !numeric[1]) {
      header_allowed = false;  // a row of column names
      continue;
    }
    header_allowed = false;
    if (fields.size() != 2)
      throw std::invalid_argument(where + "expected 2 columns (x, y), got " +
                                  std::to_string(fields.size()));
    for (int k = 0; k < 2; ++k) {
      const char* name = k == 0 ? "x" : "y";
      if (!numeric[k])
        throw std::invalid_argument(where + name + " '" + fields[static_cast<std::size_t>(k)] +
                                    "' is not a number");
      if (!std::isfinite(v[k] * scale_to_m))
        throw std::invalid_argument(where + name + " is not finite");
    }
    if (points.size() == kMaxRows)
      throw std::invalid_argument(where + "more than " + std::to_string(kMaxRows) + " data rows");
    points.emplace_back(v[0] * scale_to_m, v[1] * scale_to_m);
  }
  if (points.empty()) throw std::invalid_argument(path + ": no data rows (x, y)");
  return points;
}

// ---------------------------------------------------------------------------------------------
namespace {

void check_polar_spec(const PolarHandSpec& spec) {
  if (!std::isfinite(spec.palm_phi))
    throw std::invalid_argument("hand.palm_phi_deg: must be finite");
  if (spec.form == PolarHandSpec::Form::kFourier) {
    if (spec.cos_terms.empty())
      throw std::invalid_argument("hand.cos: needs at least a0, the mean radius");
    for (const auto& [terms, field] :
         {std::pair{&spec.cos_terms, "hand.cos"}, {&spec.sin_terms, "hand.sin"}}) {
      if (terms->size() > 64)
        throw std::invalid_argument(std::string(field) + ": at most 64 terms");
      for (double v : *terms)
        if (!std::isfinite(v)) throw std::invalid_argument(std::string(field) + ": must be finite");
    }
    return;
  }
  if (spec.phi.size() != spec.r.size())
    throw std::invalid_argument("hand.r: needs one radius per angle of hand.phi_deg (" +
                                std::to_string(spec.phi.size()) + " angles, " +
                                std::to_string(spec.r.size()) + " radii)");
  if (spec.phi.size() < 6 || spec.phi.size() > 100000)
    throw std::invalid_argument("hand.phi_deg: a table needs 6 to 100000 rows, got " +
                                std::to_string(spec.phi.size()));
  for (std::size_t i = 0; i < spec.phi.size(); ++i) {
    if (!std::isfinite(spec.phi[i]) || !std::isfinite(spec.r[i]))
      throw std::invalid_argument("hand.phi_deg: row " + std::to_string(i) + " is not finite");
    if (!(spec.r[i] > 0))
      throw std::invalid_argument("hand.r: row " + std::to_string(i) + " must be positive, got " +
                                  format_significant(spec.r[i]));
    if (i > 0 && !(spec.phi[i] > spec.phi[i - 1]))
      throw std::invalid_argument("hand.phi_deg: must increase strictly (row " + std::to_string(i) +
                                  ")");
  }
  if (!(spec.phi.back() - spec.phi.front() < 2 * kPi))
    throw std::invalid_argument("hand.phi_deg: the table must span less than a full turn");
}

}  // namespace

PolarHand::PolarHand(const PolarHandSpec& spec) : spec_(spec) {
  check_polar_spec(spec_);
  if (spec_.form == PolarHandSpec::Form::kTable) {
    const Eigen::Map<const Eigen::VectorXd> radii(spec_.r.data(),
                                                  static_cast<Eigen::Index>(spec_.r.size()));
    const PeriodicSpline sp =
        fit_periodic_spline(spec_.phi, Eigen::MatrixXd(radii), 2 * kPi, 0.0, "hand.r");
    knots_ = sp.knots;
    spans_.resize(knots_.size() - 1);
    for (std::size_t i = 0; i < spans_.size(); ++i)
      for (int k = 0; k < 6; ++k)
        spans_[i][static_cast<std::size_t>(k)] = sp.taylor(static_cast<Eigen::Index>(i), k);
    lookup_ = span_lookup(knots_);
  }
  // The radius must stay positive between the given values too (a star-shaped outline, which
  // then cannot cross itself): checked on a sampling finer than any of its features.
  const int samples = std::max<int>(4096, 16 * static_cast<int>(spans_.size()));
  for (int i = 0; i < samples; ++i) {
    const double phi = 2 * kPi * i / samples;
    const double r = radius_jet(phi)[0];
    if (!(r > 0))
      throw std::invalid_argument(
          std::string(spec_.form == PolarHandSpec::Form::kTable ? "hand.r" : "hand.cos") +
          ": the radius must be positive at every angle; it is " + format_significant(r) +
          " m at phi = " + format_significant(phi * 180 / kPi) + " deg");
  }
  outline_ = sample_outline(*this, 2048, &reach_);
}

std::array<double, 4> PolarHand::radius_jet(double phi) const {
  if (spec_.form == PolarHandSpec::Form::kTable) {
    const double lo = knots_.front();
    const double u = phi - 2 * kPi * std::floor((phi - lo) / (2 * kPi));
    const int i = find_span(knots_, lookup_, u);
    return taylor_jet(spans_[static_cast<std::size_t>(i)].data(),
                      u - knots_[static_cast<std::size_t>(i)]);
  }
  std::array<double, 4> r{spec_.cos_terms[0], 0, 0, 0};
  const std::size_t terms = std::max(spec_.cos_terms.size(), spec_.sin_terms.size() + 1);
  for (std::size_t k = 1; k < terms; ++k) {
    const double a = k < spec_.cos_terms.size() ? spec_.cos_terms[k] : 0.0;
    const double b = k - 1 < spec_.sin_terms.size() ? spec_.sin_terms[k - 1] : 0.0;
    const double kk = static_cast<double>(k), c = std::cos(kk * phi), s = std::sin(kk * phi);
    // d/dphi (a cos + b sin) = k (b cos - a sin), and so on.
    const double even = a * c + b * s, odd = b * c - a * s;
    r[0] += even;
    r[1] += kk * odd;
    r[2] -= kk * kk * even;
    r[3] -= kk * kk * kk * odd;
  }
  return r;
}

PieceInterval PolarHand::piece_interval(int) const { return {-kInf, kInf}; }

CurveJet PolarHand::jet(double s, int) const {
  // phi = palm_phi - (pi/2)(s + 1); P(phi) = r e with e = (cos phi, sin phi), e' = perp(e):
  //   P'   = r' e + r e_perp
  //   P''  = (r'' - r) e + 2 r' e_perp
  //   P''' = (r''' - 3 r') e + (3 r'' - r) e_perp
  // and d^k/ds^k = q^k d^k/dphi^k with q = -pi/2; the frame is then turned by pi/2 - palm_phi.
  const double q = -0.5 * kPi;
  const double phi = spec_.palm_phi + q * (s + 1.0);
  const auto r = radius_jet(phi);
  // e and e_perp turned by pi/2 - palm_phi: the angle phi + pi/2 - palm_phi.
  const double turned = phi + 0.5 * kPi - spec_.palm_phi;
  const Vec2 e(std::cos(turned), std::sin(turned)), ep = perp(e);
  return {r[0] * e, q * (r[1] * e + r[0] * ep), q * q * ((r[2] - r[0]) * e + 2 * r[1] * ep),
          q * q * q * ((r[3] - 3 * r[1]) * e + (3 * r[2] - r[0]) * ep)};
}

std::string PolarHand::describe() const {
  if (spec_.form == PolarHandSpec::Form::kTable)
    return "polar hand (table of " + std::to_string(spec_.phi.size()) + " radii)";
  return "polar hand (Fourier series of " +
         std::to_string(std::max(spec_.cos_terms.size(), spec_.sin_terms.size() + 1)) +
         " terms, mean radius " + format_significant(spec_.cos_terms[0]) + " m)";
}

double PolarHand::nearest(const Vec2& p) const { return nearest_on_outline(*this, outline_, p); }

std::shared_ptr<const PolarHand> make_polar_hand(const PolarHandSpec& spec) {
  auto hand = std::make_shared<const PolarHand>(spec);
  validate_hand_outline(*hand);
  return hand;
}

}  // namespace flatland::sim
