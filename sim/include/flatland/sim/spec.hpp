// Plain description of one simulation: what a scene file's simulator part says, in SI units.
// The scene loader (scene/) fills it; sim turns it into a RollingProblem.
#pragma once

#include "flatland/sim/simulate.hpp"

#include <numbers>
#include <optional>

namespace flatland::sim {

struct HandSpec {
  // The paper's polynomial hand (section 4.1), metres; e and f are derived.
  double a = 0.18, b = -0.18, c = -0.252, d = 0.216;
};

struct ObjectSpec {
  enum class Kind { kDisk, kEllipse };
  Kind kind = Kind::kDisk;
  double radius = 0.051;                    ///< m (disk)
  double semi_axis_x = 0, semi_axis_y = 0;  ///< m (ellipse)
  double mass = 1.0;                        ///< kg
  std::optional<double> inertia;            ///< kg m^2; default: uniform plate
};

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
