// Plain description of one simulation: what a scene file's simulator part says, in SI units.
// The scene loader (scene/) fills it; sim turns it into a RollingProblem.
#pragma once

#include "flatland/sim/object.hpp"
#include "flatland/sim/hand_shapes.hpp"
#include "flatland/sim/simulate.hpp"

#include <numbers>
#include <optional>

namespace flatland::sim {

struct HandSpec {
  /// The outline (scene `hand.shape`); each shape reads its own fields below.
  enum class Shape { kPolynomial, kLine, kCircle, kPoints, kPolar };
  Shape shape = Shape::kPolynomial;
  // The paper's polynomial hand (section 4.1), metres; e and f are derived.
  double a = 0.18, b = -0.18, c = -0.252, d = 0.216;
  // A line (an incline): through `line_origin` (m, hand frame), along the direction at
  // `line_angle` (rad, counter-clockwise from the hand's +x); the object rolls on the side the
  // direction turned +90 degrees points to (above it for |line_angle| < 90 degrees).
  Vec2 line_origin = Vec2::Zero();
  double line_angle = 0;
  // A circular well: the object rolls inside the circle of radius `well_radius` (m) about
  // `well_center` (m, hand frame); s_h is the angle from the well's bottom.
  double well_radius = 0.2;
  Vec2 well_center = Vec2::Zero();
  /// A measured outline (make_points_hand): the points themselves, read from the scene's
  /// `hand.file` when the scene is loaded, so that a spec never reads a file again.
  PointsHandSpec points;
  /// A polar frame r(phi) (make_polar_hand).
  PolarHandSpec polar;
};

/// The scene's word for a shape: "polynomial", "line", "circle", "points", "polar".
const char* to_string(HandSpec::Shape shape);

/// The rolling object's physical description (the scene's `object`); build_problem converts it
/// into the rigid object the dynamics see (equivalent_disk for the round ones).
struct ObjectSpec {
  enum class Kind {
    kDisk,     ///< a plate of radius `radius`
    kRing,     ///< an annulus: outer radius `radius`, inner radius `inner_radius`
    kBall,     ///< a ball of radius `radius`, on the hand's edge or on two rails (`rail_gap`)
    kEllipse,  ///< an elliptical plate
  };
  Kind kind = Kind::kDisk;
  double radius = 0.051;                    ///< m: disk radius, ring's outer, ball's radius
  double inner_radius = 0;                  ///< m (ring), < radius
  bool hollow = false;                      ///< ball: a thin shell rather than solid
  std::optional<double> rail_gap;           ///< m (ball): rides on two parallel rails this apart
  double semi_axis_x = 0, semi_axis_y = 0;  ///< m (ellipse)
  double mass = 1.0;                        ///< kg
  /// kg m^2 about the centre; default: the uniform body of the description
  std::optional<double> inertia;

  /// Disk, ring or ball: rolls on a circle about its centre (the reduced formulation applies).
  bool round() const { return kind != Kind::kEllipse; }
  /// Radius of the outline a camera looking along the plane's normal sees: the disk's or ring's
  /// outer radius, the ball's own radius R (also on rails). Ellipse: std::logic_error.
  double seen_radius() const;
};

/// A round object's description as the planar dynamics see it: the rolling radius (the ball on
/// rails: sqrt(R^2 - (gap/2)^2), else `radius`) and the inertia about the centre (given, or the
/// uniform body's: disk m R^2/2, ring m (R^2 + R_i^2)/2, ball 2/5 m R^2, hollow 2/3 m R^2). A
/// given inertia is checked against what a body of that description can have: J > 0 for all,
/// J <= m R^2 (mass within R of the centre; R the outer or the ball's radius, not the rolling
/// radius), J >= m R_i^2 for a ring (no mass inside its hole). Throws std::invalid_argument naming
/// the field; std::logic_error for an ellipse.
RollingDisk equivalent_disk(const ObjectSpec& object);
struct MotionSpec {
  enum class Kind { kButterfly, kFixed };
  Kind kind = Kind::kButterfly;
  double period = 1.181;  ///< 2T, s (butterfly)
  double k = -1.1393;     ///< dip parameter (butterfly)
  double angle = 0.0;     ///< rad (fixed)
};

struct SimulationSpec {
  double gravity = 9.8;                  ///< m/s^2
  double tilt = 0.5 * std::numbers::pi;  ///< rad, table tilt; pi/2 = vertical plane (full g)
  HandSpec hand;
  ObjectSpec object;
  MotionSpec motion;
  InitialContact initial;
  std::optional<double> duration;  ///< s; default: the butterfly's period, else 1 s
  ContactLaw contact;              ///< friction, restitution, losses (scene `contact`)
  RunOptions run;  ///< integrator, formulation, events, contact model (run.t_end is derived)

  /// g sin(tilt): gravity in the table plane.
  double effective_gravity() const;
  /// Simulated time span: `duration` or the default above.
  double end_time() const;
};

/// The hand's outline of a spec (no check against the object; build_problem does that). Throws
/// std::invalid_argument naming the field for values no outline has (a non-positive radius).
HandPtr build_hand(const HandSpec& spec);

/// Refuses a hand without the butterfly's palm and back wells (HandCurve::has_palm_and_back: a
/// line, a circular well): `needed_by` (a command, "the closed loop's plan") starts in the palm
/// and ends in the back. Throws std::invalid_argument naming hand.shape, one line.
void require_palm_and_back(const HandSpec& spec, const Curve& hand, const std::string& needed_by);

/// Build (and validate) the problem: checks the hand shape for a disk (validate_hand_for_disk),
/// positive radius/mass, the motion's parameters. Throws std::invalid_argument naming the field.
std::shared_ptr<const RollingProblem> build_problem(const SimulationSpec& spec);
/// spec.run with t_end set from end_time().
RunOptions run_options(const SimulationSpec& spec);
/// The paper's model of a spec: the rolling model without losses (mu is kept, for the friction
/// margins it reports). The design searches and the closed loop's plan use it: the losses break
/// the time symmetry the searches rely on, and the paper planned without them.
SimulationSpec paper_model(const SimulationSpec& spec);
/// build_problem + simulate.
RunResult run_spec(const SimulationSpec& spec);

}  // namespace flatland::sim
