// Surfaces for spatial rolling: the geometry every surface derives from its jet, and the jets of
// the plane, the ellipsoid (sphere), the extruded curve and the surface of revolution.
#include "flatland/sim/surface.hpp"
#include "infinity.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <utility>

namespace flatland::sim {

namespace {

std::string at_text(const SurfaceParam& s) {
  return "(u, v) = (" + format_significant(s.x(), 9) + ", " + format_significant(s.y(), 9) + ")";
}

Mat32 columns(const Vec3& a, const Vec3& b) {
  Mat32 m;
  m.col(0) = a;
  m.col(1) = b;
  return m;
}

}  // namespace

SurfaceGeometry geometry_from_jet(const SurfaceJet& j, int normal_sign) {
  // n = sigma m / |m| with m = c_u x c_v; its first and second derivatives by the chain rule from
  // those of m (which need c's derivatives up to third order).
  const Vec3 m = j.cu.cross(j.cv);
  const double r = m.norm();
  // |c_u x c_v| against |c_u|^2 + |c_v|^2: at most 1/2, and near 0 only where the chart
  // degenerates (a pole of the ellipsoid's, the axis of a surface of revolution).
  if (!std::isfinite(r) || !(r > 1e-10 * (j.cu.squaredNorm() + j.cv.squaredNorm())))
    throw std::invalid_argument("surface: singular chart (c_u x c_v = 0)");
  const Vec3 mu = j.cuu.cross(j.cv) + j.cu.cross(j.cuv);
  const Vec3 mv = j.cuv.cross(j.cv) + j.cu.cross(j.cvv);
  const Vec3 muu = j.cuuu.cross(j.cv) + 2 * j.cuu.cross(j.cuv) + j.cu.cross(j.cuuv);
  const Vec3 muv = j.cuuv.cross(j.cv) + j.cuu.cross(j.cvv) + j.cu.cross(j.cuvv);
  const Vec3 mvv = j.cuvv.cross(j.cv) + 2 * j.cuv.cross(j.cvv) + j.cu.cross(j.cvvv);
  const double sigma = normal_sign >= 0 ? 1.0 : -1.0;
  const double r2 = r * r, r3 = r2 * r, r5 = r3 * r2;
  const auto d1 = [&](const Vec3& mi) -> Vec3 { return sigma * (mi / r - m * m.dot(mi) / r3); };
  const auto d2 = [&](const Vec3& mi, const Vec3& mj, const Vec3& mij) -> Vec3 {
    const double a = m.dot(mi), b = m.dot(mj);
    return sigma * (mij / r - mi * b / r3 - mj * a / r3 - m * (mi.dot(mj) + m.dot(mij)) / r3 +
                    3 * m * a * b / r5);
  };
  SurfaceGeometry g;
  g.point = j.c;
  g.jacobian = columns(j.cu, j.cv);
  g.jacobian_ds = {columns(j.cuu, j.cuv), columns(j.cuv, j.cvv)};
  g.normal = sigma * m / r;
  const Vec3 nu = d1(mu), nv = d1(mv);
  g.curvature_form = columns(nu, nv);
  const Vec3 nuv = d2(mu, mv, muv);
  g.curvature_form_ds = {columns(d2(mu, mu, muu), nuv), columns(nuv, d2(mv, mv, mvv))};
  const Eigen::Matrix2d metric = g.jacobian.transpose() * g.jacobian;
  g.shape_operator = metric.ldlt().solve(g.jacobian.transpose() * g.curvature_form);
  return g;
}

SurfaceGeometry Surface::geometry(const SurfaceParam& s) const {
  try {
    return geometry_from_jet(jet(s), normal_sign());
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(describe() + ": " + e.what() + " at " + at_text(s));
  }
}

// ---- plane ----------------------------------------------------------------------------------

PlaneSurface::PlaneSurface(Vec3 origin, Vec3 axis_u, Vec3 axis_v)
    : origin_(origin), axis_u_(axis_u), axis_v_(axis_v) {
  if (!origin.allFinite() || !axis_u.allFinite() || !axis_v.allFinite())
    throw std::invalid_argument("plane: origin and axes must be finite");
  if (std::abs(axis_u.norm() - 1) > 1e-9 || std::abs(axis_v.norm() - 1) > 1e-9 ||
      std::abs(axis_u.dot(axis_v)) > 1e-9)
    throw std::invalid_argument("plane: axis_u and axis_v must be orthonormal");
}

SurfaceJet PlaneSurface::jet(const SurfaceParam& s) const {
  SurfaceJet j;
  j.c = origin_ + s.x() * axis_u_ + s.y() * axis_v_;
  j.cu = axis_u_;
  j.cv = axis_v_;
  j.cuu = j.cuv = j.cvv = j.cuuu = j.cuuv = j.cuvv = j.cvvv = Vec3::Zero();
  return j;
}

SurfacePatch PlaneSurface::patch() const { return {{-kInf, -kInf}, {kInf, kInf}}; }

std::string PlaneSurface::describe() const { return "plane"; }

// ---- ellipsoid --------------------------------------------------------------------------------

EllipsoidSurface::EllipsoidSurface(double a, double b, double c, Side side, double pole_margin)
    : a_(a), b_(b), c_(c), side_(side), pole_margin_(pole_margin) {
  for (double v : {a, b, c})
    if (!std::isfinite(v) || !(v > 0))
      throw std::invalid_argument("ellipsoid: semi-axes must be positive and finite, got " +
                                  format_significant(v));
  if (!(pole_margin > 0 && pole_margin < std::numbers::pi / 2))
    throw std::invalid_argument("ellipsoid: pole_margin must be in (0, pi/2) rad");
}

SurfaceJet EllipsoidSurface::jet(const SurfaceParam& s) const {
  const double cu = std::cos(s.x()), su = std::sin(s.x());
  const double cv = std::cos(s.y()), sv = std::sin(s.y());
  const double a = a_, b = b_, c = c_;
  SurfaceJet j;
  j.c = {a * cv * cu, b * cv * su, c * sv};
  j.cu = {-a * cv * su, b * cv * cu, 0};
  j.cv = {-a * sv * cu, -b * sv * su, c * cv};
  j.cuu = {-a * cv * cu, -b * cv * su, 0};
  j.cuv = {a * sv * su, -b * sv * cu, 0};
  j.cvv = {-a * cv * cu, -b * cv * su, -c * sv};
  j.cuuu = {a * cv * su, -b * cv * cu, 0};
  j.cuuv = {a * sv * cu, b * sv * su, 0};
  j.cuvv = {a * cv * su, -b * cv * cu, 0};
  j.cvvv = {a * sv * cu, b * sv * su, -c * cv};
  return j;
}

SurfacePatch EllipsoidSurface::patch() const {
  const double v = std::numbers::pi / 2 - pole_margin_;
  return {{-kInf, -v}, {kInf, v}};
}

std::string EllipsoidSurface::describe() const {
  const bool sphere = a_ == b_ && b_ == c_;
  const std::string what = side_ == Side::kConvexBody
                               ? (sphere ? "sphere" : "ellipsoid")
                               : (sphere ? "spherical bowl" : "ellipsoidal dish");
  return what + " (" +
         (sphere ? "r " + format_significant(a_)
                 : "semi-axes " + format_significant(a_) + ", " + format_significant(b_) + ", " +
                       format_significant(c_)) +
         " m)";
}

// ---- a surface in a turned frame ---------------------------------------------------------------

RotatedSurface::RotatedSurface(SurfacePtr inner, const Eigen::Matrix3d& rotation,
                               std::string description)
    : inner_(std::move(inner)), rotation_(rotation), description_(std::move(description)) {
  if (!inner_) throw std::invalid_argument("rotated surface: no surface");
  if (!rotation.allFinite() ||
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).norm() > 1e-9 ||
      std::abs(rotation.determinant() - 1) > 1e-9)
    throw std::invalid_argument("rotated surface: the frame must be a rotation");
}

