// The scene's `lighting` section: off without it, its defaults with it, and strict: known keys
// only, numbers in range, the lamp above the hand and the disk, one-line errors naming the field's
// path.
#include "flatland/scene/scene.hpp"
#include "scene/minimal_scene.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {

using flatland::parse_scene;
using flatland::Scene;
using flatland::SceneError;

// The minimum a scene must say, and the error of a lighting section appended to it.
using flatland_test::error_with_section;
using flatland_test::kMinimal;

}  // namespace

TEST(SceneLightingSection, AbsentIsOffAndPresentTakesTheDefaultsItDoesNotSet) {
  EXPECT_FALSE(parse_scene(kMinimal, "t.yaml").lighting.has_value());
  const Scene s = parse_scene(kMinimal + R"(lighting:
  position: [0.1, -0.2, 1.4]
  ambient: 0.2
  shadows: false
  materials:
    band: {specular: 0.7, shininess: 90}
)",
                              "t.yaml");
  ASSERT_TRUE(s.lighting.has_value());
  EXPECT_EQ(s.lighting->position[1], -0.2);
  EXPECT_EQ(s.lighting->ambient, 0.2);
  EXPECT_FALSE(s.lighting->shadows);
  EXPECT_TRUE(s.lighting->falloff);
  EXPECT_EQ(s.lighting->band.specular, 0.7);
  EXPECT_EQ(s.lighting->band.shininess, 90.0);
  const flatland::LightingSpec defaults;
  EXPECT_EQ(s.lighting->intensity, defaults.intensity);
  EXPECT_EQ(s.lighting->table.specular, defaults.table.specular);
}

TEST(SceneLightingSection, BadValuesAreRefusedNamingTheField) {
  EXPECT_EQ(error_with_section("lighting:\n  position: [0, 0, 0.01]\n"),
            "t.yaml: lighting.position: the lamp must be above the hand and the disk (z > 0.012 "
            "m, their top), got z = 0.01");
  EXPECT_EQ(error_with_section("lighting:\n  color: [1, 1.5, 1]\n"),
            "t.yaml: lighting.color[1]: must be in [0, 1], got 1.5");
  EXPECT_EQ(error_with_section("lighting:\n  ambient: -0.1\n"),
            "t.yaml: lighting.ambient: must be in [0, 1], got -0.1");
  EXPECT_EQ(error_with_section("lighting:\n  intensity: -1\n"),
            "t.yaml: lighting.intensity: must be finite and >= 0, got -1");
  EXPECT_EQ(error_with_section("lighting:\n  materials:\n    band:\n      shininess: 0.5\n"),
            "t.yaml: lighting.materials.band.shininess: must be in [1, 10000], got 0.5");
  EXPECT_EQ(error_with_section("lighting:\n  materials:\n    hand:\n      specular: 2\n"),
            "t.yaml: lighting.materials.hand.specular: must be in [0, 1], got 2");
  EXPECT_NE(error_with_section("lighting:\n  lamp: 1\n").find("t.yaml: lighting.lamp: unknown key"),
            std::string::npos);
  EXPECT_NE(error_with_section("lighting:\n  materials:\n    board: {}\n")
                .find("t.yaml: lighting.materials.board: unknown key"),
            std::string::npos);
  EXPECT_NE(error_with_section("lighting:\n  shadows: 3\n").find("t.yaml: lighting.shadows:"),
            std::string::npos);
}

TEST(SceneLightingSection, TheLampMustClearATallerHand) {
  EXPECT_EQ(
      error_with_section("render:\n  hand_thickness: 0.5\nlighting:\n  position: [0, 0, 0.4]\n"),
      "t.yaml: lighting.position: the lamp must be above the hand and the disk (z > 0.5 m, "
      "their top), got z = 0.4");
}
