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
/// Disk with a given inertia (e.g. a ring-loaded disk), I in (0, m r^2].
RigidObject make_disk(double radius, double mass, double inertia);
/// Uniform elliptical plate with semi-axes ax, ay: I = m (ax^2 + ay^2) / 4.
RigidObject make_uniform_ellipse(double ax, double ay, double mass = 1.0);

}  // namespace flatland::sim
