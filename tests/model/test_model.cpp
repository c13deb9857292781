// The compiled Model: one compile of a scene gives every module its typed values, built once and
// shared (model/model.hpp); the camera's rules are written once and both the scene loader and
// the compile step report them.
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <string>

namespace {

using flatland::CameraSpec;
using flatland::Scene;
namespace model = flatland::model;
namespace sim = flatland::sim;

Scene bundled(const std::string& name) {
  return flatland::load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/" + name);
}

std::string compile_error(const Scene& scene) {
  try {
    model::compile(scene);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  ADD_FAILURE() << "compile accepted the scene";
  return {};
}

TEST(Model, CompilesEveryPartOfTheAirTableScene) {
  const Scene scene = bundled("airtable-feedback.yaml");
  const auto m = model::compile(scene);

  // The plant is built once: its hand is the model's hand, and the paper's plant shares it.
  ASSERT_TRUE(m->plant && m->paper_plant && m->hand);
  EXPECT_EQ(m->plant->hand.get(), m->hand.get());
  EXPECT_EQ(m->paper_plant->hand.get(), m->hand.get());
  EXPECT_EQ(m->paper_plant->motion.get(), m->plant->motion.get());
  // The paper's plant is the scene's without losses; friction is kept.
  ASSERT_GT(scene.sim.contact.drag, 0);
  ASSERT_GT(scene.sim.contact.rolling_resistance, 0);
  EXPECT_EQ(m->plant->contact.drag, scene.sim.contact.drag);
  EXPECT_EQ(m->paper_plant->contact.drag, 0);
  EXPECT_EQ(m->paper_plant->contact.drag_angular, 0);
  EXPECT_EQ(m->paper_plant->contact.rolling_resistance, 0);
  EXPECT_EQ(m->paper_plant->contact.mu, scene.sim.contact.mu);
  // The world's gravity is g sin(tilt).
  EXPECT_DOUBLE_EQ(m->plant->gravity, scene.sim.gravity * std::sin(scene.sim.tilt));
  // The hand is the scene's polynomial: x(0) = a (the tip), x(+-1) = 0.
  EXPECT_NEAR(m->hand->geometry(0.0).point.x(), scene.sim.hand.a, 1e-15);

  // The camera is compile_camera's, and the mapping and tracker see through it.
  ASSERT_TRUE(m->camera && m->mapping && m->tracker.camera);
  const auto direct = model::compile_camera(*scene.camera);
  EXPECT_EQ(m->camera->K, direct.K);
  EXPECT_EQ(m->camera->R, direct.R);
  EXPECT_EQ(m->camera->t, direct.t);
  EXPECT_EQ(m->mapping->camera.K, direct.K);
  EXPECT_EQ(m->mapping->plane_z, scene.render.disk_thickness);
  EXPECT_EQ(m->mapping->disk_radius, scene.sim.object.radius);
  EXPECT_EQ(m->mapping->axis_table, cv::Point2d(0, 0));
  EXPECT_EQ(m->tracker.plane_z, scene.render.disk_thickness);

  // The loop's configs carry the scene's values.
  EXPECT_EQ(m->controller.type, scene.controller.type);
  EXPECT_EQ(m->controller.paper.feedback, scene.controller.mode == "feedback");
  EXPECT_EQ(m->controller.paper.kp, scene.controller.kp);
  EXPECT_EQ(m->controller.paper.kd, scene.controller.kd);
  EXPECT_DOUBLE_EQ(m->control_dt, 1.0 / scene.joint.rate);
  EXPECT_EQ(m->safety.stop_deceleration, scene.controller.stop_deceleration);
  EXPECT_EQ(m->estimator.type, scene.estimator.type);
  EXPECT_EQ(m->safety.lost_timeout, scene.controller.lost_timeout);
  EXPECT_EQ(m->safety.innovation_strikes, scene.controller.innovation_strikes);
  EXPECT_EQ(m->estimator.config.process_noise, scene.estimator.process_noise);
  // The estimator's history reaches past the worst latency and two frames.
  EXPECT_GE(m->estimator.config.history,
            3 * (scene.camera->latency + scene.camera->latency_jitter) + 2 / scene.camera->fps);
}

TEST(Model, SectionsASceneLacksAreOff) {
  const auto m = model::compile(bundled("butterfly.yaml"));
  EXPECT_FALSE(m->camera);
  EXPECT_FALSE(m->mapping);
  EXPECT_FALSE(m->tracker.camera);
  EXPECT_TRUE(m->boards.empty());
}

TEST(Model, BoardsAreTheScenesTargetsInOrder) {
  Scene scene = bundled("butterfly-camera.yaml");
  flatland::TargetSpec charuco;
  charuco.kind = flatland::TargetSpec::Kind::kCharuco;
  charuco.squares_x = 5;
  charuco.squares_y = 4;
  charuco.position = {0.1, -0.2, 0.0};
  scene.targets.push_back(charuco);
  const auto m = model::compile(scene);
  ASSERT_EQ(m->boards.size(), scene.targets.size());
  const auto& last = m->boards.back();
  EXPECT_EQ(last.board.kind, flatland::camera::Board::Kind::kCharuco);
  EXPECT_EQ(last.board.squares_x, 5);
  EXPECT_EQ(last.position, cv::Vec3d(0.1, -0.2, 0.0));
}

TEST(Model, AnEllipseHasNoDiskMapping) {
  Scene scene = bundled("butterfly-camera.yaml");
  scene.sim.object.kind = sim::ObjectSpec::Kind::kEllipse;
  scene.sim.object.semi_axis_x = 0.05;
  scene.sim.object.semi_axis_y = 0.04;
  const auto m = model::compile(scene);
  EXPECT_TRUE(m->camera);
  EXPECT_FALSE(m->mapping);
  try {
    model::hand_mapping(*m, *m->camera);
    ADD_FAILURE() << "a mapping for an ellipse";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("object.type: ellipse: "), std::string::npos) << e.what();
  }
}

// The mapping offsets a ball on rails' centre by its rolling radius; the tracker cannot follow it
// (the hand hides its part beyond r), nor a ring (its hole): no mapping, one line naming the key.
TEST(Model, MappingUsesTheRollingRadiusAndRefusesWhatTheTrackerCannotFollow) {
  Scene scene = bundled("butterfly-camera.yaml");
  scene.sim.object.kind = sim::ObjectSpec::Kind::kBall;
  scene.sim.object.radius = 0.05;
  const auto plain = model::compile(scene);
  ASSERT_TRUE(plain->mapping);
  EXPECT_EQ(plain->mapping->disk_radius, 0.05);
  scene.sim.object.rail_gap = 0.06;  // rolling radius 0.04 (3-4-5)
  const auto on_rails = model::compile(scene);
  EXPECT_NEAR(*on_rails->plant->object.disk_radius, 0.04, 1e-15);
  EXPECT_FALSE(on_rails->mapping);
  EXPECT_EQ(model::tracking_problem(scene.sim.object)->rfind("object.rails: ", 0), 0u);
  scene.sim.object.kind = sim::ObjectSpec::Kind::kRing;
  scene.sim.object.rail_gap.reset();
  scene.sim.object.inner_radius = 0.03;
  EXPECT_FALSE(model::compile(scene)->mapping);
  EXPECT_EQ(model::tracking_problem(scene.sim.object)->rfind("object.type: ring: ", 0), 0u);
}

TEST(Model, ARecompiledEditIsANewWorldAndTheOldOneStays) {
  Scene scene = bundled("airtable-feedback.yaml");
  const auto before = model::compile(scene);
  scene.sim.object.radius *= 1.1;
  scene.sim.tilt *= 0.9;
  const auto after = model::compile(scene);
  EXPECT_DOUBLE_EQ(after->mapping->disk_radius, 1.1 * before->mapping->disk_radius);
  EXPECT_LT(after->plant->gravity, before->plant->gravity);
  EXPECT_EQ(before->spec.sim.object.radius, before->mapping->disk_radius);
}

TEST(Model, BadValuesAreOneLineErrorsNamingTheField) {
  Scene scene = bundled("butterfly-camera.yaml");
  scene.sim.object.radius = -1;
  EXPECT_EQ(compile_error(scene).rfind("object.radius", 0), 0u) << compile_error(scene);
  scene = bundled("butterfly-camera.yaml");
  scene.camera->look_at = {0, 0, 2};  // above the camera: the table is behind it
  const std::string e = compile_error(scene);
  EXPECT_EQ(e.rfind("camera.look_at: must be below the camera", 0), 0u) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos);
}

