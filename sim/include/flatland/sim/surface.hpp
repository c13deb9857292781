// Surfaces for spatial rolling (the paper's section 3 in its spatial form; Montana's contact
// geometry): a hand or an object surface locally parameterised by s = (u, v) in R^2 over a patch,
// with the quantities the 11 x 10 rolling equations take: the position c(s), the Jacobian
// J = dc/ds (3 x 2), the outward unit normal n, the curvature form K = dn/ds (3 x 2) and the
// derivatives of J and K along s (for the J-dot and K-dot terms of equations (1) and (2)).
//
// Each surface gives only its position and partial derivatives up to third order (a SurfaceJet);
// everything else is derived from them once, in geometry_from_jet, as CurveGeometry is for the
// planar curves. The spatial dynamics (spatial.hpp) take it.
#pragma once

#include "flatland/sim/curve.hpp"

#include <Eigen/Core>

#include <array>
#include <memory>
#include <string>

namespace flatland::sim {

using Vec3 = Eigen::Vector3d;
using Mat32 = Eigen::Matrix<double, 3, 2>;
using SurfaceParam = Eigen::Vector2d;  ///< s = (u, v)

/// Position and its partial derivatives up to third order at one s = (u, v).
struct SurfaceJet {
  Vec3 c;
  Vec3 cu, cv;
  Vec3 cuu, cuv, cvv;
  Vec3 cuuu, cuuv, cuvv, cvvv;
};

/// The differential geometry at one s (everything derived from a SurfaceJet).
struct SurfaceGeometry {
  Vec3 point;                              ///< c(s), m
  Mat32 jacobian;                          ///< J = dc/ds = [c_u c_v]
  std::array<Mat32, 2> jacobian_ds;        ///< dJ/du, dJ/dv
  Vec3 normal;                             ///< unit outward normal, +-(c_u x c_v) / |c_u x c_v|
  Mat32 curvature_form;                    ///< K = dn/ds = [n_u n_v] (the paper's K_h, K_o)
  std::array<Mat32, 2> curvature_form_ds;  ///< dK/du, dK/dv
  /// The shape operator's matrix in the (u, v) basis, (J^T J)^-1 J^T K: its determinant is the
  /// Gaussian curvature (> 0 where the body is convex or concave like a bowl, with the sign of
  /// its trace telling which: > 0 convex), its eigenvalues the principal curvatures, 1/m.
  Eigen::Matrix2d shape_operator;
  double gaussian_curvature() const {
    return shape_operator(0, 0) * shape_operator(1, 1) - shape_operator(0, 1) * shape_operator(1, 0);
  }
  double mean_curvature() const { return 0.5 * shape_operator.trace(); }
};

/// The box of parameters over which a surface's chart is regular; a contact that leaves it must
/// be moved to another chart (an event of the spatial integrator).
struct SurfacePatch {
  SurfaceParam lo, hi;
  bool contains(const SurfaceParam& s) const {
    return s.x() >= lo.x() && s.x() <= hi.x() && s.y() >= lo.y() && s.y() <= hi.y();
  }
};

/// A hand or object surface. `normal_sign` orients the normal: +1 where c_u x c_v points out of
/// the body, -1 where it points in.
class Surface {
 public:
  virtual ~Surface() = default;
  virtual SurfaceJet jet(const SurfaceParam& s) const = 0;
  virtual int normal_sign() const = 0;
  virtual SurfacePatch patch() const = 0;
  virtual std::string describe() const = 0;
  /// std::invalid_argument naming the surface and s where c_u x c_v vanishes (a singular chart).
  SurfaceGeometry geometry(const SurfaceParam& s) const;
};
using SurfacePtr = std::shared_ptr<const Surface>;

/// Geometry from a jet; `normal_sign` as Surface::normal_sign(). std::invalid_argument if
/// |c_u x c_v| is not positive (the chart is singular there).
SurfaceGeometry geometry_from_jet(const SurfaceJet& jet, int normal_sign);

/// A plane through `origin` spanned by the orthonormal `axis_u`, `axis_v`: c = o + u e_u + v e_v,
/// outward normal e_u x e_v (the body lies behind it). K = 0.
class PlaneSurface final : public Surface {
 public:
  /// std::invalid_argument unless the axes are unit and orthogonal (to 1e-9).
  PlaneSurface(Vec3 origin, Vec3 axis_u, Vec3 axis_v);
  SurfaceJet jet(const SurfaceParam& s) const override;
  int normal_sign() const override { return +1; }
  SurfacePatch patch() const override;
  std::string describe() const override;