// Every derivative is a vector of the inner frame, turned as the position is; a rotation keeps
// c_u x c_v turned too, so the normal's side is the inner surface's.
SurfaceJet RotatedSurface::jet(const SurfaceParam& s) const {
  SurfaceJet j = inner_->jet(s);
  for (Vec3* v : {&j.c, &j.cu, &j.cv, &j.cuu, &j.cuv, &j.cvv, &j.cuuu, &j.cuuv, &j.cuvv, &j.cvvv})
    *v = rotation_ * *v;
  return j;
}

std::string RotatedSurface::describe() const {
  return description_.empty() ? inner_->describe() : description_;
}

// ---- extruded curve ---------------------------------------------------------------------------

ExtrudedSurface::ExtrudedSurface(CurvePtr curve, int piece)
    : curve_(std::move(curve)), piece_(piece) {
  if (!curve_) throw std::invalid_argument("extruded surface: no curve");
}

SurfaceJet ExtrudedSurface::jet(const SurfaceParam& s) const {
  const CurveJet cj = curve_->jet(s.x(), piece_);
  SurfaceJet j;
  j.c = {cj.c.x(), cj.c.y(), s.y()};
  j.cu = {cj.d1.x(), cj.d1.y(), 0};
  j.cv = Vec3::UnitZ();
  j.cuu = {cj.d2.x(), cj.d2.y(), 0};
  j.cuuu = {cj.d3.x(), cj.d3.y(), 0};
  j.cuv = j.cvv = j.cuuv = j.cuvv = j.cvvv = Vec3::Zero();
  return j;
}

