// Surfaces for spatial rolling: every derived quantity against finite differences of the one it
// derives from, and against closed forms (sphere, plane, ellipsoid, the planar hand extruded, a
// circle and an ellipse turned into a sphere and an ellipsoid of revolution).
#include "flatland/sim/surface.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

namespace flatland::sim {
namespace {

/// Central differences of f along u and v, step h.
template <class F>
auto central(const F& f, const SurfaceParam& s, int axis, double h) -> decltype(f(s)) {
  SurfaceParam a = s, b = s;
  a[axis] += h;
  b[axis] -= h;
  return ((f(a) - f(b)) / (2 * h)).eval();
}

/// Each of J, dJ, n, K, dK is the derivative of the one before it (to the differences' accuracy).
void expect_consistent(const Surface& surface, const SurfaceParam& s) {
  SCOPED_TRACE(surface.describe() + " at (" + std::to_string(s.x()) + ", " + std::to_string(s.y()) +
               ")");
  const double h = 1e-5;
  const SurfaceGeometry g = surface.geometry(s);
  const auto point = [&](const SurfaceParam& p) -> Vec3 { return surface.geometry(p).point; };
  const auto jac = [&](const SurfaceParam& p) -> Mat32 { return surface.geometry(p).jacobian; };
  const auto normal = [&](const SurfaceParam& p) -> Vec3 { return surface.geometry(p).normal; };
  const auto form = [&](const SurfaceParam& p) -> Mat32 {
    return surface.geometry(p).curvature_form;
  };
  const double scale = 1 + g.jacobian.norm();
  for (int i = 0; i < 2; ++i) {
    EXPECT_LT((central(point, s, i, h) - g.jacobian.col(i)).norm(), 1e-8 * scale) << "J col " << i;
    EXPECT_LT((central(jac, s, i, h) - g.jacobian_ds[i]).norm(), 1e-7 * scale) << "dJ/ds" << i;
    EXPECT_LT((central(normal, s, i, h) - g.curvature_form.col(i)).norm(), 1e-7 * scale)
        << "K col " << i;
    EXPECT_LT((central(form, s, i, h) - g.curvature_form_ds[i]).norm(),
              1e-6 * (1 + g.curvature_form.norm()))
        << "dK/ds" << i;
  }
  EXPECT_NEAR(g.normal.norm(), 1.0, 1e-14);
  EXPECT_LT(std::abs(g.normal.dot(g.jacobian.col(0))), 1e-12 * scale);
  EXPECT_LT(std::abs(g.normal.dot(g.jacobian.col(1))), 1e-12 * scale);
}

TEST(Surface, DerivativesAgreeWithFiniteDifferencesOnEverySurface) {
  const auto hand = std::make_shared<PolynomialHand>(0.18, -0.18, -0.252, 0.216);
  const auto ellipse = std::make_shared<EllipseCurve>(0.05, 0.03);
  const std::vector<std::shared_ptr<const Surface>> surfaces = {
      std::make_shared<PlaneSurface>(Vec3(0.1, -0.2, 0.3), Vec3(1, 0, 0),
                                     Vec3(0, std::sqrt(0.5), std::sqrt(0.5))),
      std::make_shared<EllipsoidSurface>(
          EllipsoidSurface::sphere(0.05, EllipsoidSurface::Side::kConvexBody)),
      std::make_shared<EllipsoidSurface>(
          EllipsoidSurface::sphere(0.3, EllipsoidSurface::Side::kDish)),
      std::make_shared<EllipsoidSurface>(0.07, 0.05, 0.03, EllipsoidSurface::Side::kConvexBody),
      std::make_shared<EllipsoidSurface>(0.4, 0.3, 0.2, EllipsoidSurface::Side::kDish),
      std::make_shared<ExtrudedSurface>(hand, 0),
      std::make_shared<RevolutionSurface>(ellipse, 0),
      std::make_shared<RotatedSurface>(
          std::make_shared<EllipsoidSurface>(0.4, 0.3, 0.2, EllipsoidSurface::Side::kDish),
          Eigen::AngleAxisd(0.7, Vec3(1, -2, 0.5).normalized()).toRotationMatrix()),
  };
  for (const auto& surface : surfaces)
    for (const SurfaceParam& s : {SurfaceParam(0.3, 0.2), SurfaceParam(-1.1, -0.7),
                                  SurfaceParam(2.5, 0.9), SurfaceParam(0.0, -0.35)})
      expect_consistent(*surface, s);
}

TEST(Surface, SphereHasItsClosedForms) {
  const double R = 0.05;
  for (const auto side : {EllipsoidSurface::Side::kConvexBody, EllipsoidSurface::Side::kDish}) {
    const EllipsoidSurface sphere = EllipsoidSurface::sphere(R, side);
    const double sign = side == EllipsoidSurface::Side::kConvexBody ? 1 : -1;
    for (const SurfaceParam& s : {SurfaceParam(0.4, 0.3), SurfaceParam(-2.0, -1.0)}) {
      const SurfaceGeometry g = sphere.geometry(s);
      EXPECT_NEAR(g.point.norm(), R, 1e-15);
      // Outward from a ball, towards the centre in a bowl; dn/ds = J / R with that sign.
      EXPECT_LT((g.normal - sign * g.point / R).norm(), 1e-14);
      EXPECT_LT((g.curvature_form - sign * g.jacobian / R).norm(), 1e-13);
      // Both principal curvatures 1/R: Gaussian 1/R^2; mean +1/R for the ball, -1/R in the bowl.
      EXPECT_NEAR(g.gaussian_curvature(), 1 / (R * R), 1e-9 / (R * R));
      EXPECT_NEAR(g.mean_curvature(), sign / R, 1e-9 / R);
    }
  }
}

TEST(Surface, PlaneIsFlat) {
  const PlaneSurface plane({0, 0, 0.1}, {1, 0, 0}, {0, 1, 0});
  const SurfaceGeometry g = plane.geometry({0.3, -0.4});
  EXPECT_EQ(g.point, Vec3(0.3, -0.4, 0.1));
  EXPECT_EQ(g.normal, Vec3(0, 0, 1));
  EXPECT_EQ(g.curvature_form, Mat32::Zero());
  EXPECT_EQ(g.curvature_form_ds[0], Mat32::Zero());
  EXPECT_THROW(PlaneSurface({0, 0, 0}, {1, 0, 0}, {1, 0, 0}), std::invalid_argument);
  EXPECT_THROW(PlaneSurface({0, 0, 0}, {2, 0, 0}, {0, 1, 0}), std::invalid_argument);
}

TEST(Surface, EllipsoidNormalAndGaussianCurvatureHaveTheirClosedForms) {
  const double a = 0.07, b = 0.05, c = 0.03;
  const EllipsoidSurface e(a, b, c, EllipsoidSurface::Side::kConvexBody);
  for (const SurfaceParam& s : {SurfaceParam(0.3, 0.2), SurfaceParam(2.0, -0.9)}) {
    const SurfaceGeometry g = e.geometry(s);
    const Vec3& p = g.point;
    EXPECT_NEAR(p.x() * p.x() / (a * a) + p.y() * p.y() / (b * b) + p.z() * p.z() / (c * c), 1,
                1e-14);
    // The gradient of the implicit function x^2/a^2 + y^2/b^2 + z^2/c^2 is normal.
    const Vec3 grad(p.x() / (a * a), p.y() / (b * b), p.z() / (c * c));
    EXPECT_LT((g.normal - grad.normalized()).norm(), 1e-13);
    // K = 1 / (a^2 b^2 c^2 (x^2/a^4 + y^2/b^4 + z^2/c^4)^2).
    const double q = p.x() * p.x() / std::pow(a, 4) + p.y() * p.y() / std::pow(b, 4) +
                     p.z() * p.z() / std::pow(c, 4);
    const double gaussian = 1 / (a * a * b * b * c * c * q * q);
    EXPECT_NEAR(g.gaussian_curvature(), gaussian, 1e-10 * gaussian);
  }
}

TEST(Surface, ExtrudedHandCarriesThePlanarGeometry) {
  const auto hand = std::make_shared<PolynomialHand>(0.18, -0.18, -0.252, 0.216);
  const ExtrudedSurface surface(hand, 0);
  for (const double s : {-0.8, -0.2, 0.0, 0.5, 0.95}) {
    const CurveGeometry planar = hand->geometry(s, 0);
    const SurfaceGeometry g = surface.geometry({s, 0.02});
    EXPECT_LT((g.point - Vec3(planar.point.x(), planar.point.y(), 0.02)).norm(), 1e-15);
    EXPECT_LT((g.normal - Vec3(planar.normal.x(), planar.normal.y(), 0)).norm(), 1e-14);
    // dn/du is the planar K; nothing changes along the extrusion.
    EXPECT_LT(
        (g.curvature_form.col(0) - Vec3(planar.normal_ds.x(), planar.normal_ds.y(), 0)).norm(),
        1e-12);
    EXPECT_EQ(g.curvature_form.col(1), Vec3::Zero());
    EXPECT_LT(
        (g.curvature_form_ds[0].col(0) - Vec3(planar.normal_dss.x(), planar.normal_dss.y(), 0))
            .norm(),
        1e-10);
    // One principal curvature is the planar one, the other 0: Gaussian curvature 0.
    EXPECT_NEAR(g.gaussian_curvature(), 0, 1e-12);
    EXPECT_NEAR(g.mean_curvature(), 0.5 * planar.curvature,
                1e-10 * (1 + std::abs(planar.curvature)));
  }
}

TEST(Surface, AnEllipseTurnedAboutItsAxisIsTheEllipsoidOfRevolution) {
  // The profile (a cos t, c sin t) turned about z is the ellipsoid (a, a, c), parameterised the
  // same way (longitude u, latitude v = t): two independent derivations of the same geometry.
  const double a = 0.06, c = 0.04;
  const RevolutionSurface revolved(std::make_shared<EllipseCurve>(a, c), 0);
  const EllipsoidSurface ellipsoid(a, a, c, EllipsoidSurface::Side::kConvexBody);
  for (const SurfaceParam& s :
       {SurfaceParam(0.3, 0.2), SurfaceParam(-2.2, -1.1), SurfaceParam(1, 1.3)}) {
    const SurfaceGeometry g1 = revolved.geometry(s), g2 = ellipsoid.geometry(s);
    EXPECT_LT((g1.point - g2.point).norm(), 1e-15);
    EXPECT_LT((g1.normal - g2.normal).norm(), 1e-14);
    EXPECT_LT((g1.curvature_form - g2.curvature_form).norm(), 1e-12);
    EXPECT_LT((g1.curvature_form_ds[1] - g2.curvature_form_ds[1]).norm(), 1e-10);
  }
}

TEST(Surface, ARotatedSurfaceIsItsSurfaceTurned) {
  // An ellipsoid's chart with its poles on the x axis: the ellipsoid with semi-axes (b, c, a) in
  // the frame that takes its x, y, z to the body's y, z, x is the same ellipsoid.
  const double a = 0.07, b = 0.05, c = 0.03;
  const auto inner = std::make_shared<EllipsoidSurface>(b, c, a, EllipsoidSurface::Side::kDish);
  Eigen::Matrix3d Q;
  Q << 0, 0, 1, 1, 0, 0, 0, 1, 0;
  const RotatedSurface turned(inner, Q, "dish, chart with its poles on x");
  EXPECT_EQ(turned.describe(), "dish, chart with its poles on x");
  EXPECT_EQ(turned.normal_sign(), inner->normal_sign());
  EXPECT_EQ(turned.patch().hi, inner->patch().hi);
  for (const SurfaceParam& s : {SurfaceParam(0.3, 0.2), SurfaceParam(-2.0, -1.1)}) {
    const SurfaceGeometry g = turned.geometry(s), gi = inner->geometry(s);
    const Vec3 x = g.point;
    EXPECT_NEAR(x.x() * x.x() / (a * a) + x.y() * x.y() / (b * b) + x.z() * x.z() / (c * c), 1,
                1e-14);
    EXPECT_LT((x - Q * gi.point).norm(), 1e-16);
    EXPECT_LT((g.normal - Q * gi.normal).norm(), 1e-15);
    EXPECT_LT((g.curvature_form - Q * gi.curvature_form).norm(), 1e-12);
    EXPECT_NEAR(g.gaussian_curvature(), gi.gaussian_curvature(), 1e-9 * gi.gaussian_curvature());
    // The dish's normal points towards the centre, as the unturned dish's does.
    EXPECT_LT(g.normal.dot(x), 0);
  }
  EXPECT_EQ(RotatedSurface(inner, Eigen::Matrix3d::Identity()).describe(), inner->describe());
  EXPECT_THROW(RotatedSurface(inner, 2 * Q), std::invalid_argument);
  EXPECT_THROW(RotatedSurface(inner, -Q), std::invalid_argument);  // a reflection
  EXPECT_THROW(RotatedSurface(nullptr, Q), std::invalid_argument);
}

TEST(Surface, SingularChartsAndBadShapesAreRefused) {
  const EllipsoidSurface sphere =
      EllipsoidSurface::sphere(0.05, EllipsoidSurface::Side::kConvexBody);
  try {
    sphere.geometry({0.0, std::numbers::pi / 2});  // the pole: c_u = 0
    FAIL() << "no error at the pole";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sphere (r 0.05 m): surface: singular chart"),
              std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(sphere.patch().contains({0.0, std::numbers::pi / 2}));
  EXPECT_TRUE(sphere.patch().contains({100.0, 1.0}));
  EXPECT_THROW(EllipsoidSurface(0.1, -0.1, 0.1, EllipsoidSurface::Side::kDish),
               std::invalid_argument);
  EXPECT_THROW(EllipsoidSurface(0.1, 0.1, NAN, EllipsoidSurface::Side::kDish),
               std::invalid_argument);
  EXPECT_THROW(EllipsoidSurface(0.1, 0.1, 0.1, EllipsoidSurface::Side::kDish, 2.0),
               std::invalid_argument);
}

}  // namespace
}  // namespace flatland::sim
