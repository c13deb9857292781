// Scene loading: the bundled scenes carry the paper's values in SI units, defaults are applied,
// and every kind of bad input is a one-line SceneError naming the field.
#include "flatland/scene/scene.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/spec.hpp"
#include "scene/minimal_scene.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>

#include <unistd.h>

namespace {

using flatland::parse_scene;
using flatland::Scene;
using flatland::SceneError;
namespace sim = flatland::sim;

constexpr double kPi = std::numbers::pi;

// A complete, valid scene; error tests perturb one line of it.
const std::string kBase = R"(name: test
gravity:
  g: 9.8
  tilt_deg: 90
hand:
  shape: polynomial
  a: 0.18
  b: -0.18
  c: -0.252
  d: 0.216
object:
  type: disk
  radius: 0.051
  mass: 1.0
motion:
  type: butterfly
  period: 1.181
  k: -1.1393
initial:
  s_h: -1
  sdot_h: 0
duration: 1.181
integrator:
  method: dopri5
  rtol: 1.0e-10
  atol: 1.0e-12
  formulation: auto
contact:
  stop_on_contact_loss: true
  event_tolerance: 1.0e-12
)";

const std::string kHandSection =
    "hand:\n  shape: polynomial\n  a: 0.18\n  b: -0.18\n  c: -0.252\n  d: 0.216\n";

using flatland_test::kMinimal;  // the minimum a scene must say

/// `text` with the first occurrence of `from` replaced; fails the test if `from` is absent, so a
/// perturbation can never silently become a no-op.
std::string with(const std::string& text, const std::string& from, const std::string& to) {
  const auto pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << "test bug: '" << from << "' not in the base scene";
  if (pos == std::string::npos) return text;
  std::string out = text;
  out.replace(pos, from.size(), to);
  return out;
}

std::string error_of(const std::string& yaml, const std::string& origin = "t.yaml") {
  try {
    parse_scene(yaml, origin);
  } catch (const SceneError& e) {
    return e.what();
  } catch (const std::exception& e) {
    return std::string("WRONG EXCEPTION TYPE: ") + e.what();
  }
  return "NO ERROR";
}

/// The error is one line and starts with "t.yaml: <field>: ".
void expect_field_error(const std::string& yaml, const std::string& field,
                        const std::string& reason_part = "") {
  const std::string msg = error_of(yaml);
  EXPECT_EQ(msg.rfind("t.yaml: " + field + ": ", 0), 0u) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  if (!reason_part.empty()) {
    EXPECT_NE(msg.find(reason_part), std::string::npos) << msg;
  }
}

// --------------------------------------------------------------------------------------------
// Bundled scenes

// Found at run time beside the program (build/bin/../share/flatland links to assets/), never
// through a path compiled in from the source tree.
TEST(SceneTest, DefaultScenePathIsTheButterfly) {
  namespace fs = std::filesystem;
  ASSERT_EQ(std::getenv("FLATLAND_DATA_DIR"), nullptr) << "the test sets it itself";
  const std::string p = flatland::default_scene_path();
  EXPECT_TRUE(fs::equivalent(p, std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly.yaml")) << p;
  const fs::path self = fs::read_symlink("/proc/self/exe");
  EXPECT_EQ(fs::path(flatland::data_directory()),
            (self.parent_path() / ".." / "share" / "flatland").lexically_normal());
}

TEST(SceneTest, DataDirectoryFromTheEnvironmentComesFirst) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("flatland_data_" + std::to_string(::getpid()));
  fs::create_directories(dir / "scenes");
  std::ofstream(dir / "scenes" / "butterfly.yaml") << "name: x\n";
  ::setenv("FLATLAND_DATA_DIR", dir.c_str(), 1);
  const std::string found = flatland::data_directory();
  // Without a butterfly.yaml the environment's directory is passed over.
  fs::remove(dir / "scenes" / "butterfly.yaml");
  const std::string passed_over = flatland::data_directory();
  ::unsetenv("FLATLAND_DATA_DIR");
  fs::remove_all(dir);
  EXPECT_EQ(found, dir.string());
  EXPECT_NE(passed_over, dir.string());
  EXPECT_TRUE(fs::exists(fs::path(passed_over) / "scenes" / "butterfly.yaml")) << passed_over;
}

TEST(SceneTest, ButterflySceneHasThePapersValuesInSI) {
  const std::string path = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly.yaml";
  const Scene s = flatland::load_scene(path);
  EXPECT_EQ(s.origin, path);
  EXPECT_EQ(s.name, "paper-butterfly");
  const sim::SimulationSpec& sp = s.sim;
  EXPECT_DOUBLE_EQ(sp.gravity, 9.8);
  EXPECT_NEAR(sp.tilt, kPi / 2, 1e-15);
  EXPECT_DOUBLE_EQ(sp.effective_gravity(), 9.8);
  // Section 4.1 in cm -> m.
  EXPECT_DOUBLE_EQ(sp.hand.a, 0.18);
  EXPECT_DOUBLE_EQ(sp.hand.b, -0.18);
  EXPECT_DOUBLE_EQ(sp.hand.c, -0.252);
  EXPECT_DOUBLE_EQ(sp.hand.d, 0.216);
  EXPECT_EQ(sp.object.kind, sim::ObjectSpec::Kind::kDisk);
  EXPECT_DOUBLE_EQ(sp.object.radius, 0.051);
  EXPECT_DOUBLE_EQ(sp.object.mass, 1.0);
  EXPECT_FALSE(sp.object.inertia.has_value());
  EXPECT_EQ(sp.motion.kind, sim::MotionSpec::Kind::kButterfly);
  EXPECT_DOUBLE_EQ(sp.motion.period, 1.181);
  EXPECT_DOUBLE_EQ(sp.motion.k, -1.1393);
  EXPECT_DOUBLE_EQ(sp.initial.s_h, -1.0);
  EXPECT_DOUBLE_EQ(sp.initial.sdot_h, 0.0);
  EXPECT_FALSE(sp.initial.s_o.has_value());
  ASSERT_TRUE(sp.duration.has_value());
  EXPECT_DOUBLE_EQ(*sp.duration, 1.181);
  EXPECT_EQ(sp.run.integrator.method, sim::Method::kDormandPrince54);
  EXPECT_DOUBLE_EQ(sp.run.integrator.rtol, 1e-10);
  EXPECT_DOUBLE_EQ(sp.run.integrator.atol, 1e-12);
  EXPECT_EQ(sp.run.formulation, sim::Formulation::kAuto);
  EXPECT_TRUE(sp.run.events.stop_on_contact_loss);
  EXPECT_FALSE(sp.contact.mu.has_value());
  EXPECT_DOUBLE_EQ(sp.run.events.time_tolerance, 1e-12);

  // e and f are derived from the loaded a..d (paper: e = 7.2 cm, f = -9.36 cm).
  const auto problem = sim::build_problem(sp);
  const auto* hand = dynamic_cast<const sim::PolynomialHand*>(problem->hand.get());
  ASSERT_NE(hand, nullptr);
  EXPECT_NEAR(hand->e(), 0.072, 1e-15);
  EXPECT_NEAR(hand->f(), -0.0936, 1e-15);
}

TEST(SceneTest, AirTableSceneIsTheButterflyTimeScaledTo5Degrees) {
  const Scene s =
      flatland::load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-5deg.yaml");
  const sim::SimulationSpec& sp = s.sim;
  EXPECT_NEAR(sp.tilt, 5.0 * kPi / 180.0, 1e-15);
  EXPECT_NEAR(sp.effective_gravity(), 9.8 * std::sin(5.0 * kPi / 180.0), 1e-12);
  EXPECT_DOUBLE_EQ(sp.object.radius, 0.051);
  EXPECT_DOUBLE_EQ(sp.hand.c, -0.252);
  EXPECT_DOUBLE_EQ(sp.hand.d, 0.216);
  EXPECT_DOUBLE_EQ(sp.motion.k, -1.1393);
  EXPECT_DOUBLE_EQ(sp.motion.period, 4.0);
  // Section 5: 2T = kappa * 1.181 s, kappa = sqrt(1 / sin 5 deg), rounded to 4.0 s in the paper.
  const double kappa = std::sqrt(1.0 / std::sin(5.0 * kPi / 180.0));
  EXPECT_NEAR(kappa, 3.387, 5e-4);
  EXPECT_NEAR(sp.motion.period, kappa * 1.181, 0.01);
  EXPECT_DOUBLE_EQ(sp.end_time(), 4.0);
}

TEST(SceneTest, CameraSceneIsTheAirTableButterflySeenByThePapersCamera) {
  const Scene s =
      flatland::load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml");
  const sim::SimulationSpec& sp = s.sim;
  EXPECT_NEAR(sp.tilt, 5.0 * kPi / 180.0, 1e-15);
  EXPECT_DOUBLE_EQ(sp.motion.period, 4.0);
  EXPECT_DOUBLE_EQ(sp.motion.k, -1.1393);
  EXPECT_DOUBLE_EQ(sp.object.radius, 0.051);
  ASSERT_TRUE(s.camera.has_value());
  const flatland::CameraSpec& c = *s.camera;
  // Section 5: a 30 Hz vision system; 640 x 480 images.
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);
  EXPECT_DOUBLE_EQ(c.fps, 30.0);
  EXPECT_EQ(c.fx, c.fy);
  // About 1.2 m straight above the pivot, looking down at it.
  EXPECT_EQ(c.position, (std::array<double, 3>{0.0, 0.0, 1.2}));
  EXPECT_EQ(c.look_at, (std::array<double, 3>{0.0, 0.0, 0.0}));
  // Pinhole projection of the table points +-0.3 m around the pivot: all inside the image.
  for (double x : {-0.3, 0.3})
    for (double y : {-0.3, 0.3}) {
      const double u = c.cx + c.fx * x / c.position[2];
      const double v = c.cy - c.fy * y / c.position[2];
      EXPECT_GE(u, -0.5);
      EXPECT_LE(u, c.width - 0.5);
      EXPECT_GE(v, -0.5);
      EXPECT_LE(v, c.height - 0.5);
    }
  EXPECT_EQ(s.render.backend, "osmesa");
  EXPECT_EQ(s.render.view, "overhead");
}

