// The charts a spatial run moves a contact between (spatial_run.cpp). An ellipsoid's or a sphere's
// chart by longitude and latitude is singular at its two poles, and a contact that rolls for long
// reaches them: the run then carries the contact into another chart of the same surface in which
// it lies far from the poles. Internal to sim/.
#pragma once

#include "flatland/sim/surface.hpp"

#include <Eigen/Core>

#include <string>

namespace flatland::sim::detail {

/// A run changes chart after a step that leaves the contact more than this far from the chart's
/// equator (rad of latitude: 0.57 rad short of a pole), when another chart has it nearer its own.
/// A patch narrower than that (a pole margin above 0.57 rad) ends the run where the contact
/// leaves it instead: the surface was cut off there.
inline constexpr double kSwitchLatitude = 1.0;

/// One surface's charts and the one in use. Three kinds:
///  - a surface with no other chart here (a plane, an extruded curve, a surface of revolution,
///    whose patch is one piece of its outline or profile): its own;
///  - a ball (a sphere with `turn_a_sphere_freely`: the object's side): the sphere in any turned
///    frame. A change puts the contact at the new chart's (0, 0) with its path over the ball
///    along the equator, where the coordinates are the smoothest and the poles the farthest (a
///    ball rolling straight on keeps its chart for ever);
///  - any other ellipsoid (an ellipsoid object, a bowl or dish, a dome): three charts, the
///    ellipsoid with its poles on the body's x, y or z axis (the chart's semi-axes permuted
///    cyclically, in the frame that permutation turns to); a change picks the chart whose poles
///    are farthest from the contact, where its latitude is at most asin(1/sqrt 3) = 0.62 rad.
/// Chart 0 of each is the surface itself (the scene's chart, where a run starts). A sphere hand
/// keeps to the three axis charts, whose coordinates (the outputs' s_h) a reader can follow.
class SurfaceCharts {
 public:
  SurfaceCharts(SurfacePtr surface, bool turn_a_sphere_freely);

  /// The surface in the chart in use, in the body's (or the hand's) frame.
  const SurfacePtr& chart() const { return chart_; }

  /// If the contact at s is past kSwitchLatitude and another chart has it nearer its equator,
  /// changes to that chart and gives the same point and velocity over the surface there: s and
  /// sdot are rewritten. Returns whether the chart changed.
  bool update(SurfaceParam& s, SurfaceParam& sdot);

  /// The longitude back into [-pi, pi] (the same point in the same chart). One that winds up (a
  /// contact circling a pole, or running along a spinning ball's equator: 2.4e4 rad in 20 s on
  /// the inclined turntable) keeps only ulp(u) of absolute precision (4e-12 rad there), below
  /// which the projection cannot place the contact: its residual grew to 9e-11 (6e-14 wrapped).
  void wrap_longitude(SurfaceParam& s) const;

 private:
  /// Makes the chart whose frame (chart -> body) is `frame`, with the ellipsoid's semi-axes
  /// `axes` in that chart; `what` says which chart in the surface's description.
  void use(const Eigen::Matrix3d& frame, const Vec3& axes, const std::string& what);

  SurfacePtr surface_;
  const EllipsoidSurface* ellipsoid_ = nullptr;  ///< surface_ as an ellipsoid, if it is one
  bool turn_freely_ = false;
  int pole_axis_ = 2;  ///< the body axis the poles lie on (three charts)
  Eigen::Matrix3d frame_ = Eigen::Matrix3d::Identity();
  Vec3 axes_ = Vec3::Ones();  ///< the chart's semi-axes (a, b, c)
  SurfacePtr chart_;
};

}  // namespace flatland::sim::detail
