// A spatial scene's simulation (`space: 3d`, docs/SCENE.md "Spatial scenes"), shaped like the
// file: the hand's surface and pose, the object, the hand's motion, where the object starts, the
// integrator and the contact. build_spatial turns it into what simulate_spatial takes, and owns
// every physical check (its messages start with the field's path, as the scene file spells it).
#pragma once

#include "flatland/sim/spatial_run.hpp"
#include "flatland/sim/spec.hpp"

#include <array>
#include <memory>
#include <optional>
#include <vector>

namespace flatland::sim {

/// The hand's surface (section `hand`), in the hand frame.
struct SurfaceSpec {
  enum class Kind { kPlane, kSphere, kEllipsoid, kExtruded };
  Kind kind = Kind::kPlane;
  /// Sphere and ellipsoid: the inside (a bowl or dish) instead of the outside (a dome).
  bool inside = false;
  double radius = 0;                  ///< m (sphere)
  std::array<double, 3> semi_axes{};  ///< m (ellipsoid, along the hand's x, y, z)
  double pole_margin = 0.2;           ///< rad, the chart's patch stops this short of its poles
  HandSpec polynomial;                ///< the paper's hand, extruded along z (extruded)
  int piece = 0;                      ///< the outline's smooth piece (extruded; 0 = the palm)
};

/// The object (section `object`): a ball or an ellipsoid, uniform unless `inertia` is given.
struct SpatialObjectSpec {
  enum class Kind { kBall, kEllipsoid };
  Kind kind = Kind::kBall;
  double radius = 0.02;                          ///< m (ball)
  std::array<double, 3> semi_axes{};             ///< m (ellipsoid)
  double mass = 1.0;                             ///< kg
  std::optional<std::array<double, 3>> inertia;  ///< kg m^2, principal, about the body axes
};

/// The hand's motion (section `motion`). The hand's pose (hand.position, hand.rotation) is its
/// pose at t = 0 for every kind.
struct SpatialMotionSpec {
  enum class Kind { kFixed, kSpin, kButterfly, kTabulated };
  Kind kind = Kind::kFixed;
  std::array<double, 3> axis{0.0, 0.0, 1.0};  ///< spin, tabulated: world direction
  double rate = 0;                            ///< rad/s (spin)
  std::array<double, 3> point{};              ///< m, a point on the spin axis (world)
  double period = 1.181, k = -1.1393;         ///< the paper's butterfly about the hand's z axis
  std::vector<TabulatedHand3::Row> rows;      ///< tabulated accelerations
  std::array<double, 3> velocity{};           ///< m/s at the table's start (tabulated)
  double angular_velocity = 0;                ///< rad/s about the axis at the table's start
};

struct SpatialSpec {
  std::array<double, 3> gravity{0.0, 0.0, -9.8};  ///< m/s^2, world
  SurfaceSpec hand;
  std::array<double, 3> hand_position{};  ///< m, the hand frame's origin at t = 0 (world)
  std::array<double, 3> hand_rotation{};  ///< rad, Rodrigues vector hand -> world at t = 0
  SpatialObjectSpec object;
  SpatialMotionSpec motion;
  ContactPlacement initial;        ///< where the object starts (at t = 0, on the hand's pose then)
  std::optional<double> duration;  ///< s; absent: 2T for the butterfly, else 1 s
  IntegratorSettings integrator;
  std::optional<double> mu;
  bool stop_on_contact_loss = true;
  double event_tolerance = 1e-12;  ///< s

  double end_time() const;
};

/// Everything simulate_spatial takes, built from a spec.
struct SpatialSetup {
  SpatialRollingProblem problem;
  std::shared_ptr<const HandMotion3> motion;
  SpatialState initial;
  double t0 = 0;
  SpatialRunOptions options;
};

/// std::invalid_argument ("field: reason") for a degenerate surface, an object that does not
/// fit the hand's curvature at the start, a start outside the patch, a rank-deficient contact,
/// bad motion or integrator values.
SpatialSetup build_spatial(const SpatialSpec& spec);

/// build_spatial, then simulate_spatial from its start (options.sample_dt as given).
SpatialRunResult run_spatial(const SpatialSetup& setup);

}  // namespace flatland::sim