// --------------------------------------------------------------------------------------------
// Defaults and variants

TEST(SceneTest, MinimalSceneGetsDefaults) {
  const Scene s = parse_scene(kMinimal);
  EXPECT_EQ(s.origin, "<string>");
  EXPECT_EQ(s.name, "");
  const sim::SimulationSpec& sp = s.sim;
  EXPECT_DOUBLE_EQ(sp.tilt, kPi / 2);
  EXPECT_DOUBLE_EQ(sp.object.mass, 1.0);
  EXPECT_FALSE(sp.object.inertia.has_value());
  EXPECT_DOUBLE_EQ(sp.initial.s_h, -1.0);
  EXPECT_DOUBLE_EQ(sp.initial.sdot_h, 0.0);
  EXPECT_DOUBLE_EQ(sp.initial.object_angle, 0.0);
  EXPECT_FALSE(sp.initial.s_o.has_value());
  EXPECT_FALSE(sp.duration.has_value());
  EXPECT_DOUBLE_EQ(sp.end_time(), 1.181);  // the butterfly's period
  EXPECT_EQ(sp.run.integrator.method, sim::Method::kDormandPrince54);
  EXPECT_DOUBLE_EQ(sp.run.integrator.rtol, 1e-10);
  EXPECT_DOUBLE_EQ(sp.run.integrator.atol, 1e-12);
  EXPECT_DOUBLE_EQ(sp.run.integrator.fixed_step, 1e-3);
  EXPECT_TRUE(std::isinf(sp.run.integrator.max_step));
  EXPECT_EQ(sp.run.formulation, sim::Formulation::kAuto);
  EXPECT_TRUE(sp.run.events.stop_on_contact_loss);
  EXPECT_FALSE(sp.contact.mu.has_value());
  EXPECT_DOUBLE_EQ(sp.run.events.time_tolerance, 1e-12);
}

TEST(SceneTest, OptionalSectionsOverrideDefaults) {
  const std::string yaml = kMinimal + R"(name: custom
initial:
  s_h: -0.5
  sdot_h: 2
  s_o: 0.25
  object_angle_deg: 90
duration: 3
integrator:
  method: rk4
  step: 2.0e-4
  max_step: 0.01
  formulation: general
contact:
  mu: 0.5
  stop_on_contact_loss: false
  event_tolerance: 1.0e-9
)";
  const Scene s = parse_scene(yaml);
  const sim::SimulationSpec& sp = s.sim;
  EXPECT_EQ(s.name, "custom");
  EXPECT_DOUBLE_EQ(sp.initial.s_h, -0.5);
  EXPECT_DOUBLE_EQ(sp.initial.sdot_h, 2.0);
  ASSERT_TRUE(sp.initial.s_o.has_value());
  EXPECT_DOUBLE_EQ(*sp.initial.s_o, 0.25);
  EXPECT_NEAR(sp.initial.object_angle, kPi / 2, 1e-15);
  ASSERT_TRUE(sp.duration.has_value());
  EXPECT_DOUBLE_EQ(*sp.duration, 3.0);
  EXPECT_EQ(sp.run.integrator.method, sim::Method::kRungeKutta4);
  EXPECT_DOUBLE_EQ(sp.run.integrator.fixed_step, 2e-4);
  EXPECT_DOUBLE_EQ(sp.run.integrator.max_step, 0.01);
  EXPECT_EQ(sp.run.formulation, sim::Formulation::kGeneral);
  ASSERT_TRUE(sp.contact.mu.has_value());
  EXPECT_DOUBLE_EQ(*sp.contact.mu, 0.5);
  EXPECT_FALSE(sp.run.events.stop_on_contact_loss);
  EXPECT_DOUBLE_EQ(sp.run.events.time_tolerance, 1e-9);
}

TEST(SceneTest, IntegersAreAcceptedAsNumbers) {
  const Scene s =
      parse_scene(with(with(kMinimal, "g: 9.8", "g: 10"), "period: 1.181", "period: 2"));
  EXPECT_DOUBLE_EQ(s.sim.gravity, 10.0);
  EXPECT_DOUBLE_EQ(s.sim.motion.period, 2.0);
}

TEST(SceneTest, TiltDegreesBecomeRadians) {
  const Scene s = parse_scene(with(kBase, "tilt_deg: 90", "tilt_deg: 30"));
  EXPECT_NEAR(s.sim.tilt, kPi / 6, 1e-15);
  EXPECT_NEAR(s.sim.effective_gravity(), 4.9, 1e-12);
}

TEST(SceneTest, FixedMotion) {
  const Scene s = parse_scene(with(kMinimal, "  type: butterfly\n  period: 1.181\n  k: -1.1393\n",
                                   "  type: fixed\n  angle_deg: 30\n"));
  EXPECT_EQ(s.sim.motion.kind, sim::MotionSpec::Kind::kFixed);
  EXPECT_NEAR(s.sim.motion.angle, kPi / 6, 1e-15);
  EXPECT_DOUBLE_EQ(s.sim.end_time(), 1.0);  // no period to default to
}