// c_u x c_v = (y', -x', 0): the tangent turned by -90 degrees.
int ExtrudedSurface::normal_sign() const { return -curve_->normal_side(); }

SurfacePatch ExtrudedSurface::patch() const {
  const PieceInterval iv = curve_->piece_interval(piece_);
  return {{iv.lo, -kInf}, {iv.hi, kInf}};
}

std::string ExtrudedSurface::describe() const { return "extruded " + curve_->describe(); }

// ---- surface of revolution --------------------------------------------------------------------

RevolutionSurface::RevolutionSurface(CurvePtr profile, int piece)
    : profile_(std::move(profile)), piece_(piece) {
  if (!profile_) throw std::invalid_argument("surface of revolution: no profile");
}

SurfaceJet RevolutionSurface::jet(const SurfaceParam& s) const {
  const CurveJet p = profile_->jet(s.y(), piece_);  // (r, z) = (x, y) of the profile
  const double cu = std::cos(s.x()), su = std::sin(s.x());
  const double r = p.c.x(), r1 = p.d1.x(), r2 = p.d2.x(), r3 = p.d3.x();
  SurfaceJet j;
  j.c = {r * cu, r * su, p.c.y()};
  j.cu = {-r * su, r * cu, 0};
  j.cv = {r1 * cu, r1 * su, p.d1.y()};
  j.cuu = {-r * cu, -r * su, 0};
  j.cuv = {-r1 * su, r1 * cu, 0};
  j.cvv = {r2 * cu, r2 * su, p.d2.y()};
  j.cuuu = {r * su, -r * cu, 0};
  j.cuuv = {-r1 * cu, -r1 * su, 0};
  j.cuvv = {-r2 * su, r2 * cu, 0};
  j.cvvv = {r3 * cu, r3 * su, p.d3.y()};
  return j;
}

// c_u x c_v = r (z' cos u, z' sin u, -r'): for r > 0 the profile's tangent turned by -90 degrees,
// turned with it.
int RevolutionSurface::normal_sign() const { return -profile_->normal_side(); }

SurfacePatch RevolutionSurface::patch() const {
  const PieceInterval iv = profile_->piece_interval(piece_);
  return {{-kInf, iv.lo}, {kInf, iv.hi}};
}

std::string RevolutionSurface::describe() const {
  return "surface of revolution of " + profile_->describe();
}

}  // namespace flatland::sim
