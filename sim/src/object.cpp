#include "flatland/sim/object.hpp"
#include "flatland/sim/format.hpp"

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

RollingDisk ball_on_rails(double radius, double gap, double mass, bool hollow) {
  check_positive(radius, "object.radius");
  check_positive(gap, "object.rails.gap");
  check_positive(mass, "object.mass");
  if (!(gap < 2 * radius))
    throw std::invalid_argument("object.rails.gap: larger than the ball's diameter (" +
                                format_significant(2 * radius) + " m), got " +
                                format_significant(gap) + " m: the ball falls through");
  const double half_gap = 0.5 * gap;
  // (R - g/2)(R + g/2) rather than R^2 - (g/2)^2: no cancellation when the gap nears 2R.
  const double rolling_radius = std::sqrt((radius - half_gap) * (radius + half_gap));
  const double shape_factor = hollow ? 2.0 / 3.0 : 0.4;
  return {rolling_radius, shape_factor * mass * radius * radius};
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
