// Hands beyond the paper's polynomial (issue 26): an outline fitted to measured points, and a
// frame described in polar form r(phi). Both are sim::HandCurve with the paper's parameter
// convention (curve.hpp): s = -1 the middle of the palm well, 0 the tip, +1 the middle of the back
// well, period 4, traversed clockwise (outward normal = tangent turned +90 deg), hand frame with
// the pivot at the origin.
//
// Scene keys (proposed for scene/; lengths in metres unless a key says otherwise):
//   hand:
//     shape: points
//     file: hand.csv          # CSV of x, y (relative to the scene file); read_hand_points_csv
//     units: m                # m | mm | cm: the file's unit (scale_to_m = 1, 1e-3, 1e-2)
//     closed: false           # false: the right half, palm -> tip -> back, mirrored x -> -x;
//                             # true: the whole loop
//     smoothing: 0            # >= 0, dimensionless (PointsHandSpec::smoothing); 0 interpolates
//     palm_point: 0           # closed only, optional: 0-based index of the palm's point (the
//     back_point: 57          #   point of the file's data rows); both or neither; absent: found
//   hand:
//     shape: polar
//     palm_phi_deg: 90        # the frame's own polar angle of the palm well's middle
//     phi_deg: [0, 30, ...]   # a table: strictly increasing over less than a turn,
//     r: [0.12, 0.1, ...]     #   the radii at those angles (periodic spline through them)
//     # or a Fourier series r = a0 + sum a_k cos k phi + b_k sin k phi:
//     cos: [a0, a1, a2, ...]  # m
//     sin: [b1, b2, ...]      # m (may be empty or absent)
// Bad values throw std::invalid_argument with one line naming the field (as the keys above spell
// it, prefixed "hand."), or "file:line: reason" for the CSV.
#pragma once

#include "flatland/sim/curve.hpp"

#include <array>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace flatland::sim {

/// How far a fitted outline lies from the points it was fitted to.
struct HandFitReport {
  std::size_t points = 0;           ///< data points fitted
  double rms = 0;                   ///< m, root mean square of each point's distance to the curve
  double worst = 0;                 ///< m, the largest distance
  std::size_t worst_index = 0;      ///< 0-based index of that point in PointsHandSpec::points
  Vec2 worst_point = Vec2::Zero();  ///< that point, m
  double worst_s = 0;               ///< the curve's parameter nearest to it
};

/// A measured outline. Open (closed = false): the right half of the hand from the palm well's
/// middle (first point, s = -1) over the tip to the back well's middle (last point, s = +1), in
/// order; the left half is its mirror image x -> -x, so the first and last points belong on the
/// axis x = 0 (their x is taken as 0 for the fit, and their own distance is in the fit report).
/// Closed: the whole loop in order (either orientation; no repeated first point), the palm and back
/// points given by index or found as the points nearest to where the outline crosses x = 0 (the
/// palm the upper crossing, the back the lower, as the paper's hand has them).
struct PointsHandSpec {
  std::vector<Vec2> points;  ///< m, hand frame
  bool closed = false;
  /// The smoothing spline's weight, >= 0 and finite; 0 interpolates the points. The curve
  /// minimises mean |c(t_i) - p_i|^2 + smoothing * h^6 * mean |c'''(t)|^2 over its parameter t
  /// with h the mean spacing of the points' parameters: about 1 smooths over one point spacing,
  /// 1e6 over ten.
  double smoothing = 0;
  std::optional<std::size_t> palm_point, back_point;  ///< closed only, both or neither
  /// Where the points came from ("hand.csv"), for messages and the report.
  std::string source;
};

/// The points hand: a periodic quintic smoothing spline through the outline (continuous up to the
/// fourth derivative, so curvature and its derivative are continuous everywhere).
class PointsHand;

/// Fit and check a points hand: throws std::invalid_argument naming the field ("hand.points",
/// "hand.smoothing", "hand.palm_point") or the source, for too few points, non-finite
/// coordinates, repeated points, a self-intersecting or cusped outline.
std::shared_ptr<const PointsHand> make_points_hand(const PointsHandSpec& spec);

/// The points of a CSV file: two numeric columns x, y per row (more columns are refused), an
/// optional first row of column names, '#' comment lines and blank lines skipped. Each value is
/// multiplied by `scale_to_m`. Bounded: files over 16 MiB or with more than 100000 data rows are
/// refused. Throws std::invalid_argument "path:line: reason" (a non-numeric or non-finite value,
/// a wrong number of columns), or "path: reason" (cannot be read, too large, no data rows).
std::vector<Vec2> read_hand_points_csv(const std::string& path, double scale_to_m = 1.0);

