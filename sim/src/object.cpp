#include "flatland/sim/object.hpp"

#include <cmath>
#include <stdexcept>

namespace flatland::sim {

namespace {
void check_positive(double v, const char* field) {
  if (!(v > 0) || !std::isfinite(v))
    throw std::invalid_argument(std::string(field) + ": must be positive and finite, got " +
                                std::to_string(v));
}
}  // namespace

RigidObject make_disk(double radius, double mass, double inertia) {
  check_positive(radius, "object.radius");
  check_positive(mass, "object.mass");
  check_positive(inertia, "object.inertia");
  if (inertia > mass * radius * radius * (1 + 1e-12))
    throw std::invalid_argument("object.inertia: a disk's inertia cannot exceed m r^2 (a ring)");
  RigidObject o;
  o.mass = mass;
  o.inertia = inertia;
  o.boundary = std::make_shared<CircleCurve>(Vec2::Zero(), radius, CircleCurve::Side::kConvexBody);
  o.disk_radius = radius;
  o.kind = "disk";
  return o;
}

RigidObject make_uniform_disk(double radius, double mass) {
  check_positive(radius, "object.radius");
  check_positive(mass, "object.mass");
  return make_disk(radius, mass, 0.5 * mass * radius * radius);
}

RigidObject make_uniform_ellipse(double ax, double ay, double mass) {
  check_positive(ax, "object.semi_axes[0]");
  check_positive(ay, "object.semi_axes[1]");
  check_positive(mass, "object.mass");
  RigidObject o;
  o.mass = mass;
  o.inertia = 0.25 * mass * (ax * ax + ay * ay);
  o.boundary = std::make_shared<EllipseCurve>(ax, ay);
  o.kind = "ellipse";
  return o;
}

}  // namespace flatland::sim
