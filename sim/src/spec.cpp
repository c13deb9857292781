#include "flatland/sim/spec.hpp"
#include "flatland/sim/format.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace flatland::sim {

double SimulationSpec::effective_gravity() const { return gravity * std::sin(tilt); }

double SimulationSpec::end_time() const {
  if (duration) return initial.t0 + *duration;
  return motion.kind == MotionSpec::Kind::kButterfly ? motion.period : initial.t0 + 1.0;
}

namespace {

const char* kind_name(ObjectSpec::Kind kind) {
  switch (kind) {
    case ObjectSpec::Kind::kDisk:
      return "disk";
    case ObjectSpec::Kind::kRing:
      return "ring";
    case ObjectSpec::Kind::kBall:
      return "ball";
    case ObjectSpec::Kind::kEllipse:
      break;
  }
  return "ellipse";
}

void require_positive(double value, const char* field) {
  if (!(value > 0) || !std::isfinite(value))
    throw std::invalid_argument(std::string(field) + ": must be positive and finite, got " +
                                format_significant(value));
}

// The given inertia against what a body of the description can have: its mass lies within
// `outer` of the centre (J <= m outer^2) and, for a ring, not inside `inner` (J >= m inner^2).
void check_inertia_bounds(const ObjectSpec& o, double inner, double outer) {
  const double J = *o.inertia, m = o.mass;
  require_positive(J, "object.inertia");
  const std::string body =
      std::string("a ") + kind_name(o.kind) + " of mass " + format_significant(m) + " kg";
  // A relative slack of 1e-12: the bound itself (a thin ring) is a body one can describe.
  if (J > m * outer * outer * (1 + 1e-12))
    throw std::invalid_argument(
        "object.inertia: " + body + " within " + format_significant(outer) +
        " m of its centre has at most m R^2 = " + format_significant(m * outer * outer) +
        " kg m^2, got " + format_significant(J));
  if (J < m * inner * inner * (1 - 1e-12))
    throw std::invalid_argument(
        "object.inertia: " + body + " with no mass inside " + format_significant(inner) +
        " m has at least m R_i^2 = " + format_significant(m * inner * inner) + " kg m^2, got " +
        format_significant(J));
}

}  // namespace

double ObjectSpec::seen_radius() const {
  if (!round()) throw std::logic_error("ObjectSpec::seen_radius: an ellipse has no radius");
  return radius;
}

RollingDisk equivalent_disk(const ObjectSpec& o) {
  if (!o.round()) throw std::logic_error("equivalent_disk: an ellipse is no disk");
  require_positive(o.radius, "object.radius");
  require_positive(o.mass, "object.mass");
  const double R = o.radius, m = o.mass;
  RollingDisk disk{R, 0.5 * m * R * R};
  double inner = 0;
  switch (o.kind) {
    case ObjectSpec::Kind::kRing:
      inner = o.inner_radius;
      require_positive(inner, "object.inner_radius");
      if (!(inner < R))
        throw std::invalid_argument("object.inner_radius: must be below object.radius (" +
                                    format_significant(R) + " m), got " +
                                    format_significant(inner));
      disk.inertia = 0.5 * m * (R * R + inner * inner);
      break;
    case ObjectSpec::Kind::kBall:
      if (o.rail_gap)
        disk = ball_on_rails(R, *o.rail_gap, m, o.hollow);
      else
        disk.inertia = (o.hollow ? 2.0 / 3.0 : 0.4) * m * R * R;
      break;
    default:
      break;
  }
  if (o.inertia) {
    check_inertia_bounds(o, inner, R);
    disk.inertia = *o.inertia;
  }
  return disk;
}

const char* to_string(HandSpec::Shape shape) {
  switch (shape) {
    case HandSpec::Shape::kPolynomial:
      return "polynomial";
    case HandSpec::Shape::kLine:
      return "line";
    case HandSpec::Shape::kCircle:
      return "circle";
    case HandSpec::Shape::kPoints:
      return "points";
    case HandSpec::Shape::kPolar:
      return "polar";
  }
  return "unknown";
}

HandPtr build_hand(const HandSpec& spec) {
  switch (spec.shape) {
    case HandSpec::Shape::kPolynomial:
      return std::make_shared<PolynomialHand>(spec.a, spec.b, spec.c, spec.d);
    case HandSpec::Shape::kLine:
      if (!std::isfinite(spec.line_angle))
        throw std::invalid_argument("hand.angle_deg: must be finite");
      if (!spec.line_origin.allFinite()) throw std::invalid_argument("hand.origin: must be finite");
      return std::make_shared<LineCurve>(
          spec.line_origin, Vec2(std::cos(spec.line_angle), std::sin(spec.line_angle)));
    case HandSpec::Shape::kCircle:
      if (!(spec.well_radius > 0) || !std::isfinite(spec.well_radius))
        throw std::invalid_argument("hand.radius: must be positive and finite, got " +
                                    format_significant(spec.well_radius));
      if (!spec.well_center.allFinite()) throw std::invalid_argument("hand.center: must be finite");
      return std::make_shared<CircleWellHand>(spec.well_center, spec.well_radius);
    case HandSpec::Shape::kPoints:
      return make_points_hand(spec.points);
    case HandSpec::Shape::kPolar:
      return make_polar_hand(spec.polar);
  }
  throw std::logic_error("build_hand: unknown hand shape");
}