 private:
  Vec3 origin_, axis_u_, axis_v_;
};

/// An ellipsoid with semi-axes (a, b, c) about the origin, by longitude u and latitude v:
/// c(u, v) = (a cos v cos u, b cos v sin u, c sin v). kConvexBody: a ball or ellipsoid (an object,
/// or a dome-shaped hand), normal outwards; kDish: the inside of the ellipsoid as a hand (a bowl
/// or dish holding an object), normal towards the centre. The chart is singular at the poles; its
/// patch stops `pole_margin` rad short of them.
class EllipsoidSurface final : public Surface {
 public:
  enum class Side { kConvexBody, kDish };
  /// std::invalid_argument unless a, b, c are positive and finite and 0 < pole_margin < pi/2.
  EllipsoidSurface(double a, double b, double c, Side side, double pole_margin = 0.2);
  static EllipsoidSurface sphere(double radius, Side side) {
    return {radius, radius, radius, side};
  }
  SurfaceJet jet(const SurfaceParam& s) const override;
  int normal_sign() const override { return side_ == Side::kConvexBody ? +1 : -1; }
  SurfacePatch patch() const override;
  std::string describe() const override;
  Vec3 semi_axes() const { return {a_, b_, c_}; }
  Side side() const { return side_; }
  double pole_margin() const { return pole_margin_; }

 private:
  double a_, b_, c_;
  Side side_;
  double pole_margin_;
};

/// A surface given in a turned frame: c(s) = Q c_inner(s), Q a rotation, with the inner surface's
/// parameters, normal side and patch. A spatial run moves a contact between charts made so (an
/// ellipsoid's with its poles on another axis, a ball's laid along the contact's path).
class RotatedSurface final : public Surface {
 public:
  /// std::invalid_argument without an inner surface or unless `rotation` is a rotation (to
  /// 1e-9). `description`: what describe() says (empty: the inner surface's description).
  RotatedSurface(SurfacePtr inner, const Eigen::Matrix3d& rotation, std::string description = {});
  SurfaceJet jet(const SurfaceParam& s) const override;
  int normal_sign() const override { return inner_->normal_sign(); }
  SurfacePatch patch() const override { return inner_->patch(); }
  std::string describe() const override;
  const Eigen::Matrix3d& rotation() const { return rotation_; }

 private:
  SurfacePtr inner_;
  Eigen::Matrix3d rotation_;
  std::string description_;
};

/// A planar curve extruded along z: c(u, v) = (x(u), y(u), v), u the curve's parameter (on one
/// of its smooth pieces), v the height. Its normal is the curve's outward normal, in the plane.
/// The planar hand extruded so is the surface on which a sphere rolling in the plane z = const
/// reproduces the planar problem.
class ExtrudedSurface final : public Surface {
 public:
  /// `piece`: the curve's smooth piece whose formula is used (the patch is its interval).
  ExtrudedSurface(CurvePtr curve, int piece);
  SurfaceJet jet(const SurfaceParam& s) const override;
  int normal_sign() const override;
  SurfacePatch patch() const override;
  std::string describe() const override;

 private:
  CurvePtr curve_;
  int piece_;
};

/// A planar profile (r(t), z(t)) (the curve's x and y) turned about the z axis: c(u, v) =
/// (r(v) cos u, r(v) sin u, z(v)), u the angle, v the profile's parameter (on one smooth piece).
/// Its normal is the profile's outward normal turned with it. Where r = 0 the chart is singular.
class RevolutionSurface final : public Surface {
 public:
  RevolutionSurface(CurvePtr profile, int piece);
  SurfaceJet jet(const SurfaceParam& s) const override;
  int normal_sign() const override;
  SurfacePatch patch() const override;
  std::string describe() const override;

 private:
  CurvePtr profile_;
  int piece_;
};

}  // namespace flatland::sim