TEST(SceneTest, EllipseObject) {
  const Scene s =
      parse_scene(with(kBase, "  type: disk\n  radius: 0.051\n",
                       "  type: ellipse\n  semi_axes: [0.03, 0.02]\n  inertia: 2e-4\n"));
  EXPECT_EQ(s.sim.object.kind, sim::ObjectSpec::Kind::kEllipse);
  EXPECT_DOUBLE_EQ(s.sim.object.semi_axis_x, 0.03);
  EXPECT_DOUBLE_EQ(s.sim.object.semi_axis_y, 0.02);
  ASSERT_TRUE(s.sim.object.inertia.has_value());
  EXPECT_DOUBLE_EQ(*s.sim.object.inertia, 2e-4);
}

const std::string kDiskKeys = "  type: disk\n  radius: 0.051\n";

// A ring and a ball (solid, hollow, on rails) read into their description; sim converts it.
TEST(SceneTest, RingAndBallObjects) {
  const Scene ring =
      parse_scene(with(kBase, kDiskKeys, "  type: ring\n  radius: 0.05\n  inner_radius: 0.04\n"));
  EXPECT_EQ(ring.sim.object.kind, sim::ObjectSpec::Kind::kRing);
  EXPECT_EQ(ring.sim.object.radius, 0.05);
  EXPECT_EQ(ring.sim.object.inner_radius, 0.04);
  const Scene ball = parse_scene(with(kBase, kDiskKeys, "  type: ball\n  radius: 0.05\n"));
  EXPECT_EQ(ball.sim.object.kind, sim::ObjectSpec::Kind::kBall);
  EXPECT_FALSE(ball.sim.object.hollow);
  EXPECT_FALSE(ball.sim.object.rail_gap.has_value());
  const Scene on_rails = parse_scene(with(
      kBase, kDiskKeys, "  type: ball\n  radius: 0.05\n  hollow: true\n  rails: {gap: 0.06}\n"));
  EXPECT_TRUE(on_rails.sim.object.hollow);
  ASSERT_TRUE(on_rails.sim.object.rail_gap.has_value());
  EXPECT_EQ(*on_rails.sim.object.rail_gap, 0.06);
  // Its own inertia, 2/3 m R^2 = 1.67e-3 for m = 1, is above m r^2 = 1.6e-3 of its rolling radius
  // 0.04 m, and a given one up to m R^2 = 2.5e-3 is a ball's.
  EXPECT_NO_THROW(
      parse_scene(with(kBase, kDiskKeys,
                       "  type: ball\n  radius: 0.05\n  rails: {gap: 0.06}\n  inertia: 2.4e-3\n")));
}

TEST(SceneTest, RingAndBallErrorsNameTheField) {
  const auto object = [](const std::string& keys) { return with(kBase, kDiskKeys, keys); };
  expect_field_error(object("  type: ball\n  radius: 0.05\n  rails: {gap: 0.1}\n"),
                     "object.rails.gap", "larger than the ball's diameter");
  expect_field_error(object("  type: ball\n  radius: 0.05\n  rails: {gap: 0}\n"),
                     "object.rails.gap", "positive");
  expect_field_error(object("  type: ball\n  radius: 0.05\n  rails: {width: 0.06}\n"),
                     "object.rails.width", "unknown key");
  expect_field_error(object("  type: ball\n  radius: 0.05\n  hollow: yes\n"), "object.hollow",
                     "true or false");
  expect_field_error(object("  type: ball\n  radius: 0.05\n  hollow: true\n  inertia: 1e-3\n"),
                     "object.hollow", "remove it");
  expect_field_error(
      object("  type: ball\n  radius: 0.05\n  rails: {gap: 0.06}\n  inertia: 2.6e-3\n"),
      "object.inertia", "at most m R^2");
  expect_field_error(object("  type: ring\n  radius: 0.05\n  inner_radius: 0.05\n"),
                     "object.inner_radius", "must be below object.radius");
  expect_field_error(object("  type: ring\n  radius: 0.05\n  inner_radius: -0.01\n"),
                     "object.inner_radius", "positive");
  expect_field_error(object("  type: ring\n  radius: 0.05\n"), "object.inner_radius", "missing");
  expect_field_error(
      object("  type: ring\n  radius: 0.05\n  inner_radius: 0.03\n  inertia: 5e-4\n"),
      "object.inertia", "at least m R_i^2");
  expect_field_error(object("  type: disk\n  radius: 0.05\n  inner_radius: 0.03\n"),
                     "object.inner_radius", "only for type: ring");
  expect_field_error(object("  type: disk\n  radius: 0.05\n  rails: {gap: 0.06}\n"), "object.rails",
                     "only for type: ball");
  expect_field_error(object("  type: ring\n  radius: 0.05\n  hollow: true\n"), "object.hollow",
                     "only for type: ball");
  expect_field_error(object("  type: ball\n  semi_axes: [0.03, 0.02]\n"), "object.semi_axes",
                     "only for type: ellipse");
  expect_field_error(object("  type: cube\n  radius: 0.05\n"), "object.type", "disk, ring, ball");
}

// --------------------------------------------------------------------------------------------
// Structural errors

TEST(SceneTest, ExactMessageFormat) {
  EXPECT_EQ(error_of(with(kBase, "radius: 0.051", "radius: -0.05"), "scenes/x.yaml"),
            "scenes/x.yaml: object.radius: must be positive, got -0.05");
  EXPECT_EQ(error_of(with(kBase, "k: -1.1393", "k: abc"), "x.yaml"),
            "x.yaml: motion.k: expected a number, got 'abc'");
  EXPECT_EQ(error_of(with(kBase, "gravity:\n  g: 9.8\n  tilt_deg: 90\n", ""), "x.yaml"),
            "x.yaml: gravity: missing required section");
}

TEST(SceneTest, MissingSection) {
  expect_field_error(with(kBase, "gravity:\n  g: 9.8\n  tilt_deg: 90\n", ""), "gravity",
                     "missing required section");
  expect_field_error(
      with(kMinimal, "motion:\n  type: butterfly\n  period: 1.181\n  k: -1.1393\n", ""), "motion",
      "missing");
}

TEST(SceneTest, MissingKey) {
  expect_field_error(with(kBase, "  k: -1.1393\n", ""), "motion.k", "missing required key");
  expect_field_error(with(kBase, "  g: 9.8\n", ""), "gravity.g", "missing");
  expect_field_error(with(kBase, "  radius: 0.051\n", ""), "object.radius", "missing");
  expect_field_error(with(kBase, "  shape: polynomial\n", ""), "hand.shape", "missing");
  expect_field_error(with(kBase, "  type: disk\n", ""), "object.type", "missing");
}

TEST(SceneTest, UnknownKeys) {
  expect_field_error(kBase + "colour: red\n", "colour", "unknown key");
  expect_field_error(with(kBase, "  d: 0.216\n", "  d: 0.216\n  foo: 1\n"), "hand.foo",
                     "unknown key");
  // A typo is reported as the unknown key, not as the missing one.
  expect_field_error(with(kBase, "radius: 0.051", "raduis: 0.051"), "object.raduis", "unknown key");
  expect_field_error(with(kBase, "rtol: 1.0e-10", "rtoll: 1.0e-10"), "integrator.rtoll",
                     "unknown key");
  expect_field_error(with(kBase, "event_tolerance", "tolerance"), "contact.tolerance",
                     "unknown key");
}

TEST(SceneTest, DuplicateKey) {
  expect_field_error(with(kBase, "  a: 0.18\n", "  a: 0.18\n  a: 0.19\n"), "hand.a", "duplicate");
}

