// Planar curves: hand outlines and object boundaries.
//
// A curve is a chain of smooth pieces. Each piece is evaluated by its own analytic formula, which
// is also valid a little beyond the piece's ends: the integrator keeps one piece active for a whole
// segment and only switches at a located breakpoint ("stop and restart there"), so no integration
// step ever straddles the jump in curvature derivative at a junction.
#pragma once

#include <Eigen/Core>

#include <algorithm>

#include <memory>
#include <string>
#include <vector>

namespace flatland::sim {

using Vec2 = Eigen::Vector2d;

/// Rotate a planar vector by +90 degrees (z-hat cross v).
inline Vec2 perp(const Vec2& v) { return {-v.y(), v.x()}; }
/// Planar cross product (z component of a x b).
inline double cross2(const Vec2& a, const Vec2& b) { return a.x() * b.y() - a.y() * b.x(); }

/// Position and its first three parameter derivatives on one smooth piece. The scalar is a
/// template parameter so that sensitivities can carry derivatives through it (CurveJet: double).
template <class T>
struct BasicCurveJet {
  Eigen::Matrix<T, 2, 1> c, d1, d2, d3;
};
using CurveJet = BasicCurveJet<double>;

/// Differential geometry at one parameter value (everything derived from a CurveJet).
template <class T>
struct BasicCurveGeometry {
  using V = Eigen::Matrix<T, 2, 1>;
  V point;         ///< c(s), m
  V jacobian;      ///< J = dc/ds
  V jacobian_ds;   ///< dJ/ds
  T speed;         ///< |J|
  T speed_ds;      ///< d|J|/ds
  V tangent;       ///< unit J
  V normal;        ///< unit outward normal
  T curvature;     ///< 1/m; > 0 where the body is convex, < 0 where concave
  T curvature_ds;  ///< d(curvature)/ds
  V normal_ds;     ///< K = dn/ds = curvature * speed * tangent (the paper's K)
  V normal_dss;    ///< dK/ds
};
using CurveGeometry = BasicCurveGeometry<double>;

/// Closed interval of the parameter covered by one smooth piece.
struct PieceInterval {
  double lo, hi;
};

class Curve {
 public:
  virtual ~Curve() = default;

  /// Index of the smooth piece containing s. On a breakpoint, `direction` (+1 / -1) picks the
  /// piece the parameter is moving into.
  virtual int piece_at(double s, int direction) const = 0;
  /// Parameter interval of a piece (may be infinite for a single-piece curve).
  virtual PieceInterval piece_interval(int piece) const = 0;
  /// Derivatives of piece `piece` at s, by that piece's formula even slightly outside its interval.
  virtual CurveJet jet(double s, int piece) const = 0;
  /// +1 if the outward normal is the tangent turned by +90 degrees (the body lies to the right
  /// of the direction of travel, i.e. it is traversed clockwise), -1 if turned by -90 degrees.
  virtual int normal_side() const = 0;
  /// Short human-readable description, for errors and reports.
  virtual std::string describe() const = 0;
  /// The parameter of the point of the whole curve (every piece of a closed outline) nearest to
  /// `p`, in the curve's frame: the global minimum of the distance, refined by Newton's method.
  virtual double nearest(const Vec2& p) const = 0;
  /// The largest distance of a point of the curve from the frame's origin (infinite for an
  /// unbounded curve): nothing farther from the origin can touch it.
  virtual double reach() const = 0;

  CurveGeometry geometry(double s, int piece) const;
  CurveGeometry geometry(double s) const { return geometry(s, piece_at(s, +1)); }
};

using CurvePtr = std::shared_ptr<const Curve>;

/// Compute geometry from a jet. `normal_side` as in Curve::normal_side().
CurveGeometry geometry_from_jet(const CurveJet& jet, int normal_side);

/// A hand's outline. Every hand follows the paper's parameter convention where it applies: a
/// closed outline is periodic in s with period() (4 for the butterfly hands: s = -1 the middle of
/// the palm, 0 the tip, +1 the middle of the back, 2 the mirrored tip), traversed clockwise. A hand
/// with has_palm_and_back() has wells at s = -1 and s = +1: the butterfly's start and goal, which
/// the searches (solve, locus, surface, time-optimal) and the closed loop's plan need; the others
/// (a line, a circular well) are simulated, drawn and tracked, and refused by those with one line.
class HandCurve : public Curve {
 public:
  /// The parameter's period over the closed outline; +infinity for an open curve (a line).
  virtual double period() const = 0;
  /// Whether s = -1 and s = +1 are the palm's and the back's wells (the butterfly convention).
  virtual bool has_palm_and_back() const = 0;
};

using HandPtr = std::shared_ptr<const HandCurve>;

/// The paper's hand (section 4.1). Right half, s in [-1, 1]:
///   x(s) = a + c s^2 + e s^4,  y(s) = b s + d s^3 + f s^5,
/// with e = -(a + c), f = -(b + 3 d)/5 so that x(+-1) = 0 and y'(+-1) = 0. The left half is its
/// mirror image x -> -x. The closed outline is parameterised continuously by a global s:
///   piece m covers [2m - 1, 2m + 1]; even m is the right half with local u = s - 2m,
///   odd m the mirrored half with local u = 2m - s.
/// So s = -1 is the middle of the palm, 0 the tip, +1 the middle of the back, 2 the mirrored tip,
/// and s is periodic with period 4. Traversed clockwise: outward normal = tangent turned +90 deg.
class PolynomialHand final : public HandCurve {
 public:
  /// Coefficients in metres.
  PolynomialHand(double a, double b, double c, double d);

