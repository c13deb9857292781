// Hand and object geometry: derivatives against finite differences, the paper's shape,
// junction continuity, and shape validation.
#include "flatland/sim/curve.hpp"
#include "flatland/sim/motion.hpp"
#include "flatland/sim/object.hpp"
#include "sim/rolling_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <vector>

using namespace flatland::sim;

namespace {

// Central differences of the geometry along one piece.
void expect_consistent_derivatives(const Curve& curve, double s, int piece) {
  const double h = 1e-5;
  const CurveGeometry g = curve.geometry(s, piece);
  const CurveGeometry gp = curve.geometry(s + h, piece), gm = curve.geometry(s - h, piece);
  EXPECT_NEAR(g.tangent.norm(), 1.0, 1e-14);
  EXPECT_NEAR(g.normal.norm(), 1.0, 1e-14);
  EXPECT_NEAR(g.tangent.dot(g.normal), 0.0, 1e-14);
  const Vec2 dc = (gp.point - gm.point) / (2 * h);
  EXPECT_NEAR((dc - g.jacobian).norm(), 0.0, 1e-8 * (1 + g.speed));
  const Vec2 dn = (gp.normal - gm.normal) / (2 * h);
  EXPECT_NEAR((dn - g.normal_ds).norm(), 0.0, 1e-6 * (1 + g.normal_ds.norm()));
  const Vec2 dK = (gp.normal_ds - gm.normal_ds) / (2 * h);
  EXPECT_NEAR((dK - g.normal_dss).norm(), 0.0, 1e-5 * (1 + g.normal_dss.norm()));
  EXPECT_NEAR((gp.curvature - gm.curvature) / (2 * h), g.curvature_ds,
              1e-5 * (1 + std::abs(g.curvature_ds)));
  EXPECT_NEAR((gp.speed - gm.speed) / (2 * h), g.speed_ds, 1e-6 * (1 + std::abs(g.speed_ds)));
}

}  // namespace

