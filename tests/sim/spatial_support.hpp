// Helpers of the spatial rolling tests: a ball placed in rolling contact on a hand.
#pragma once

#include "flatland/sim/spatial_run.hpp"

#include <Eigen/Dense>

namespace flatland::sim {

/// A ball of radius r resting on (or rolling over) the hand at the contact s_h, its centre moving
/// at v (tangent to the hand), no spin about the normal; the rates of the contact coordinates
/// roughly right (the run's first projection makes the state consistent).
inline SpatialState ball_on(const SpatialRollingProblem& pb, const HandPose3& hand, double r,
                            const SurfaceParam& s_h, const Vec3& v, double contact_speed_factor) {
  const SurfaceGeometry gh = pb.hand->geometry(s_h);
  const Vec3 nh = hand.rotation * gh.normal;
  const Vec3 contact = hand.position + hand.rotation * gh.point;
  SpatialState s;
  s.s_h = s_h;
  s.position = contact + r * nh;
  // The ball's chart puts its (0, 0) point, body +x, at the contact.
  s.orientation = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitX(), -nh);
  s.velocity = v;
  const Vec3 ro = -r * nh;
  const Vec3 Vh = hand.velocity + hand.angular_velocity.cross(contact - hand.position);
  // Rolling: v + omega x r_o = the hand's velocity there; omega's normal part 0.
  s.angular_velocity = (v - Vh).cross(ro) / (r * r);
  const Vec3 w = contact_speed_factor * (v - Vh);  // the contact point over both surfaces
  const Mat32 Jh = hand.rotation * gh.jacobian;
  s.sdot_h = (Jh.transpose() * Jh).ldlt().solve(Jh.transpose() * w);
  const SurfaceGeometry go = pb.object.surface->geometry(SurfaceParam::Zero());
  const Mat32 Jo = s.orientation.toRotationMatrix() * go.jacobian;
  s.sdot_o = (Jo.transpose() * Jo).ldlt().solve(Jo.transpose() * w);
  return s;
}

}  // namespace flatland::sim
