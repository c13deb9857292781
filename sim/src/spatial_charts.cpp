// The charts a spatial run moves a contact between: a ball's turned along the contact's path, an
// ellipsoid's three with their poles on its axes (spatial_charts.hpp).
#include "spatial_charts.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <string>
#include <utility>

namespace flatland::sim::detail {

SurfaceCharts::SurfaceCharts(SurfacePtr surface, bool turn_a_sphere_freely)
    : surface_(std::move(surface)), chart_(surface_) {
  ellipsoid_ = dynamic_cast<const EllipsoidSurface*>(surface_.get());
  if (!ellipsoid_) return;
  axes_ = ellipsoid_->semi_axes();
  turn_freely_ = turn_a_sphere_freely && axes_.x() == axes_.y() && axes_.y() == axes_.z();
}

void SurfaceCharts::use(const Eigen::Matrix3d& frame, const Vec3& axes, const std::string& what) {
  frame_ = frame;
  axes_ = axes;
  if (frame.isIdentity(0.0)) {  // back in the surface's own chart
    chart_ = surface_;
    return;
  }
  // A sphere is the same in every frame; an ellipsoid's chart has its semi-axes permuted.
  const SurfacePtr inner = turn_freely_ ? surface_
                                        : std::make_shared<EllipsoidSurface>(
                                              axes.x(), axes.y(), axes.z(), ellipsoid_->side(),
                                              ellipsoid_->pole_margin());
  chart_ = std::make_shared<RotatedSurface>(inner, frame, surface_->describe() + ", " + what);
}

bool SurfaceCharts::update(SurfaceParam& s, SurfaceParam& sdot) {
  if (!ellipsoid_ || !(std::abs(s.y()) > kSwitchLatitude)) return false;
  const SurfaceGeometry g = chart_->geometry(s);
  const Vec3 x = g.point, w = g.jacobian * sdot;  // the contact and its velocity, body frame
  if (turn_freely_) {
    // The new chart's (0, 0) point (its +x end) on the contact, its u direction along the
    // contact's velocity over the ball (any tangent if the contact rests on it).
    const Vec3 e1 = x.normalized();
    const Vec3 along = w - w.dot(e1) * e1;
    const Vec3 e2 = along.norm() > 1e-12 * x.norm() ? along.normalized() : e1.unitOrthogonal();
    Eigen::Matrix3d frame;
    frame << e1, e2, e1.cross(e2);
    use(frame, axes_, "chart laid along the contact's path");
  } else {
    // x / (a, b, c) is a unit vector: its component along each axis is the sine of the contact's
    // latitude in the chart with its poles on that axis. The smallest is at most 1/sqrt 3.
    const Vec3 semi = ellipsoid_->semi_axes();
    int axis = 0;
    x.cwiseQuotient(semi).cwiseAbs().minCoeff(&axis);
    if (axis == pole_axis_) return false;
    pole_axis_ = axis;
    // Chart axis i is body axis (axis + 1 + i) mod 3: a cyclic permutation (a rotation) that
    // puts the chart's z, the poles' axis, on the body's `axis`.
    Eigen::Matrix3d frame = Eigen::Matrix3d::Zero();
    Vec3 axes;
    for (int i = 0; i < 3; ++i) {
      const int body = (axis + 1 + i) % 3;
      frame(body, i) = 1;
      axes[i] = semi[body];
    }
    use(frame, axes, std::string("chart with its poles on the ") + "xyz"[axis] + " axis");
  }
  // The same point and velocity in the new chart: c = (a cos v cos u, b cos v sin u, c sin v).
  const Vec3 y = frame_.transpose() * x;
  s = SurfaceParam(std::atan2(y.y() / axes_.y(), y.x() / axes_.x()),
                   std::asin(std::clamp(y.z() / axes_.z(), -1.0, 1.0)));
  const Mat32 J = chart_->geometry(s).jacobian;
  sdot = (J.transpose() * J).ldlt().solve(J.transpose() * w);
  return true;
}

void SurfaceCharts::wrap_longitude(SurfaceParam& s) const {
  constexpr double kPi = std::numbers::pi;
  if (ellipsoid_ && std::abs(s.x()) > kPi) s.x() = std::remainder(s.x(), 2 * kPi);
}

}  // namespace flatland::sim::detail