void require_palm_and_back(const HandSpec& spec, const Curve& hand, const std::string& needed_by) {
  const auto* h = dynamic_cast<const HandCurve*>(&hand);
  if (h && h->has_palm_and_back()) return;
  throw std::invalid_argument(std::string("hand.shape: ") + to_string(spec.shape) + " (" +
                              hand.describe() + ") has no palm and back wells (s_h = -1 and +1), " +
                              "which " + needed_by +
                              " needs; simulate and render take any hand shape");
}

namespace {
// The checks of the hand against the object: a disk of `radius` (the largest radius of curvature
// of the object's boundary, for an ellipse) must fit every concave part of the outline.
void validate_hand_for_object(const HandSpec& spec, const HandCurve& hand, double radius) {
  switch (spec.shape) {
    case HandSpec::Shape::kPolynomial:
    case HandSpec::Shape::kPoints:
    case HandSpec::Shape::kPolar:
      validate_hand_for_disk(hand, radius);
      return;
    case HandSpec::Shape::kLine:
      if (!(radius > 0) || !std::isfinite(radius))
        throw std::invalid_argument("object.radius: must be positive and finite, got " +
                                    format_significant(radius));
      return;  // a straight edge has no concave part
    case HandSpec::Shape::kCircle:
      if (!(radius > 0) || !std::isfinite(radius))
        throw std::invalid_argument("object.radius: must be positive and finite, got " +
                                    format_significant(radius));
      if (!(radius < spec.well_radius))
        throw std::invalid_argument(
            "hand.radius: the well (radius " + format_significant(spec.well_radius) +
            " m) must be wider than the object (radius of curvature up to " +
            format_significant(radius) + " m), which rolls inside it");
      return;
  }
}
}  // namespace

std::shared_ptr<const RollingProblem> build_problem(const SimulationSpec& spec) {
  if (!(spec.gravity > 0) || !std::isfinite(spec.gravity))
    throw std::invalid_argument("gravity.g: must be positive and finite");
  if (!(spec.tilt > 0) || !(spec.tilt <= 0.5 * std::numbers::pi + 1e-12))
    throw std::invalid_argument("gravity.tilt_deg: must be in (0, 90] degrees");
  auto pb = std::make_shared<RollingProblem>();
  const HandPtr hand = build_hand(spec.hand);
  const ObjectSpec& o = spec.object;
  if (o.round()) {
    const RollingDisk disk = equivalent_disk(o);
    pb->object = make_disk(disk.radius, o.mass, disk.inertia);
    pb->object.kind = kind_name(o.kind);
    validate_hand_for_object(spec.hand, *hand, disk.radius);
  } else {
    pb->object = make_uniform_ellipse(o.semi_axis_x, o.semi_axis_y, o.mass);
    if (o.inertia) {
      if (!(*o.inertia > 0) || !std::isfinite(*o.inertia))
        throw std::invalid_argument("object.inertia: must be positive and finite");
      pb->object.inertia = *o.inertia;
    }
    // An ellipse touches the hand with its flattest part at most; check with its largest
    // radius of curvature, max(ax^2/ay, ay^2/ax).
    const double ax = o.semi_axis_x, ay = o.semi_axis_y;
    validate_hand_for_object(spec.hand, *hand, std::max(ax * ax / ay, ay * ay / ax));
  }
  pb->hand = hand;
  if (spec.motion.kind == MotionSpec::Kind::kButterfly)
    pb->motion = std::make_shared<ButterflyMotion>(spec.motion.period, spec.motion.k);
  else
    pb->motion = std::make_shared<FixedHand>(spec.motion.angle);
  pb->gravity = spec.effective_gravity();
  spec.contact.validate();
  pb->contact = spec.contact;
  const ContactLaw& law = spec.contact;
  if (law.rolling_resistance > 0 && pb->object.disk_radius && law.mu &&
      !(law.rolling_resistance < law.kinetic() * *pb->object.disk_radius))
    throw std::invalid_argument(
        "contact.rolling_resistance: must be below mu_kinetic x the rolling radius (" +
        std::to_string(law.kinetic() * *pb->object.disk_radius) +
        " m): a larger couple than friction's could hold a sliding disk's rotation");
  if (spec.run.model == ContactModel::kRolling && spec.contact.has_losses())
    throw std::invalid_argument(
        "contact.model: the losses (rolling_resistance, drag, drag_angular) need model: hybrid "
        "(the rolling model is the paper's lossless simulation)");
  return pb;
}

SimulationSpec paper_model(const SimulationSpec& spec) {
  SimulationSpec s = spec;
  s.run.model = ContactModel::kRolling;
  s.contact.rolling_resistance = 0;
  s.contact.drag = 0;
  s.contact.drag_angular = 0;
  return s;
}

RunOptions run_options(const SimulationSpec& spec) {
  RunOptions o = spec.run;
  o.t_end = spec.end_time();
  return o;
}

RunResult run_spec(const SimulationSpec& spec) {
  return simulate(build_problem(spec), spec.initial, run_options(spec));
}

}  // namespace flatland::sim
