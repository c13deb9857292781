// The scene's `estimator` section: its type is read as text (the compile step checks it against
// control's registry), and the unscented filter's subsection `estimator.ukf` is strict: known
// keys only, numbers in range, one-line errors naming the field's path.
#include "flatland/scene/scene.hpp"
#include "scene/minimal_scene.hpp"

#include <gtest/gtest.h>

#include <string>

namespace {

using flatland::parse_scene;
using flatland::Scene;
using flatland::SceneError;

// The minimum a scene must say, and the error of an estimator section appended to it.
using flatland_test::error_with_section;
using flatland_test::kMinimal;

TEST(SceneEstimatorSection, DefaultsAreTheEkfAndTheUnscentedTransformsJulierPoints) {
  const Scene s = parse_scene(kMinimal, "t.yaml");
  EXPECT_EQ(s.estimator.type, "ekf");
  // n + kappa = 3 with alpha = 1: the points at +-sqrt(3) sigma; beta = 2 for a Gaussian.
  EXPECT_EQ(s.estimator.ukf.alpha, 1.0);
  EXPECT_EQ(s.estimator.ukf.beta, 2.0);
  EXPECT_EQ(s.estimator.ukf.kappa, 1.0);
}

TEST(SceneEstimatorSection, TypeAndSigmaPointsAreRead) {
  const Scene s = parse_scene(
      kMinimal + "estimator:\n  type: ukf\n  ukf:\n    alpha: 0.5\n    beta: 0\n    kappa: 3\n",
      "t.yaml");
  EXPECT_EQ(s.estimator.type, "ukf");
  EXPECT_EQ(s.estimator.ukf.alpha, 0.5);
  EXPECT_EQ(s.estimator.ukf.beta, 0.0);
  EXPECT_EQ(s.estimator.ukf.kappa, 3.0);
  // Any text is a type here; model::compile checks it against the registry.
  EXPECT_EQ(parse_scene(kMinimal + "estimator:\n  type: mine\n", "t.yaml").estimator.type, "mine");
}

TEST(SceneEstimatorSection, BadSigmaPointsAreOneLineErrorsNamingTheField) {
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    alpha: 0\n"),
            "t.yaml: estimator.ukf.alpha: must be in [1e-04, 1], got 0");
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    alpha: 1.5\n"),
            "t.yaml: estimator.ukf.alpha: must be in [1e-04, 1], got 1.5");
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    beta: -1\n"),
            "t.yaml: estimator.ukf.beta: must be >= 0, got -1");
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    kappa: .nan\n"),
            "t.yaml: estimator.ukf.kappa: must be a finite number, got .nan");
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    kappa: \"3\"\n"),
            "t.yaml: estimator.ukf.kappa: expected a number, got the string '3' (remove the "
            "quotes)");
  EXPECT_EQ(error_with_section("estimator:\n  ukf:\n    lambda: 1\n"),
            "t.yaml: estimator.ukf.lambda: unknown key (allowed: alpha, beta, kappa)");
  EXPECT_EQ(error_with_section("estimator:\n  ukf: 3\n"),
            "t.yaml: estimator.ukf: expected a mapping of keys, got '3'");
  EXPECT_EQ(error_with_section("estimator:\n  type: [ukf]\n")
                .rfind("t.yaml: estimator.type: expected a "
                       "string",
                       0),
            0u);
  EXPECT_EQ(error_with_section("estimator:\n  filter: ukf\n")
                .rfind("t.yaml: estimator.filter: unknown key", 0),
            0u);
}

}  // namespace
