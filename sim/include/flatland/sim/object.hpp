// Rigid objects that roll on the hand: a mass, an inertia about the centre of mass and a smooth
// convex boundary curve in the object frame (centre of mass at the origin).
#pragma once

#include "flatland/sim/curve.hpp"

#include <optional>
#include <string>

namespace flatland::sim {

struct RigidObject {
  double mass = 1.0;     ///< kg; motion does not depend on it, forces scale with it
  double inertia = 0.0;  ///< kg m^2 about the centre of mass
  CurvePtr boundary;     ///< smooth convex outline, object frame, centre of mass at the origin
  /// Set when the boundary is a circle centred on the centre of mass: the reduced
  /// one-coordinate formulation applies.
  std::optional<double> disk_radius;
  std::string kind;  ///< "disk", "ellipse": for reports
};

/// Uniform disk: I = m r^2 / 2. Throws std::invalid_argument on radius <= 0 or mass <= 0.
RigidObject make_uniform_disk(double radius, double mass = 1.0);
/// A round object rolling on a circle of radius `radius` about its centre of mass, with a given
/// inertia > 0. The inertia is not bounded by m r^2 here: a ball on rails rolls on a circle
/// smaller than its own radius (ball_on_rails). The bounds of each physical description are
/// checked where it is converted (equivalent_disk in spec.hpp).
RigidObject make_disk(double radius, double mass, double inertia);
/// What the planar dynamics see of a round object: a disk rolling on a circle of `radius` about
/// its centre, turning with `inertia` about it.
struct RollingDisk {
  double radius = 0;   ///< m, rolling radius: centre to the contact, in the plane of motion
  double inertia = 0;  ///< kg m^2, about the axis normal to the plane through the centre
};

/// A ball of radius R, solid (J = 2/5 m R^2) or a thin hollow shell (J = 2/3 m R^2), riding
/// between two parallel plates `gap` apart: it touches each plate's edge where the plate's face
/// cuts it, on a circle of radius r = sqrt(R^2 - (gap/2)^2) about the axis normal to the plates,
/// so it rolls as a disk of radius r that keeps the ball's own inertia (above m r^2 once
/// gap > 2 sqrt(3/5) R, solid). Throws std::invalid_argument naming the field
/// (object.radius, object.rails.gap, object.mass) for a non-positive or non-finite value or a gap
/// of at least the ball's diameter.
RollingDisk ball_on_rails(double radius, double gap, double mass, bool hollow);

/// Uniform elliptical plate with semi-axes ax, ay: I = m (ax^2 + ay^2) / 4.
RigidObject make_uniform_ellipse(double ax, double ay, double mass = 1.0);

}  // namespace flatland::sim