TEST(SceneTest, WrongTypes) {
  expect_field_error(with(kBase, "k: -1.1393", "k: abc"), "motion.k", "expected a number");
  expect_field_error(with(kBase, "g: 9.8", "g: [1, 2]"), "gravity.g",
                     "expected a number, got a list");
  expect_field_error(with(kBase, "g: 9.8", "g: {x: 1}"), "gravity.g", "expected a number");
  expect_field_error(with(kBase, "radius: 0.051", "radius:"), "object.radius", "empty");
  expect_field_error(with(kBase, "radius: 0.051", "radius: \"0.051\""), "object.radius", "string");
  expect_field_error(with(kBase, "radius: 0.051", "radius: 0.051m"), "object.radius",
                     "expected a number");
  expect_field_error(with(kBase, "type: disk", "type: [disk]"), "object.type", "expected a string");
  expect_field_error(with(kBase, kHandSection, "hand: 3\n"), "hand", "expected a mapping");
  expect_field_error(with(kBase, kHandSection, "hand:\n"), "hand", "expected a mapping");
  expect_field_error(with(kBase, "stop_on_contact_loss: true", "stop_on_contact_loss: yes"),
                     "contact.stop_on_contact_loss", "true or false");
  expect_field_error(with(kBase, "stop_on_contact_loss: true", "stop_on_contact_loss: 1"),
                     "contact.stop_on_contact_loss", "true or false");
}

TEST(SceneTest, NonFiniteNumbers) {
  expect_field_error(with(kBase, "radius: 0.051", "radius: .nan"), "object.radius", "finite");
  expect_field_error(with(kBase, "period: 1.181", "period: .inf"), "motion.period", "finite");
  expect_field_error(with(kBase, "k: -1.1393", "k: -.inf"), "motion.k", "finite");
  expect_field_error(with(kBase, "s_h: -1", "s_h: .NaN"), "initial.s_h", "finite");
  expect_field_error(with(kBase, "g: 9.8", "g: 1e999"), "gravity.g", "range");
  expect_field_error(with(kBase, "  type: disk\n  radius: 0.051\n",
                          "  type: ellipse\n  semi_axes: [0.03, .nan]\n"),
                     "object.semi_axes[1]", "finite");
}

TEST(SceneTest, UnknownEnumValues) {
  expect_field_error(with(kBase, "method: dopri5", "method: euler"), "integrator.method",
                     "'euler' (allowed: dopri5, dop853, rk4)");
  expect_field_error(with(kBase, "formulation: auto", "formulation: magic"),
                     "integrator.formulation", "allowed: auto, general, reduced");
  expect_field_error(with(kBase, "type: disk", "type: square"), "object.type", "disk, ring, ball, ellipse");
  expect_field_error(with(kBase, "type: butterfly", "type: wave"), "motion.type",
                     "butterfly, fixed");
  expect_field_error(with(kBase, "shape: polynomial", "shape: spiral"), "hand.shape",
                     "allowed: polynomial, line, circle");
}

TEST(SceneTest, DerivedCoefficientsCannotBeGiven) {
  expect_field_error(with(kBase, "  d: 0.216\n", "  d: 0.216\n  e: 0.072\n"), "hand.e", "derived");
  expect_field_error(with(kBase, "  d: 0.216\n", "  d: 0.216\n  f: -0.0936\n"), "hand.f",
                     "derived");
}

TEST(SceneTest, KeysOfTheOtherVariant) {
  expect_field_error(with(kBase, "  radius: 0.051\n", "  radius: 0.051\n  semi_axes: [1, 2]\n"),
                     "object.semi_axes", "ellipse");
  expect_field_error(with(kBase, "  type: disk\n", "  type: ellipse\n  semi_axes: [0.03, 0.02]\n"),
                     "object.radius", "disk");
  expect_field_error(with(kBase, "  k: -1.1393\n", "  k: -1.1393\n  angle_deg: 10\n"),
                     "motion.angle_deg", "fixed");
  expect_field_error(with(kBase, "type: butterfly", "type: fixed"), "motion.period", "butterfly");
  expect_field_error(with(kBase, "  type: disk\n  radius: 0.051\n",
                          "  type: ellipse\n  semi_axes: [0.03, 0.02, 0.01]\n"),
                     "object.semi_axes", "two numbers");
  expect_field_error(with(kBase, "  type: disk\n  radius: 0.051\n", "  type: ellipse\n"),
                     "object.semi_axes", "missing");
}

// --------------------------------------------------------------------------------------------
// Value errors

TEST(SceneTest, OutOfRangeValues) {
  expect_field_error(with(kBase, "radius: 0.051", "radius: -0.05"), "object.radius",
                     "must be positive, got -0.05");
  expect_field_error(with(kBase, "radius: 0.051", "radius: 0"), "object.radius", "positive");
  expect_field_error(with(kBase, "period: 1.181", "period: 0"), "motion.period", "positive");
  expect_field_error(with(kBase, "period: 1.181", "period: -1.181"), "motion.period", "positive");
  expect_field_error(with(kBase, "g: 9.8", "g: -9.8"), "gravity.g", "positive");
  expect_field_error(with(kBase, "tilt_deg: 90", "tilt_deg: 0"), "gravity.tilt_deg", "(0, 90]");
  expect_field_error(with(kBase, "tilt_deg: 90", "tilt_deg: 95"), "gravity.tilt_deg", "(0, 90]");
  expect_field_error(with(kBase, "mass: 1.0", "mass: 0"), "object.mass", "positive");
  expect_field_error(with(kBase, "mass: 1.0", "mass: 1.0\n  inertia: -1"), "object.inertia",
                     "positive");
  expect_field_error(with(kBase, "duration: 1.181", "duration: 0"), "duration", "positive");
  // The integrator's inputs within the bounds sim sets (docs/SCENE.md, "integrator").
  expect_field_error(with(kBase, "rtol: 1.0e-10", "rtol: 0"), "integrator.rtol",
                     "must be in [1e-14, 0.1]");
  expect_field_error(with(kBase, "rtol: 1.0e-10", "rtol: 1.0e-300"), "integrator.rtol",
                     "must be in [1e-14, 0.1]");
  expect_field_error(with(kBase, "rtol: 1.0e-10", "rtol: 0.5"), "integrator.rtol",
                     "must be in [1e-14, 0.1]");
  expect_field_error(with(kBase, "atol: 1.0e-12", "atol: -1"), "integrator.atol",
                     "must be in [1e-18, 1]");
  expect_field_error(with(kBase, "atol: 1.0e-12", "atol: 1.0e-302"), "integrator.atol",
                     "must be in [1e-18, 1]");
  expect_field_error(with(kBase, "atol: 1.0e-12", "atol: 1.0e-12\n  energy_tolerance: 1.0e-13"),
                     "integrator.energy_tolerance", "must be in [1e-12, 1]");
  expect_field_error(with(kBase, "atol: 1.0e-12", "atol: 1.0e-12\n  step: .inf"), "integrator.step",
                     "must be a finite number");
  expect_field_error(with(kBase, "formulation: auto", "formulation: auto\n  step: 0"),
                     "integrator.step", "positive");
  expect_field_error(with(kBase, "formulation: auto", "formulation: auto\n  max_step: -0.1"),
                     "integrator.max_step", "positive");
  expect_field_error(with(kBase, "stop_on_contact_loss: true", "mu: -0.1"), "contact.mu", ">= 0");
  expect_field_error(with(kBase, "event_tolerance: 1.0e-12", "event_tolerance: 0"),
                     "contact.event_tolerance", "positive");
}

// A scene is a few kB: over 1 MiB it is refused before it is parsed.
TEST(SceneTest, OversizedSceneIsRefused) {
  expect_field_error(std::string((1 << 20) + 1, '#'), "(document)", "larger than 1 MiB");
}