  double a() const { return a_; }
  double b() const { return b_; }
  double c() const { return c_; }
  double d() const { return d_; }
  double e() const { return e_; }
  double f() const { return f_; }

  int piece_at(double s, int direction) const override;
  PieceInterval piece_interval(int piece) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return +1; }
  std::string describe() const override;
  /// In [-1, 3): the closed outline's period.
  double nearest(const Vec2& p) const override;
  double reach() const override { return reach_; }
  double period() const override { return 4.0; }
  bool has_palm_and_back() const override { return true; }

 private:
  double a_, b_, c_, d_, e_, f_;
  /// The closed outline sampled evenly in s over [-1, 3) (the start of the nearest-point search).
  std::vector<Vec2> outline_;
  double reach_ = 0;
  double coarse_spacing_ = 0;
};

/// A straight line through `origin` along unit `direction`, s in metres. Outward normal is the
/// direction turned +90 degrees (for direction +x the free side is +y). As a hand (`hand.shape:
/// line`, an incline) it is open: no period, no palm and back wells.
class LineCurve final : public HandCurve {
 public:
  LineCurve(Vec2 origin, Vec2 direction);
  int piece_at(double, int) const override { return 0; }
  PieceInterval piece_interval(int) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return +1; }
  std::string describe() const override;
  double nearest(const Vec2& p) const override { return (p - origin_).dot(direction_); }
  double reach() const override;
  double period() const override;
  bool has_palm_and_back() const override { return false; }
  const Vec2& origin() const { return origin_; }
  const Vec2& direction() const { return direction_; }

 private:
  Vec2 origin_, direction_;
};

/// A circle of radius R about `center`, s the angle in radians.
/// kConvexBody: the body is the inside of the circle (a disk or a cylinder), c(s) = center +
///   R (cos s, sin s), traversed counter-clockwise, outward normal points away from the centre.
/// kConcaveWell: the body is outside the circle (a circular well holding an object inside),
///   c(s) = center + R (sin s, -cos s) (s = 0 at the bottom), outward normal points to the centre.
class CircleCurve final : public Curve {
 public:
  enum class Side { kConvexBody, kConcaveWell };
  CircleCurve(Vec2 center, double radius, Side side);
  double radius() const { return radius_; }
  Side side() const { return side_; }
  int piece_at(double, int) const override { return 0; }
  PieceInterval piece_interval(int) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return side_ == Side::kConvexBody ? -1 : +1; }
  std::string describe() const override;
  double nearest(const Vec2& p) const override;
  double reach() const override { return center_.norm() + radius_; }

 private:
  Vec2 center_;
  double radius_;
  Side side_;
};

/// A circular well as a hand (`hand.shape: circle`): the body is outside the circle of radius R
/// about `center` and the object rolls inside it, c(s) = center + R (sin s, -cos s), s the angle in
/// radians from the bottom (CircleCurve's kConcaveWell, whose formulas it uses). Closed with period
/// 2 pi, but with no palm and back wells in the butterfly's sense.
class CircleWellHand final : public HandCurve {
 public:
  CircleWellHand(Vec2 center, double radius);
  double radius() const { return well_.radius(); }
  const Vec2& center() const { return center_; }
  int piece_at(double s, int direction) const override { return well_.piece_at(s, direction); }
  PieceInterval piece_interval(int piece) const override { return well_.piece_interval(piece); }
  CurveJet jet(double s, int piece) const override { return well_.jet(s, piece); }
  int normal_side() const override { return well_.normal_side(); }
  std::string describe() const override { return well_.describe(); }
  double nearest(const Vec2& p) const override { return well_.nearest(p); }
  double reach() const override { return well_.reach(); }
  double period() const override;
  bool has_palm_and_back() const override { return false; }

 private:
  Vec2 center_;
  CircleCurve well_;
};

/// Ellipse with semi-axes (ax, ay) about the origin, c(s) = (ax cos s, ay sin s), convex body,
/// traversed counter-clockwise.
class EllipseCurve final : public Curve {
 public:
  EllipseCurve(double ax, double ay);
  double ax() const { return ax_; }
  double ay() const { return ay_; }
  int piece_at(double, int) const override { return 0; }
  PieceInterval piece_interval(int) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return -1; }
  std::string describe() const override;
  double nearest(const Vec2& p) const override;
  double reach() const override { return std::max(ax_, ay_); }

 private:
  double ax_, ay_;
};

/// Check that a closed hand outline can carry a disk of radius `disk_radius` (paper section 4.1):
/// the outline does not self-intersect, the palm (s = -1) and back (s = +1) are wells (concave),
/// and every concave part has curvature radius larger than the disk radius (r * |kappa| < 1).
/// Throws std::invalid_argument naming the failing condition and where (s and the point, in m).
/// The polynomial hand is checked on its right half (the left is its mirror) and its tip `hand.a`
/// too; any other hand on its whole closed outline (a finite period()), the wells only where it
/// has_palm_and_back().
void validate_hand_for_disk(const HandCurve& hand, double disk_radius);
/// The checks of a closed outline that need no object: no cusp (zero parametric speed) and no
/// self-intersection, on the whole period. Throws std::invalid_argument "hand: ..." as above.
void validate_hand_outline(const HandCurve& hand);

}  // namespace flatland::sim
