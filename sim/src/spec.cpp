#include "flatland/sim/spec.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace flatland::sim {

double SimulationSpec::effective_gravity() const { return gravity * std::sin(tilt); }

double SimulationSpec::end_time() const {
  if (duration) return initial.t0 + *duration;
  return motion.kind == MotionSpec::Kind::kButterfly ? motion.period : initial.t0 + 1.0;
}

std::shared_ptr<const RollingProblem> build_problem(const SimulationSpec& spec) {
  if (!(spec.gravity > 0) || !std::isfinite(spec.gravity))
    throw std::invalid_argument("gravity.g: must be positive and finite");
  if (!(spec.tilt > 0) || !(spec.tilt <= 0.5 * std::numbers::pi + 1e-12))
    throw std::invalid_argument("gravity.tilt_deg: must be in (0, 90] degrees");
  auto pb = std::make_shared<RollingProblem>();
  auto hand = std::make_shared<PolynomialHand>(spec.hand.a, spec.hand.b, spec.hand.c, spec.hand.d);
  const ObjectSpec& o = spec.object;
  if (o.kind == ObjectSpec::Kind::kDisk) {
    pb->object =
        o.inertia ? make_disk(o.radius, o.mass, *o.inertia) : make_uniform_disk(o.radius, o.mass);
    validate_hand_for_disk(*hand, o.radius);
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
    validate_hand_for_disk(*hand, std::max(ax * ax / ay, ay * ay / ax));
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
        "contact.rolling_resistance: must be below mu_kinetic x object.radius (" +
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