// The hybrid model's contact law and losses.
TEST(SceneTest, HybridContactSection) {
  const std::string hybrid =
      "contact:\n  model: hybrid\n  mu: 0.8\n  mu_kinetic: 0.6\n"
      "  restitution: 0.4\n  capture_velocity: 0.002\n"
      "  rolling_resistance: 5.0e-5\n  drag: 0.015\n"
      "  drag_angular: 2.0e-5\n  event_tolerance: 1.0e-12\n";
  const std::string rolling =
      "contact:\n  stop_on_contact_loss: true\n  event_tolerance: 1.0e-12\n";
  const Scene s = parse_scene(with(kBase, rolling, hybrid));
  const sim::ContactLaw& c = s.sim.contact;
  EXPECT_EQ(s.sim.run.model, sim::ContactModel::kHybrid);
  EXPECT_DOUBLE_EQ(*c.mu, 0.8);
  EXPECT_DOUBLE_EQ(*c.mu_kinetic, 0.6);
  EXPECT_DOUBLE_EQ(c.restitution, 0.4);
  EXPECT_DOUBLE_EQ(c.capture_velocity, 0.002);
  EXPECT_DOUBLE_EQ(c.rolling_resistance, 5e-5);
  EXPECT_DOUBLE_EQ(c.drag, 0.015);
  EXPECT_DOUBLE_EQ(c.drag_angular, 2e-5);
  // Absent: the rolling model, as the paper's simulation.
  EXPECT_EQ(parse_scene(kBase).sim.run.model, sim::ContactModel::kRolling);

  const auto bad = [&](const std::string& from, const std::string& to, const std::string& field,
                       const std::string& reason) {
    expect_field_error(with(with(kBase, rolling, hybrid), from, to), field, reason);
  };
  bad("mu: 0.8", "mu: -0.1", "contact.mu", ">= 0");
  bad("mu_kinetic: 0.6", "mu_kinetic: 0.9", "contact.mu_kinetic", "must not exceed contact.mu");
  bad("  mu: 0.8\n", "", "contact.mu_kinetic", "needs contact.mu");
  bad("restitution: 0.4", "restitution: 1.5", "contact.restitution", "[0, 1]");
  bad("restitution: 0.4", "restitution: -0.1", "contact.restitution", "[0, 1]");
  bad("drag: 0.015", "drag: -0.015", "contact.drag", ">= 0");
  bad("drag_angular: 2.0e-5", "drag_angular: -1", "contact.drag_angular", ">= 0");
  bad("rolling_resistance: 5.0e-5", "rolling_resistance: -5.0e-5", "contact.rolling_resistance",
      ">= 0");
  bad("capture_velocity: 0.002", "capture_velocity: -1", "contact.capture_velocity", ">= 0");
  bad("model: hybrid", "model: soft", "contact.model", "unknown value");
  bad("model: hybrid", "model: hybrid\n  stop_on_contact_loss: true",
      "contact.stop_on_contact_loss", "only for model: rolling");
  // The rolling model is the paper's: no losses, no impacts.
  bad("model: hybrid", "model: rolling", "contact.mu_kinetic", "only for model: hybrid");
  expect_field_error(with(kBase, "stop_on_contact_loss: true", "drag: 0.1"), "contact.drag",
                     "only for model: hybrid");
}

// These come from sim::build_problem, re-prefixed with the origin.
TEST(SceneTest, PhysicallyInvalidScenes) {
  expect_field_error(with(kBase, "k: -1.1393", "k: -2"), "motion.k", "k = -2");
  // A flat palm (d = 0) has no well to start in.
  expect_field_error(with(kBase, "d: 0.216", "d: 0"), "hand", "no well");
  // A disk wider than the palm well's curvature radius (r kappa >= 1).
  expect_field_error(with(kBase, "radius: 0.051", "radius: 0.1"), "hand", "too tight");
  // c = -0.5 pulls the outline across the axis of symmetry.
  expect_field_error(with(kBase, "c: -0.252", "c: -0.5"), "hand", "self-intersects");
  expect_field_error(with(kBase, "a: 0.18", "a: -0.18"), "hand.a", "positive");
  // A thin ring is the most inertia a body within the disk's radius can have: m R^2.
  expect_field_error(with(kBase, "mass: 1.0", "mass: 1.0\n  inertia: 0.01"), "object.inertia",
                     "at most m R^2");
  expect_field_error(with(with(kBase, "  type: disk\n  radius: 0.051\n",
                               "  type: ellipse\n  semi_axes: [0.03, 0.02]\n"),
                          "formulation: auto", "formulation: reduced"),
                     "integrator.formulation", "disk");
}

// --------------------------------------------------------------------------------------------
// Document-level errors

TEST(SceneTest, YamlSyntaxErrorGivesTheLine) {
  // Line 7 opens a flow sequence that is never closed.
  const std::string msg = error_of(with(kBase, "a: 0.18", "a: [0.18"));
  EXPECT_EQ(msg.rfind("t.yaml: line ", 0), 0u) << msg;
  EXPECT_NE(msg.find("invalid YAML"), std::string::npos) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;

  // Bad indentation on line 3.
  const std::string msg2 = error_of("gravity:\n  g: 9.8\n    tilt_deg: 90\n");
  EXPECT_EQ(msg2.rfind("t.yaml: line 3, column", 0), 0u) << msg2;
}

TEST(SceneTest, DocumentShapeErrors) {
  expect_field_error("", "(document)", "empty");
  expect_field_error("- 1\n- 2\n", "(document)", "mapping");
  expect_field_error("just a string\n", "(document)", "mapping");
  expect_field_error(kBase + "---\n" + kBase, "(document)", "documents");
}

TEST(SceneTest, MessagesStayOnOneLineEvenForMultiLineInput) {
  const std::string msg = error_of(with(kBase, "k: -1.1393", "k: |\n    two\n    lines"));
  EXPECT_EQ(msg.rfind("t.yaml: motion.k: expected a number", 0), 0u) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
}

// --------------------------------------------------------------------------------------------
// Renderer sections: camera, effects, render, targets

TEST(SceneRenderSections, AbsentSectionsAreOff) {
  const Scene s = parse_scene(kMinimal);
  EXPECT_FALSE(s.camera.has_value());
  EXPECT_TRUE(s.targets.empty());
  const flatland::EffectsSpec& e = s.effects;
  EXPECT_EQ(e.supersample, 1);
  EXPECT_EQ(e.blur_subframes, 1);
  EXPECT_DOUBLE_EQ(e.noise_read_dn, 0.0);
  EXPECT_DOUBLE_EQ(e.noise_shot_gain, 0.0);
  EXPECT_TRUE(e.quantize);
  EXPECT_DOUBLE_EQ(e.vignetting, 0.0);
  EXPECT_DOUBLE_EQ(e.jitter_s, 0.0);
  EXPECT_DOUBLE_EQ(e.drop_probability, 0.0);
  EXPECT_EQ(e.seed, 1u);
  EXPECT_EQ(s.render.backend, "osmesa");
  EXPECT_EQ(s.render.view, "overhead");
  EXPECT_DOUBLE_EQ(s.render.hand_thickness, 0.012);
  EXPECT_DOUBLE_EQ(s.render.disk_thickness, 0.006);
  EXPECT_DOUBLE_EQ(s.render.table_extent, 0.6);
}