TEST(Geometry, PaperHandKeyPoints) {
  const PolynomialHand hand = paper_hand();
  // Paper section 4.1: e = 7.2 cm, f = -9.36 cm.
  EXPECT_NEAR(hand.e(), 0.072, 1e-12);
  EXPECT_NEAR(hand.f(), -0.0936, 1e-12);
  // Palm middle (0, +5.76 cm) with outward normal +y; tip (18, 0) with normal +x; back (0, -5.76).
  const CurveGeometry palm = hand.geometry(-1.0, 0);
  EXPECT_NEAR((palm.point - Vec2(0, 0.0576)).norm(), 0, 1e-12);
  EXPECT_NEAR((palm.normal - Vec2(0, 1)).norm(), 0, 1e-12);
  const CurveGeometry tip = hand.geometry(0.0, 0);
  EXPECT_NEAR((tip.point - Vec2(0.18, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((tip.normal - Vec2(1, 0)).norm(), 0, 1e-12);
  EXPECT_GT(tip.curvature, 0);  // convex tip
  const CurveGeometry back = hand.geometry(1.0, 0);
  EXPECT_NEAR((back.point - Vec2(0, -0.0576)).norm(), 0, 1e-12);
  EXPECT_NEAR((back.normal - Vec2(0, -1)).norm(), 0, 1e-12);
  // Wells: concave at the palm and back (x'(1) = -21.6 cm, y''(1) = -57.6 cm).
  const double kappa_expected = -(0.216 * 0.576) / std::pow(0.216, 3);
  EXPECT_NEAR(palm.curvature, kappa_expected, 1e-9);
  EXPECT_NEAR(back.curvature, kappa_expected, 1e-9);
  // The mirrored tip at s = 2.
  EXPECT_NEAR((hand.geometry(2.0, 1).point - Vec2(-0.18, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((hand.geometry(2.0, 1).normal - Vec2(-1, 0)).norm(), 0, 1e-12);
}

TEST(Geometry, JunctionsContinuousUpToCurvature) {
  const PolynomialHand hand = paper_hand();
  for (double s : {-1.0, 1.0}) {
    const int below = hand.piece_at(s, -1), above = hand.piece_at(s, +1);
    ASSERT_EQ(above, below + 1);
    const CurveGeometry a = hand.geometry(s, below), b = hand.geometry(s, above);
    EXPECT_NEAR((a.point - b.point).norm(), 0, 1e-15);
    EXPECT_NEAR((a.jacobian - b.jacobian).norm(), 0, 1e-15);
    EXPECT_NEAR((a.normal - b.normal).norm(), 0, 1e-15);
    EXPECT_NEAR(a.curvature, b.curvature, 1e-12);
    // ... but the curvature derivative and d|J|/ds jump (paper section 4.1).
    EXPECT_GT(std::abs(a.speed_ds - b.speed_ds), 1e-3);
  }
  // Periodic with period 4.
  EXPECT_NEAR((hand.geometry(-1.5, -1).point - hand.geometry(2.5, 1).point).norm(), 0, 1e-15);
}

TEST(Geometry, DerivativesMatchFiniteDifferences) {
  const PolynomialHand hand = paper_hand();
  for (double s : {-0.9, -0.5, 0.0, 0.3, 0.95}) expect_consistent_derivatives(hand, s, 0);
  for (double s : {1.2, 2.0, 2.7}) expect_consistent_derivatives(hand, s, 1);
  for (double s : {-2.5, -1.1}) expect_consistent_derivatives(hand, s, -1);
  const CircleCurve disk(Vec2::Zero(), 0.05, CircleCurve::Side::kConvexBody);
  const CircleCurve well(Vec2(0, 0.2), 0.2, CircleCurve::Side::kConcaveWell);
  const EllipseCurve ellipse(0.06, 0.03);
  for (double s : {-2.0, 0.1, 1.3}) {
    expect_consistent_derivatives(disk, s, 0);
    expect_consistent_derivatives(well, s, 0);
    expect_consistent_derivatives(ellipse, s, 0);
  }
  EXPECT_NEAR(disk.geometry(0.7).curvature, 1 / 0.05, 1e-9);
  EXPECT_NEAR(well.geometry(0.7).curvature, -1 / 0.2, 1e-9);
  EXPECT_NEAR((well.geometry(0.0).normal - Vec2(0, 1)).norm(), 0, 1e-15);  // points to the centre
  // Ellipse curvature at the end of its major axis: a / b^2.
  EXPECT_NEAR(ellipse.geometry(0.0).curvature, 0.06 / (0.03 * 0.03), 1e-9);
}

TEST(Geometry, PaperHandIsValidForItsDisk) {
  EXPECT_NO_THROW(validate_hand_for_disk(paper_hand(), 0.051));
}

TEST(Geometry, ValidationNamesTheFailingCondition) {
  auto message = [](const PolynomialHand& h, double r) {
    try {
      validate_hand_for_disk(h, r);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  // Curvature radius of the paper's wells is 8.1 cm: a 9 cm disk does not fit.
  EXPECT_NE(message(paper_hand(), 0.09).find("too tight"), std::string::npos);
  EXPECT_NE(message(paper_hand(), 0.09).find("s_h="), std::string::npos);
  // d = 0.08: the palm bulges out (convex) -> no well.
  EXPECT_NE(message(PolynomialHand(0.18, -0.18, -0.252, 0.08), 0.051).find("no well"),
            std::string::npos);
  // A strongly negative c folds the outline over the mirror axis.
  EXPECT_NE(message(PolynomialHand(0.18, -0.18, -0.9, 0.216), 0.051).find("self-intersect"),
            std::string::npos);
  EXPECT_NE(message(paper_hand(), -0.05).find("radius"), std::string::npos);
}

// The self-intersection check tests only segment pairs whose x ranges overlap; it must report
// what a test of every pair of the same polyline reports (the first pair in outline order).
TEST(Geometry, SelfIntersectionSweepFindsWhatEveryPairFinds) {
  constexpr int kSamples = 2000, kStride = 4;  // validate_hand_for_disk's polyline
  auto crosses = [](const Vec2& p1, const Vec2& p2, const Vec2& q1, const Vec2& q2) {
    auto side = [](const Vec2& o, const Vec2& a, const Vec2& b) {
      return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
    };
    return ((side(q1, q2, p1) > 0) != (side(q1, q2, p2) > 0)) &&
           ((side(p1, p2, q1) > 0) != (side(p1, p2, q2) > 0));
  };
  int folded = 0, checked = 0;
  // Tips reaching back over the palm: b and d of either sign and size fold the right half.
  for (double b : {-0.18, -0.05, 0.05, 0.18})
    for (double c : {-0.25, -0.1, 0.1})
      for (double d = -0.6; d <= 0.6; d += 0.05) {
        const PolynomialHand hand(0.18, b, c, d);
        std::string message = "no error";
        try {
          validate_hand_for_disk(hand, 1e-4);
        } catch (const std::invalid_argument& e) {
          message = e.what();
        }
        // The checks before this one (cusp, crossing the mirror axis, tight wells) stop first.
        if (message.find("between") == std::string::npos && message != "no error" &&
            message.find("no well") == std::string::npos)
          continue;
        ++checked;
        std::vector<Vec2> pts;
        for (int i = 0; i <= kSamples; i += kStride)
          pts.push_back(hand.geometry(-1.0 + 2.0 * i / kSamples, 0).point);
        int first_i = -1;
        for (std::size_t i = 0; i + 1 < pts.size() && first_i < 0; ++i)
          for (std::size_t j = i + 2; j + 1 < pts.size(); ++j)
            if (crosses(pts[i], pts[i + 1], pts[j], pts[j + 1])) {
              first_i = static_cast<int>(i);
              break;
            }
        if (first_i < 0) {
          EXPECT_EQ(message.find("between"), std::string::npos) << "b=" << b << " d=" << d;
          continue;
        }
        ++folded;
        const std::string key = "self-intersects between at s_h=";
        const auto at = message.find(key);
        ASSERT_NE(at, std::string::npos)
            << message << " (b=" << b << " c=" << c << " d=" << d << ")";
        EXPECT_NEAR(std::stod(message.substr(at + key.size())),
                    -1.0 + 2.0 * first_i * kStride / kSamples, 1e-9)
            << message;
      }
  EXPECT_GT(folded, 5);
  EXPECT_GT(checked, folded);
}

TEST(Geometry, BadObjectsAndMotionsAreRejected) {
  EXPECT_THROW(make_uniform_disk(-0.05), std::invalid_argument);
  EXPECT_THROW(make_uniform_disk(0.05, 0.0), std::invalid_argument);
  EXPECT_THROW(make_uniform_disk(std::nan("")), std::invalid_argument);
  EXPECT_THROW(make_uniform_ellipse(0.05, -1), std::invalid_argument);
  EXPECT_THROW(ButterflyMotion(1.181, -2.0), std::invalid_argument);
  EXPECT_THROW(ButterflyMotion(0.0, -1.1), std::invalid_argument);
  EXPECT_THROW(ButterflyMotion(-1.0, -1.1), std::invalid_argument);
  EXPECT_THROW(ButterflyMotion(std::nan(""), -1.1), std::invalid_argument);
  EXPECT_THROW(PolynomialHand(0.18, std::nan(""), 0, 0), std::invalid_argument);
}

TEST(Motion, QuinticProfileMatchesThePaper) {
  const double period = 1.181, k = -1.1393;
  const ButterflyMotion m(period, k);
  EXPECT_NEAR(m.at(0.0).angle, 0.0, 1e-15);
  EXPECT_NEAR(m.at(period).angle, std::numbers::pi, 1e-14);
  EXPECT_NEAR(m.at(0.0).angular_velocity, 0.0, 1e-13);
  EXPECT_NEAR(m.at(period, 1).angular_velocity, 0.0, 1e-13);
  EXPECT_NEAR(m.at(0.5 * period).angle, 0.5 * std::numbers::pi, 1e-14);
  // Dip: the hand first turns backwards for k < -2/3, not for k = -2/3.
  EXPECT_LT(m.at(0.02).angle, 0.0);
  EXPECT_NEAR(ButterflyMotion(period, -2.0 / 3.0).at(0.0).angular_acceleration, 0.0, 1e-12);
  // Derivatives are consistent (central differences).
  const double t = 0.37, h = 1e-6;
  EXPECT_NEAR((m.at(t + h).angle - m.at(t - h).angle) / (2 * h), m.at(t).angular_velocity, 1e-6);
  EXPECT_NEAR((m.at(t + h).angular_velocity - m.at(t - h).angular_velocity) / (2 * h),
              m.at(t).angular_acceleration, 1e-5);
}
