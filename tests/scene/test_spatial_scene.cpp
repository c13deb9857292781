// Spatial scenes (`space: 3d`): every section read into sim::SpatialSpec, the physics checked at
// load, and bad input refused with one line naming the field.
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

namespace flatland {
namespace {

const std::string kBowl = R"(space: 3d
gravity: [0, 0, -9.8]
hand:
  surface: sphere
  side: inside
  radius: 0.3
object:
  type: ball
  radius: 0.05
  mass: 0.1
motion:
  type: fixed
initial:
  s_h: [0.0, -1.0]
  velocity: [0.0, 0.5, 0.0]
duration: 2
)";

std::string with(const std::string& text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << "test bug: '" << from << "' not in the base scene";
  if (pos == std::string::npos) return text;
  std::string out = text;
  out.replace(pos, from.size(), to);
  return out;
}

std::string error_of(const std::string& yaml) {
  try {
    parse_scene(yaml, "t.yaml");
  } catch (const SceneError& e) {
    return e.what();
  }
  return "NO ERROR";
}

void expect_field_error(const std::string& yaml, const std::string& field,
                        const std::string& reason_part) {
  const std::string msg = error_of(yaml);
  EXPECT_EQ(msg.rfind("t.yaml: " + field + ": ", 0), 0u) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  EXPECT_NE(msg.find(reason_part), std::string::npos) << msg;
}

TEST(SpatialScene, EverySectionIsRead) {
  const std::string yaml = R"(name: dish
space: 3d
gravity: [0.1, 0, -9.7]
hand:
  surface: ellipsoid
  side: inside
  semi_axes: [0.3, 0.4, 0.35]
  pole_margin_deg: 20
  position: [0.01, 0.02, 0.03]
  rotation: [0, 1.5707963267948966, 0]
object:
  type: ellipsoid
  semi_axes: [0.03, 0.05, 0.04]
  mass: 0.3
  inertia: [1e-4, 2e-4, 2.5e-4]
motion:
  type: tabulated
  axis: [0, 0, 2]
  velocity: [0.1, 0, 0]
  angular_velocity: 0.5
  rows:
    - [0.0, 1, 0, 0, 0.5]
    - [0.5, 0, 0, 0, 0]
initial:
  s_h: [0.01, 0.02]
  s_o: [0.03, -0.04]
  twist_deg: 30
  velocity: [0.1, 0.2, 0.3]
  spin: 1.5
duration: 3
integrator:
  method: dop853
  rtol: 1e-9
  atol: 1e-11
  max_step: 0.01
contact:
  mu: 0.4
  stop_on_contact_loss: false
  event_tolerance: 1e-10
)";
  const Scene s = parse_scene(yaml, "t.yaml");
  ASSERT_TRUE(s.spatial.has_value());
  const sim::SpatialSpec& sp = *s.spatial;
  EXPECT_EQ(s.name, "dish");
  EXPECT_EQ(sp.gravity[0], 0.1);
  EXPECT_EQ(sp.hand.kind, sim::SurfaceSpec::Kind::kEllipsoid);
  EXPECT_TRUE(sp.hand.inside);
  EXPECT_EQ(sp.hand.semi_axes[1], 0.4);
  EXPECT_NEAR(sp.hand.pole_margin, 20 * std::numbers::pi / 180, 1e-15);
  EXPECT_EQ(sp.hand_position[2], 0.03);
  EXPECT_EQ(sp.hand_rotation[1], 1.5707963267948966);
  EXPECT_EQ(sp.object.kind, sim::SpatialObjectSpec::Kind::kEllipsoid);
  EXPECT_EQ(sp.object.mass, 0.3);
  ASSERT_TRUE(sp.object.inertia.has_value());
  EXPECT_EQ((*sp.object.inertia)[2], 2.5e-4);
  EXPECT_EQ(sp.motion.kind, sim::SpatialMotionSpec::Kind::kTabulated);
  ASSERT_EQ(sp.motion.rows.size(), 2u);
  EXPECT_EQ(sp.motion.rows[0].angular_acceleration, 0.5);
  EXPECT_EQ(sp.motion.angular_velocity, 0.5);
  EXPECT_EQ(sp.initial.s_o.y(), -0.04);
  EXPECT_NEAR(sp.initial.twist, std::numbers::pi / 6, 1e-15);
  EXPECT_EQ(sp.initial.spin, 1.5);
  EXPECT_EQ(sp.end_time(), 3);
  EXPECT_EQ(sp.integrator.method, sim::Method::kDormandPrince853);
  EXPECT_EQ(sp.integrator.max_step, 0.01);
  EXPECT_EQ(sp.mu, 0.4);
  EXPECT_FALSE(sp.stop_on_contact_loss);
  EXPECT_EQ(sp.event_tolerance, 1e-10);
}