TEST(SceneRenderSections, EmptyCameraSectionGetsDefaults) {
  const Scene s = parse_scene(kMinimal + "camera: {}\n");
  ASSERT_TRUE(s.camera.has_value());
  const flatland::CameraSpec& c = *s.camera;
  EXPECT_EQ(c.width, 640);
  EXPECT_EQ(c.height, 480);
  EXPECT_DOUBLE_EQ(c.fx, 700.0);
  EXPECT_DOUBLE_EQ(c.fy, 700.0);
  EXPECT_DOUBLE_EQ(c.cx, 319.5);
  EXPECT_DOUBLE_EQ(c.cy, 239.5);
  for (double k : c.distortion) EXPECT_EQ(k, 0.0);
  EXPECT_EQ(c.position, (std::array<double, 3>{0, 0, 1}));
  EXPECT_EQ(c.look_at, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(c.up, (std::array<double, 3>{0, 1, 0}));
  EXPECT_DOUBLE_EQ(c.fps, 30.0);
  EXPECT_DOUBLE_EQ(c.exposure, 0.0);
}

TEST(SceneRenderSections, PrincipalPointDefaultsToTheImageCentre) {
  const Scene s = parse_scene(kMinimal + "camera:\n  width: 160\n  height: 121\n");
  ASSERT_TRUE(s.camera.has_value());
  EXPECT_DOUBLE_EQ(s.camera->cx, 79.5);
  EXPECT_DOUBLE_EQ(s.camera->cy, 60.0);
}

const std::string kRenderSections = R"(camera:
  width: 800
  height: 600
  fx: 650.5
  fy: 651
  cx: 401.25
  cy: 298
  distortion: [-0.1, 0.02, 0.001, -0.002, 0.003]
  position: [0.1, -0.2, 1.5]
  look_at: [0.05, 0.0, 0.01]
  up: [0, 1, 0.1]
  fps: 60
  exposure: 0.01
effects:
  supersample: 4
  blur_subframes: 8
  noise_read_dn: 1.5
  noise_shot_gain: 0.25
  quantize: false
  vignetting: 0.3
  jitter_s: 0.002
  drop_probability: 0.05
  seed: 42
render:
  backend: egl
  view: side
  hand_thickness: 0.02
  disk_thickness: 0.004
  table_extent: 0.8
targets:
  - type: chessboard
    cols: 7
    rows: 5
    square: 0.03
    position: [0.1, 0.2, 0.001]
    rotation: [0, 0, 1.5707963267948966]
  - type: charuco
    cols: 5
    rows: 4
    square: 0.04
    marker: 0.03
    dictionary: DICT_5X5_100
  - type: charuco
)";