// The camera's rules are written once (camera_problem): the loader and compile_camera give the
// same field and reason for every rule.
TEST(Model, TheLoaderAndTheCompileStepReportTheSameCameraRule) {
  std::ifstream file(std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly.yaml");
  const std::string paper((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  ASSERT_FALSE(paper.empty());
  ASSERT_EQ(paper.find("\ncamera:"), std::string::npos);
  const std::string camera_section =
      paper +
      "\ncamera:\n  width: 640\n  height: 480\n  fx: 700\n  fy: 700\n"
      "  position: [0, 0, 1]\n  fps: 30\n";
  struct Case {
    std::string yaml;  // one more key of the camera section
    void (*edit)(CameraSpec&);
    std::string field;
  };
  const Case cases[] = {
      {"  look_at: [0, 0, 1]\n",
       [](CameraSpec& c) {
         c.look_at = {0, 0, 1};
       },
       "look_at"},
      {"  look_at: [1, 0, 1]\n",
       [](CameraSpec& c) {
         c.look_at = {1, 0, 1};
       },
       "look_at"},
      {"  up: [0, 0, 1]\n",
       [](CameraSpec& c) {
         c.up = {0, 0, 1};
       },
       "up"},
      {"  up: [0, 0, 0]\n",
       [](CameraSpec& c) {
         c.up = {0, 0, 0};
       },
       "up"},
      {"  exposure: 0.05\n", [](CameraSpec& c) { c.exposure = 0.05; }, "exposure"},
  };
  for (const Case& c : cases) {
    std::string loaded;
    try {
      flatland::parse_scene(camera_section + c.yaml, "x.yaml");
      ADD_FAILURE() << "the loader accepted " << c.yaml;
    } catch (const flatland::SceneError& e) {
      loaded = e.what();
    }
    CameraSpec spec;
    spec.position = {0, 0, 1};
    c.edit(spec);
    std::string compiled;
    try {
      model::compile_camera(spec);
      ADD_FAILURE() << "compile_camera accepted " << c.yaml;
    } catch (const std::invalid_argument& e) {
      compiled = e.what();
    }
    EXPECT_EQ(compiled.rfind("camera." + c.field + ": ", 0), 0u) << compiled;
    EXPECT_EQ("x.yaml: " + compiled, loaded);
  }
}

}  // namespace
