// The scene's `controller.transverse` section: read strictly (unknown keys, wrong kinds and bad
// values are one-line errors naming the field), compiled into the controller choice's
// TransverseConfig, and the type `transverse` known to the compile step.
#include "flatland/model/model.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

using namespace flatland;

namespace {

std::string feedback_text() {
  std::ifstream in(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// The bundled feedback scene with `extra` appended to its controller section.
std::string with_controller_lines(const std::string& extra) {
  std::string text = feedback_text();
  const std::string anchor = "controller:\n";
  const auto pos = text.find(anchor);
  EXPECT_NE(pos, std::string::npos) << "test bug: no controller section";
  text.insert(pos + anchor.size(), extra);
  return text;
}

std::string error_of(const std::string& yaml) {
  try {
    const Scene scene = parse_scene(yaml, "t.yaml");
    model::compile(scene);
  } catch (const SceneError& e) {
    return e.what();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "NO ERROR";
}

void expect_field_error(const std::string& extra, const std::string& field,
                        const std::string& reason_part) {
  const std::string msg = error_of(with_controller_lines(extra));
  EXPECT_EQ(msg.rfind("t.yaml: " + field + ": ", 0), 0u) << msg;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  EXPECT_NE(msg.find(reason_part), std::string::npos) << msg;
}

}  // namespace

TEST(TransverseConfig, SectionIsReadAndCompiled) {
  const Scene scene = parse_scene(
      with_controller_lines("  type: transverse\n  transverse:\n    q: [1.0e5, 20, 3.5]\n"
                            "    r: 0.5\n    terminal: [0, 1, 2]\n    grid_step: 0.002\n"),
      "t.yaml");
  EXPECT_EQ(scene.controller.type, "transverse");
  const auto m = model::compile(scene);
  EXPECT_EQ(m->controller.type, "transverse");
  const control::TransverseConfig& c = m->controller.transverse;
  EXPECT_EQ(c.q[0], 1.0e5);
  EXPECT_EQ(c.q[1], 20.0);
  EXPECT_EQ(c.q[2], 3.5);
  EXPECT_EQ(c.r, 0.5);
  EXPECT_EQ(c.terminal[0], 0.0);
  EXPECT_EQ(c.terminal[2], 2.0);
  EXPECT_EQ(c.grid_step, 0.002);
  // The controller the choice makes is the transverse law.
  EXPECT_EQ(control::make_controller(m->controller)->name(), "transverse");
}

TEST(TransverseConfig, DefaultsAreTheControllersOwn) {
  const Scene scene = parse_scene(with_controller_lines("  type: transverse\n"), "t.yaml");
  const auto m = model::compile(scene);
  const control::TransverseConfig defaults;
  EXPECT_EQ(m->controller.transverse.q, defaults.q);
  EXPECT_EQ(m->controller.transverse.r, defaults.r);
  EXPECT_EQ(m->controller.transverse.terminal, defaults.terminal);
  EXPECT_EQ(m->controller.transverse.grid_step, defaults.grid_step);
}

TEST(TransverseConfig, BadKeysAndValuesNameTheField) {
  expect_field_error("  transverse:\n    qq: [1, 2, 3]\n", "controller.transverse.qq",
                     "unknown key (allowed: q, r, terminal, grid_step)");
  expect_field_error("  transverse:\n    q: 3\n", "controller.transverse.q",
                     "expected a list of 3 numbers");
  expect_field_error("  transverse:\n    q: [1, 2]\n", "controller.transverse.q", "a list of 2");
  expect_field_error("  transverse:\n    q: [1, abc, 2]\n", "controller.transverse.q[1]",
                     "expected a number");
  expect_field_error("  transverse:\n    terminal: [1, 2, -3]\n",
                     "controller.transverse.terminal[2]", "must be >= 0");
  expect_field_error("  transverse:\n    r: 0\n", "controller.transverse.r", "positive");
  expect_field_error("  transverse:\n    r: [1]\n", "controller.transverse.r", "expected a number");
  expect_field_error("  transverse:\n    grid_step: 0.1\n", "controller.transverse.grid_step",
                     "at most 0.01");
  expect_field_error("  transverse: 3\n", "controller.transverse", "expected a mapping");
  expect_field_error("  type: nope\n", "controller.type", "(known: paper, transverse)");
  // Open-loop playback has no law: only the paper's type plays it.
  std::string open_loop = with_controller_lines("  type: transverse\n");
  const auto mode = open_loop.find("mode: feedback");
  ASSERT_NE(mode, std::string::npos) << "test bug: the scene's mode line";
  open_loop.replace(mode, 14, "mode: open-loop");
  const std::string msg = error_of(open_loop);
  EXPECT_EQ(msg.rfind("t.yaml: controller.mode: ", 0), 0u) << msg;
  EXPECT_NE(msg.find("only controller.type paper"), std::string::npos) << msg;
}