TEST(SceneRenderSections, GivenValuesAreLoaded) {
  const Scene s = parse_scene(kMinimal + kRenderSections);
  ASSERT_TRUE(s.camera.has_value());
  const flatland::CameraSpec& c = *s.camera;
  EXPECT_EQ(c.width, 800);
  EXPECT_EQ(c.height, 600);
  EXPECT_DOUBLE_EQ(c.fx, 650.5);
  EXPECT_DOUBLE_EQ(c.fy, 651.0);
  EXPECT_DOUBLE_EQ(c.cx, 401.25);
  EXPECT_DOUBLE_EQ(c.cy, 298.0);
  EXPECT_EQ(c.distortion, (std::array<double, 5>{-0.1, 0.02, 0.001, -0.002, 0.003}));
  EXPECT_EQ(c.position, (std::array<double, 3>{0.1, -0.2, 1.5}));
  EXPECT_EQ(c.look_at, (std::array<double, 3>{0.05, 0.0, 0.01}));
  EXPECT_EQ(c.up, (std::array<double, 3>{0, 1, 0.1}));
  EXPECT_DOUBLE_EQ(c.fps, 60.0);
  EXPECT_DOUBLE_EQ(c.exposure, 0.01);

  const flatland::EffectsSpec& e = s.effects;
  EXPECT_EQ(e.supersample, 4);
  EXPECT_EQ(e.blur_subframes, 8);
  EXPECT_DOUBLE_EQ(e.noise_read_dn, 1.5);
  EXPECT_DOUBLE_EQ(e.noise_shot_gain, 0.25);
  EXPECT_FALSE(e.quantize);
  EXPECT_DOUBLE_EQ(e.vignetting, 0.3);
  EXPECT_DOUBLE_EQ(e.jitter_s, 0.002);
  EXPECT_DOUBLE_EQ(e.drop_probability, 0.05);
  EXPECT_EQ(e.seed, 42u);

  EXPECT_EQ(s.render.backend, "egl");
  EXPECT_EQ(s.render.view, "side");
  EXPECT_DOUBLE_EQ(s.render.hand_thickness, 0.02);
  EXPECT_DOUBLE_EQ(s.render.disk_thickness, 0.004);
  EXPECT_DOUBLE_EQ(s.render.table_extent, 0.8);

  ASSERT_EQ(s.targets.size(), 3u);
  const flatland::TargetSpec& board = s.targets[0];
  EXPECT_EQ(board.kind, flatland::TargetSpec::Kind::kChessboard);
  // A chessboard is counted by its inner corners, as OpenCV's patternSize: 7 x 5 is 8 x 6 squares.
  EXPECT_EQ(board.squares_x, 8);
  EXPECT_EQ(board.squares_y, 6);
  EXPECT_DOUBLE_EQ(board.square, 0.03);
  EXPECT_EQ(board.position, (std::array<double, 3>{0.1, 0.2, 0.001}));
  EXPECT_DOUBLE_EQ(board.rotation[2], kPi / 2);
  const flatland::TargetSpec& charuco = s.targets[1];
  EXPECT_EQ(charuco.kind, flatland::TargetSpec::Kind::kCharuco);
  // A ChArUco board is counted by its squares, as cv::aruco::CharucoBoard.
  EXPECT_EQ(charuco.squares_x, 5);
  EXPECT_EQ(charuco.squares_y, 4);
  EXPECT_DOUBLE_EQ(charuco.square, 0.04);
  EXPECT_DOUBLE_EQ(charuco.marker, 0.03);
  EXPECT_EQ(charuco.dictionary, "DICT_5X5_100");
  // Defaults: 9 x 6 squares of 0.02 m, 0.015 m markers, DICT_4X4_50, at the origin.
  const flatland::TargetSpec& plain = s.targets[2];
  EXPECT_EQ(plain.kind, flatland::TargetSpec::Kind::kCharuco);
  EXPECT_EQ(plain.squares_x, 9);
  EXPECT_EQ(plain.squares_y, 6);
  EXPECT_DOUBLE_EQ(plain.square, 0.02);
  EXPECT_DOUBLE_EQ(plain.marker, 0.015);
  EXPECT_EQ(plain.dictionary, "DICT_4X4_50");
  EXPECT_EQ(plain.position, (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(plain.rotation, (std::array<double, 3>{0, 0, 0}));
}

// The default chessboard is OpenCV's sample board: 9 x 6 inner corners, so 10 x 7 squares, whose
// corners render::target_corners lists as cv::findChessboardCorners does.
TEST(SceneRenderSections, DefaultChessboardIsOpenCvsSampleBoard) {
  const Scene s = parse_scene(kMinimal + "targets:\n  - type: chessboard\n");
  ASSERT_EQ(s.targets.size(), 1u);
  EXPECT_EQ(s.targets[0].squares_x, 10);
  EXPECT_EQ(s.targets[0].squares_y, 7);
}

TEST(SceneRenderSections, EmptyTargetListAndCharucoMarkerDefault) {
  EXPECT_TRUE(parse_scene(kMinimal + "targets: []\n").targets.empty());
  // Without `marker`, a ChArUco marker is 3/4 of its square.
  const Scene s = parse_scene(kMinimal + "targets:\n  - type: charuco\n    square: 0.04\n");
  ASSERT_EQ(s.targets.size(), 1u);
  EXPECT_DOUBLE_EQ(s.targets[0].marker, 0.03);
}

TEST(SceneRenderSections, ExactCameraMessages) {
  EXPECT_EQ(error_of(kMinimal + "camera:\n  position: [0, 0, -1]\n", "x.yaml"),
            "x.yaml: camera.position: the camera must be above the table (z > 0), got z = -1");
  EXPECT_EQ(error_of(kMinimal + "camera:\n  fx: 0\n", "x.yaml"),
            "x.yaml: camera.fx: must be positive, got 0");
  EXPECT_EQ(error_of(kMinimal + "camera:\n  width: 0\n", "x.yaml"),
            "x.yaml: camera.width: must be an integer in [1, 16384], got 0");
}

// Each line perturbs one value of kRenderSections; the error names that field.
TEST(SceneRenderSections, BadValuesNameTheField) {
  const std::string base = kMinimal + kRenderSections;
  auto bad = [&](const std::string& from, const std::string& to, const std::string& field,
                 const std::string& reason) {
    SCOPED_TRACE(to);
    expect_field_error(with(base, from, to), field, reason);
  };
  // camera
  bad("width: 800", "width: 0", "camera.width", "[1, 16384]");
  bad("width: 800", "width: -640", "camera.width", "[1, 16384]");
  bad("height: 600", "height: 0", "camera.height", "[1, 16384]");
  bad("width: 800", "width: 640.5", "camera.width", "expected an integer");
  bad("width: 800", "width: 6.4e2", "camera.width", "expected an integer");
  bad("width: 800", "width: \"640\"", "camera.width", "string");
  bad("fx: 650.5", "fx: 0", "camera.fx", "positive");
  bad("fy: 651", "fy: -700", "camera.fy", "positive");
  bad("cx: 401.25", "cx: .nan", "camera.cx", "finite");
  bad("cy: 298", "cy: abc", "camera.cy", "expected a number");
  bad("distortion: [-0.1, 0.02, 0.001, -0.002, 0.003]", "distortion: [-0.1, 0.02, 0.001, -0.002]",
      "camera.distortion", "5 numbers");
  bad("distortion: [-0.1, 0.02, 0.001, -0.002, 0.003]", "distortion: 0.1", "camera.distortion",
      "5 numbers");
  bad("distortion: [-0.1, 0.02, 0.001, -0.002, 0.003]",
      "distortion: [-0.1, 0.02, x, -0.002, 0.003]", "camera.distortion[2]", "expected a number");
  bad("position: [0.1, -0.2, 1.5]", "position: [0.1, -0.2, -1]", "camera.position",
      "above the table (z > 0)");
  bad("position: [0.1, -0.2, 1.5]", "position: [0.1, -0.2, 0]", "camera.position",
      "above the table");
  bad("position: [0.1, -0.2, 1.5]", "position: [0.1, 1.5]", "camera.position", "3 numbers");
  bad("position: [0.1, -0.2, 1.5]", "position: [0.05, 0.0, 0.01]", "camera.look_at", "must differ");
  bad("look_at: [0.05, 0.0, 0.01]", "look_at: [0.05, 0.0, .inf]", "camera.look_at[2]", "finite");
  bad("up: [0, 1, 0.1]", "up: [0, 0, 0]", "camera.up", "zero");
  bad("up: [0, 1, 0.1]", "up: [0.05, -0.2, 1.49]", "camera.up", "parallel");
  bad("fps: 60", "fps: 0", "camera.fps", "positive");
  bad("exposure: 0.01", "exposure: -0.001", "camera.exposure", ">= 0");
  bad("exposure: 0.01", "exposure: 0.02", "camera.exposure", "1/fps");
  bad("  exposure: 0.01\n", "  exposure: 0.01\n  focal: 700\n", "camera.focal", "unknown key");
  // effects
  bad("supersample: 4", "supersample: 0", "effects.supersample", "[1, 8]");
  bad("supersample: 4", "supersample: 9", "effects.supersample", "[1, 8]");
  bad("supersample: 4", "supersample: 2.5", "effects.supersample", "integer");
  bad("blur_subframes: 8", "blur_subframes: 0", "effects.blur_subframes", "[1, 64]");
  bad("blur_subframes: 8", "blur_subframes: 65", "effects.blur_subframes", "[1, 64]");
  bad("exposure: 0.01", "exposure: 0", "effects.blur_subframes", "camera.exposure > 0");
  bad("noise_read_dn: 1.5", "noise_read_dn: -1", "effects.noise_read_dn", ">= 0");
  bad("noise_shot_gain: 0.25", "noise_shot_gain: -0.1", "effects.noise_shot_gain", ">= 0");
  bad("quantize: false", "quantize: no", "effects.quantize", "true or false");
  bad("vignetting: 0.3", "vignetting: 1.5", "effects.vignetting", "[0, 1]");
  bad("vignetting: 0.3", "vignetting: -0.1", "effects.vignetting", "[0, 1]");
  bad("jitter_s: 0.002", "jitter_s: -0.002", "effects.jitter_s", ">= 0");
  bad("drop_probability: 0.05", "drop_probability: 1.01", "effects.drop_probability", "[0, 1]");
  bad("seed: 42", "seed: -1", "effects.seed", "integer in [0,");
  bad("seed: 42", "seed: 4.2", "effects.seed", "expected an integer");
  bad("seed: 42", "seed: 99999999999999999999999", "effects.seed", "out of range");
  bad("  seed: 42\n", "  seed: 42\n  blur: 3\n", "effects.blur", "unknown key");
  // render
  bad("backend: egl", "backend: glx", "render.backend", "(allowed: osmesa, egl)");
  bad("view: side", "view: top", "render.view", "(allowed: overhead, side)");
  bad("hand_thickness: 0.02", "hand_thickness: 0", "render.hand_thickness", "positive");
  bad("disk_thickness: 0.004", "disk_thickness: -0.004", "render.disk_thickness", "positive");
  bad("table_extent: 0.8", "table_extent: 0", "render.table_extent", "positive");
  bad("  table_extent: 0.8\n", "  table_extent: 0.8\n  light: 1\n", "render.light", "unknown key");
  // targets
  bad("  - type: chessboard\n", "  - type: circles\n", "targets[0].type",
      "(allowed: chessboard, charuco)");
  bad("cols: 7", "cols: 0", "targets[0].cols", "[1, 999]");
  bad("cols: 5", "cols: 1", "targets[1].cols", "[2, 1000]");
  bad("rows: 5", "rows: 1.5", "targets[0].rows", "expected an integer");
  bad("square: 0.03", "square: 0", "targets[0].square", "positive");
  bad("square: 0.03", "square: 0.03\n    marker: 0.02", "targets[0].marker", "charuco");
  bad("square: 0.03", "square: 0.03\n    dictionary: DICT_4X4_50", "targets[0].dictionary",
      "charuco");
  bad("marker: 0.03", "marker: 0.04", "targets[1].marker", "smaller than the square");
  bad("marker: 0.03", "marker: 0", "targets[1].marker", "positive");
  bad("dictionary: DICT_5X5_100", "dictionary: DICT_5X5_99", "targets[1].dictionary",
      "unknown value 'DICT_5X5_99'");
  bad("position: [0.1, 0.2, 0.001]", "position: [0.1, 0.2]", "targets[0].position", "3 numbers");
  bad("rotation: [0, 0, 1.5707963267948966]", "rotation: [0, 0, .nan]", "targets[0].rotation[2]",
      "finite");
  expect_field_error(base + "    colour: red\n", "targets[2].colour", "unknown key");
  expect_field_error(base + "  - 3\n", "targets[3]", "expected a mapping");
}

TEST(SceneRenderSections, SectionShapeErrors) {
  expect_field_error(kMinimal + "camera: 3\n", "camera", "expected a mapping");
  expect_field_error(kMinimal + "effects: [1]\n", "effects", "expected a mapping");
  expect_field_error(kMinimal + "render: side\n", "render", "expected a mapping");
  expect_field_error(kMinimal + "targets:\n  type: chessboard\n", "targets", "expected a list");
  // Exposure blur without any camera section.
  expect_field_error(kMinimal + "effects:\n  blur_subframes: 2\n", "effects.blur_subframes",
                     "no camera section");
}

// --------------------------------------------------------------------------------------------
// Files

class SceneFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("flatland_scene_test_" +
            std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const auto p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  std::filesystem::path dir_;
};

TEST_F(SceneFileTest, LoadsAFileAndUsesItsPathAsOrigin) {
  const std::string p = write("ok.yaml", kBase);
  const Scene s = flatland::load_scene(p);
  EXPECT_EQ(s.origin, p);
  EXPECT_EQ(s.name, "test");
}

TEST_F(SceneFileTest, ErrorsInAFileNameThePath) {
  const std::string p = write("bad.yaml", with(kBase, "radius: 0.051", "radius: -0.05"));
  try {
    flatland::load_scene(p);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()), p + ": object.radius: must be positive, got -0.05");
  }
}