/// A frame r(phi) in its own polar angle phi (rad), placed in the hand frame so that the palm
/// well's middle (phi = palm_phi) is on the +y axis: the hand frame is the polar frame rotated by
/// pi/2 - palm_phi. The parameter is linear in phi, phi = palm_phi - (pi/2) (s + 1), so the tip
/// (s = 0) is at palm_phi - pi/2, on the +x axis, and the back (s = +1) at palm_phi - pi, on -y.
/// The butterfly frame r = a - b cos 2 phi has its dips at phi = 0 and pi: palm_phi = 0 (or pi)
/// puts one dip at the top as the palm and the other at the bottom as the back.
struct PolarHandSpec {
  enum class Form { kTable, kFourier };
  Form form = Form::kFourier;
  /// kTable: angles (rad, strictly increasing, spanning less than 2 pi) and radii (m, > 0); a
  /// periodic quintic spline interpolates r(phi) through them (at least 6 rows).
  std::vector<double> phi, r;
  /// kFourier: r = cos_terms[0] + sum_k cos_terms[k] cos k phi + sin_terms[k-1] sin k phi, m.
  std::vector<double> cos_terms, sin_terms;
  double palm_phi = 1.5707963267948966;  ///< rad
};

class PolarHand;

/// Build and check a polar hand: throws std::invalid_argument naming the field ("hand.r",
/// "hand.phi_deg", "hand.cos", "hand.sin", "hand.palm_phi_deg") for a radius that is not positive
/// everywhere, too few or unordered table rows, non-finite values, a cusped outline.
std::shared_ptr<const PolarHand> make_polar_hand(const PolarHandSpec& spec);

class PointsHand final : public HandCurve {
 public:
  /// Use make_points_hand.
  PointsHand(std::vector<double> knots, std::vector<std::array<double, 12>> spans,
             std::array<double, 5> anchors, HandFitReport fit, std::string source, bool closed);

  const HandFitReport& fit() const { return fit_; }
  bool closed() const { return closed_; }

  /// One piece over every s: the spline is C4, so the jet (to the 3rd derivative) is continuous
  /// and the integrator needs no breakpoint.
  int piece_at(double, int) const override { return 0; }
  PieceInterval piece_interval(int) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return +1; }
  std::string describe() const override;
  /// In [-1, 3).
  double nearest(const Vec2& p) const override;
  double reach() const override { return reach_; }
  double period() const override { return 4.0; }
  bool has_palm_and_back() const override { return true; }

 private:
  std::vector<double> knots_;  ///< span starts (chord length from the palm), then the period
  std::vector<std::array<double, 12>> spans_;  ///< per span: x, y Taylor coefficients 0..5
  std::vector<int> lookup_;                    ///< first span of each of the equal cells
  /// The chord-length parameters of palm, tip, back, other tip, palm + period: s = -1 .. 3.
  std::array<double, 5> anchors_;
  double shortest_arc_;  ///< the shortest of the four arcs between them
  HandFitReport fit_;
  std::string source_;
  bool closed_;
  std::vector<Vec2> outline_;  ///< samples for nearest()
  double reach_ = 0;
};

class PolarHand final : public HandCurve {
 public:
  /// Use make_polar_hand.
  explicit PolarHand(const PolarHandSpec& spec);

  const PolarHandSpec& spec() const { return spec_; }
  /// r and its first three derivatives in phi at phi.
  std::array<double, 4> radius_jet(double phi) const;

  int piece_at(double, int) const override { return 0; }
  PieceInterval piece_interval(int) const override;
  CurveJet jet(double s, int piece) const override;
  int normal_side() const override { return +1; }
  std::string describe() const override;
  /// In [-1, 3).
  double nearest(const Vec2& p) const override;
  double reach() const override { return reach_; }
  double period() const override { return 4.0; }
  bool has_palm_and_back() const override { return true; }

 private:
  PolarHandSpec spec_;
  std::vector<double> knots_;                 ///< kTable: span starts over [0, 2 pi), then 2 pi
  std::vector<std::array<double, 6>> spans_;  ///< kTable: r's Taylor coefficients per span
  std::vector<int> lookup_;                   ///< kTable: first span of each of the equal cells
  std::vector<Vec2> outline_;
  double reach_ = 0;
};

}  // namespace flatland::sim
