// Helpers of the planar rolling tests: the paper's hand, a problem put together from its parts,
// the paper's butterfly and an object's mechanical energy.
#pragma once

#include "flatland/sim/rolling.hpp"
#include "units.hpp"

#include <memory>
#include <utility>

namespace flatland::sim {

/// The paper's polynomial hand.
inline PolynomialHand paper_hand() { return PolynomialHand(0.18, -0.18, -0.252, 0.216); }

/// `object` rolling on `hand` moved by `motion`, under gravity `g` in the table plane.
inline std::shared_ptr<RollingProblem> problem(CurvePtr hand, RigidObject object,
                                               std::shared_ptr<const HandMotion> motion,
                                               double g = flatland_test::kG) {
  auto pb = std::make_shared<RollingProblem>();
  pb->hand = std::move(hand);
  pb->object = std::move(object);
  pb->motion = std::move(motion);
  pb->gravity = g;
  return pb;
}

/// The paper's hand playing a butterfly (period 2T, dip k) with a uniform disk of radius 5.1 cm.
inline std::shared_ptr<RollingProblem> butterfly(double period = 1.181, double k = -1.1393) {
  return problem(std::make_shared<PolynomialHand>(paper_hand()), make_uniform_disk(0.051),
                 std::make_shared<ButterflyMotion>(period, k));
}

/// Kinetic plus potential energy of `o` in sample `s` under gravity `g` (along -y).
inline double energy(const Sample& s, const RigidObject& o, double g) {
  return 0.5 * o.mass * s.object_velocity.squaredNorm() +
         0.5 * o.inertia * s.object_angular_velocity * s.object_angular_velocity +
         o.mass * g * s.object_position.y();
}

}  // namespace flatland::sim