TEST_F(SceneFileTest, MissingFile) {
  const std::string p = (dir_ / "does-not-exist.yaml").string();
  try {
    flatland::load_scene(p);
    FAIL() << "no error";
  } catch (const SceneError& e) {
    EXPECT_EQ(std::string(e.what()),
              p + ": cannot read scene file (" + std::strerror(ENOENT) + ")");
  }
}

TEST_F(SceneFileTest, DirectoryIsUnreadable) {
  try {
    flatland::load_scene(dir_.string());
    FAIL() << "no error";
  } catch (const SceneError& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.rfind(dir_.string() + ": cannot read scene file (", 0), 0u) << msg;
  }
}

}  // namespace

// --------------------------------------------------------------------------------------------
// Hand shapes: line and circle

namespace {
const std::string kLineHand = "hand:\n  shape: line\n  angle_deg: 30\n  origin: [0.01, -0.02]\n";
const std::string kCircleHand = "hand:\n  shape: circle\n  radius: 0.25\n  center: [0, 0.1]\n";
}  // namespace

TEST(SceneHandShapes, ALineIsAnOpenHandThroughItsOriginAtItsAngle) {
  const Scene s = parse_scene(with(kBase, kHandSection, kLineHand), "t.yaml");
  EXPECT_EQ(s.sim.hand.shape, sim::HandSpec::Shape::kLine);
  EXPECT_NEAR(s.sim.hand.line_angle, kPi / 6, 1e-15);
  const auto problem = sim::build_problem(s.sim);
  const auto* line = dynamic_cast<const sim::HandCurve*>(problem->hand.get());
  ASSERT_NE(line, nullptr);
  EXPECT_FALSE(line->has_palm_and_back());
  EXPECT_TRUE(std::isinf(line->period()));
  // c(s) = origin + s (cos 30, sin 30); the object's side is above it.
  const sim::CurveGeometry g = line->geometry(0.5);
  EXPECT_NEAR(g.point.x(), 0.01 + 0.5 * std::cos(kPi / 6), 1e-15);
  EXPECT_NEAR(g.point.y(), -0.02 + 0.5 * std::sin(kPi / 6), 1e-15);
  EXPECT_NEAR(g.normal.x(), -std::sin(kPi / 6), 1e-15);
  EXPECT_NEAR(g.normal.y(), std::cos(kPi / 6), 1e-15);
  // The defaults: angle 0 through the pivot.
  const Scene d = parse_scene(with(kBase, kHandSection, "hand:\n  shape: line\n"), "t.yaml");
  EXPECT_EQ(d.sim.hand.line_angle, 0.0);
  EXPECT_EQ(d.sim.hand.line_origin, sim::Vec2::Zero());
}

TEST(SceneHandShapes, ACircleIsAWellWithItsBottomAtSZero) {
  const Scene s = parse_scene(with(kBase, kHandSection, kCircleHand), "t.yaml");
  EXPECT_EQ(s.sim.hand.shape, sim::HandSpec::Shape::kCircle);
  const auto problem = sim::build_problem(s.sim);
  const auto* well = dynamic_cast<const sim::CircleWellHand*>(problem->hand.get());
  ASSERT_NE(well, nullptr);
  EXPECT_FALSE(well->has_palm_and_back());
  EXPECT_NEAR(well->period(), 2 * kPi, 1e-15);
  // s = 0 at the bottom, the outward normal (out of the body, into the well) pointing up, and the
  // well concave where the object touches it: curvature -1/R.
  const sim::CurveGeometry g = well->geometry(0.0);
  EXPECT_NEAR(g.point.x(), 0.0, 1e-15);
  EXPECT_NEAR(g.point.y(), 0.1 - 0.25, 1e-15);
  EXPECT_NEAR(g.normal.y(), 1.0, 1e-15);
  EXPECT_NEAR(g.curvature, -1 / 0.25, 1e-12);
}

TEST(SceneHandShapes, EachShapesKeysOnlyAndTheObjectMustFitTheWell) {
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: circle\n"), "hand.radius",
                     "missing");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: circle\n  radius: 0.04\n"),
                     "hand.radius", "wider than the object");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: circle\n  radius: 0\n"),
                     "hand.radius", "positive");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: line\n  radius: 0.3\n"),
                     "hand.radius", "only for shape: circle");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: circle\n  radius: 0.3\n  d: 1\n"),
                     "hand.d", "only for shape: polynomial");
  expect_field_error(with(kBase, "  d: 0.216\n", "  d: 0.216\n  angle_deg: 3\n"), "hand.angle_deg",
                     "only for shape: line");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: line\n  origin: [1, 2, 3]\n"),
                     "hand.origin", "list of 2");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: line\n  angle_deg: .inf\n"),
                     "hand.angle_deg", "finite");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: oval\n"), "hand.shape");
  // An ellipse must fit the well with its flattest part: radius of curvature ax^2/ay = 0.288 m.
  const std::string ellipse = with(with(kBase, kHandSection, kCircleHand), "  radius: 0.051\n",
                                   "  semi_axes: [0.12, 0.05]\n");
  expect_field_error(with(ellipse, "type: disk", "type: ellipse"), "hand.radius");  // 0.25 < 0.288
}

TEST(SceneHandShapes, TheSearchesRefuseAHandWithoutPalmAndBack) {
  for (const std::string& hand : {kLineHand, kCircleHand}) {
    const Scene s = parse_scene(with(kBase, kHandSection, hand), "t.yaml");
    const auto problem = sim::build_problem(s.sim);
    try {
      sim::require_palm_and_back(s.sim.hand, *problem->hand, "solve");
      ADD_FAILURE() << "accepted " << hand;
    } catch (const std::invalid_argument& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind("hand.shape: ", 0), 0u) << msg;
      EXPECT_NE(msg.find("solve"), std::string::npos) << msg;
    }
  }
  const Scene paper = parse_scene(kBase, "t.yaml");
  EXPECT_NO_THROW(
      sim::require_palm_and_back(paper.sim.hand, *sim::build_problem(paper.sim)->hand, "solve"));
}

TEST(SceneHandShapes, PointsAndPolarKeysAreCheckedWhereTheSceneSaysThem) {
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: points\n"), "hand.file", "missing");
  expect_field_error(
      with(kBase, kHandSection, "hand:\n  shape: points\n  file: /nonexistent/flatland-hand.csv\n"),
      "hand.file", "/nonexistent/flatland-hand.csv");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: points\n  file: h.csv\n  r: [1]\n"),
                     "hand.r", "only for shape: polar");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: polar\n  units: mm\n"),
                     "hand.units", "only for shape: points");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: polar\n"), "hand.cos", "missing");
  expect_field_error(
      with(kBase, kHandSection, "hand:\n  shape: polar\n  phi_deg: [0, 90]\n  r: [0.1]\n"),
      "hand.r", "one radius per angle");
  expect_field_error(with(kBase, kHandSection, "hand:\n  shape: polar\n  r: [0.1]\n  cos: [0.1]\n"),
                     "hand.cos", "not both");
}