TEST(SpatialScene, PlanarScenesMayNameTheirSpace) {
  const std::string planar =
      "space: 2d\n"
      "gravity: {g: 9.8}\n"
      "hand: {shape: polynomial, a: 0.18, b: -0.18, c: -0.252, d: 0.216}\n"
      "object: {type: disk, radius: 0.05}\n"
      "motion: {type: fixed}\n";
  EXPECT_FALSE(parse_scene(planar, "t.yaml").spatial.has_value());
  expect_field_error(with(kBowl, "space: 3d", "space: 3D"), "space", "allowed: 2d, 3d");
}

TEST(SpatialScene, BadInputNamesTheField) {
  expect_field_error(with(kBowl, "radius: 0.3", "radius: 0"), "hand.radius", "must be positive");
  expect_field_error(with(kBowl, "radius: 0.05", "radius: 0.4"), "initial",
                     "does not fit the hand's curvature");
  // A conforming contact (the ball as large as its bowl): the curvatures match, A loses rank.
  expect_field_error(with(kBowl, "radius: 0.05", "radius: 0.3"), "initial", "curvatures match");
  expect_field_error(with(kBowl, "s_h: [0.0, -1.0]", "s_h: [0.0, -1.5]"), "initial",
                     "outside the patch");
  expect_field_error(with(kBowl, "side: inside", "side: under"), "hand.side", "allowed");
  expect_field_error(with(kBowl, "side: inside", "side: inside\n  pole_margin_deg: 90"),
                     "hand.pole_margin_deg", "must be in (0, 86]");
  expect_field_error(with(kBowl, "type: fixed", "type: fixed\n  rate: 3"), "motion.rate",
                     "only for type: spin");
  expect_field_error(with(kBowl, "type: fixed", "type: tabulated\n  rows: [[0, 0, 0, 0, 0]]"),
                     "motion.rows", "at least two rows");
  expect_field_error(
      with(kBowl, "type: fixed", "type: tabulated\n  rows: [[0, 0, 0, 0, 0], [0, 1, 0, 0, 0]]"),
      "motion.rows[1][0]", "increase strictly");
  expect_field_error(with(kBowl, "type: fixed", "type: butterfly\n  period: 1\n  k: -2"), "motion",
                     "k");
  expect_field_error(with(kBowl, "gravity: [0, 0, -9.8]", "gravity: [0, -9.8]"), "gravity",
                     "list of 3 numbers");
  expect_field_error(with(kBowl, "mass: 0.1", "mass: 0.1\n  inertia: [1, 1, 3]"), "object.inertia",
                     "no rigid body");
  expect_field_error(with(kBowl, "duration: 2", "duration: 2\njoint: {}"), "joint", "unknown key");
  expect_field_error(with(kBowl, "type: ball", "type: disk"), "object.type", "allowed: ball");
  expect_field_error(with(kBowl, "duration: 2", "duration: 2\nintegrator: {rtol: -1}"),
                     "integrator.rtol", "must be in [1e-14, 0.1]");
  expect_field_error(with(kBowl, "duration: 2", "duration: 2\nintegrator: {rtol: 1.0e-300}"),
                     "integrator.rtol", "must be in [1e-14, 0.1]");
  expect_field_error(with(kBowl, "duration: 2", "duration: 2\nintegrator: {energy_tolerance: 2}"),
                     "integrator.energy_tolerance", "must be in [1e-12, 1]");
}

TEST(SpatialScene, TheBundledSpatialScenesLoad) {
  for (const char* name : {"ball-in-bowl", "ball-on-turntable", "ellipsoid-in-dish"}) {
    const Scene s = load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/" + name + ".yaml");
    EXPECT_TRUE(s.spatial.has_value()) << name;
  }
}

}  // namespace
}  // namespace flatland
