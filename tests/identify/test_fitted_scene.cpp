// The fitted scene (identify/fitted_scene.hpp): the scene identify started from with the
// determined values in place, loadable and compilable, carrying exactly those values, keeping
// the scene's value where the data determined none, and saying where the values came from.
#include "flatland/identify/fitted_scene.hpp"
#include "flatland/model/model.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/format.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>
#include <string>

namespace {

using namespace flatland::identify;

std::string read_asset(const std::string& name) {
  std::ifstream in(std::string(FLATLAND_ASSET_DIR) + "/scenes/" + name);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

ParameterEstimate determined(const std::string& name, double value, double sigma) {
  ParameterEstimate p;
  p.name = name;
  p.value = value;
  p.initial = value * 1.1;
  p.sigma = sigma;
  return p;
}

ParameterEstimate undetermined(const std::string& name, double value, const std::string& why) {
  ParameterEstimate p;
  p.name = name;
  p.value = value;
  p.not_determined = why;
  return p;
}

/// A fit's result as identify reports it: mu_kinetic, tilt and the angle offset determined,
/// restitution and drag not.
IdentifyResult example_result() {
  IdentifyResult r;
  r.parameters = {determined("mu_kinetic", 0.5512345678901234, 0.0123),
                  undetermined("restitution", 0.93, "at its upper bound"),
                  determined("tilt", 0.0905, 0.0004),
                  undetermined("drag", 0.2,
                               "cannot be separated from rolling_resistance "
                               "(correlation -0.998)"),
                  determined("rolling_resistance", 4.2e-5, 3e-6),
                  determined("angle_offset", 0.0021, 0.0003)};
  r.chi2 = 812.5;
  r.degrees_of_freedom = 790;
  r.iterations = 12;
  r.converged = true;
  return r;
}

FitProvenance example_provenance(const std::string& scene) {
  return {scene,
          "flatland identify " + scene + " run1 --unknowns mu_kinetic,restitution",
          {"run1 (experiment, 118 samples)"}};
}

TEST(FittedScene, AirTableSceneCarriesTheDeterminedValuesAndKeepsItsComments) {
  const std::string original = read_asset("airtable-5deg.yaml");
  const IdentifyResult r = example_result();
  const std::string text = fitted_scene(original, r, example_provenance("airtable-5deg.yaml"));
  const flatland::Scene scene = flatland::parse_scene(text, "fitted.yaml");
  const flatland::Scene before = flatland::parse_scene(original, "original.yaml");
  // Determined: in place, to the last bit (tilt through degrees and back to within rounding).
  EXPECT_EQ(scene.sim.contact.mu_kinetic.value(), 0.5512345678901234);
  EXPECT_EQ(scene.sim.contact.rolling_resistance, 4.2e-5);
  EXPECT_NEAR(scene.sim.tilt, 0.0905, 1e-15);
  // Not determined: the scene's own values, not the fit's.
  EXPECT_EQ(scene.sim.contact.restitution, before.sim.contact.restitution);
  EXPECT_EQ(scene.sim.contact.drag, before.sim.contact.drag);
  // Untouched keys stay.
  EXPECT_EQ(scene.sim.contact.mu, before.sim.contact.mu);
  EXPECT_EQ(scene.sim.hand.a, before.sim.hand.a);
  EXPECT_EQ(scene.sim.run.model, flatland::sim::ContactModel::kHybrid);
  // Ready for experiment, montecarlo and render: it compiles.
  EXPECT_NO_THROW(flatland::model::compile(scene));
  // Its own comments survive; the replaced lines say what they were.
  EXPECT_NE(text.find("rubber O-rings on dry aluminium"), std::string::npos);
  EXPECT_NE(text.find("mu_kinetic: 0.5512345678901234  # identified: 0.5512345678901234 +- "
                      "0.012 (was 0.6)"),
            std::string::npos)
      << text;
  // The comment block: provenance, chi^2 against dof, every parameter.
  EXPECT_EQ(text.rfind("# World parameters identified", 0), 0u);
  EXPECT_NE(text.find("run1 (experiment, 118 samples)"), std::string::npos);
  EXPECT_NE(text.find("chi^2 = 812.5 for 790 degrees of freedom (chi^2/dof = 1.028)"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("restitution: not determined (at its upper bound)  (contact.restitution: "
                      "the scene's value kept)"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("angle_offset: 0.0021 +- 0.0003 rad  (not a scene key"), std::string::npos);
  EXPECT_NE(text.find("-> gravity.tilt_deg (" +
                      flatland::sim::format_number(0.0905 * 180 / std::numbers::pi) + ")"),
            std::string::npos)
      << text;
}

TEST(FittedScene, KeysTheSceneLacksAreAddedToItsSections) {
  // The paper's scene: rolling model, no restitution or losses, a contact section without mu.
  const std::string original = read_asset("butterfly.yaml");
  IdentifyResult r;
  r.parameters = {determined("restitution", 0.35, 0.02), determined("drag", 0.011, 0.001)};
  const std::string text = fitted_scene(original, r, example_provenance("butterfly.yaml"));
  const flatland::Scene scene = flatland::parse_scene(text, "fitted.yaml");
  EXPECT_EQ(scene.sim.contact.restitution, 0.35);
  EXPECT_EQ(scene.sim.contact.drag, 0.011);
  EXPECT_EQ(scene.sim.run.model, flatland::sim::ContactModel::kHybrid);
  EXPECT_NE(text.find("The paper's butterfly in full gravity"), std::string::npos);
  // The rolling model's stop_on_contact_loss, which the hybrid model refuses, is commented out.
  EXPECT_NE(text.find("  # stop_on_contact_loss: true"), std::string::npos) << text;
  EXPECT_NO_THROW(flatland::model::compile(scene));
}

TEST(FittedScene, AKineticCoefficientBringsTheStaticOneTheFitUsed) {
  // The paper's scene has no mu; mu_kinetic alone would be refused (it needs mu).
  IdentifyResult r;
  r.parameters = {determined("mu_kinetic", 0.45, 0.02)};
  r.world.contact.mu = 0.9;
  const std::string text =
      fitted_scene(read_asset("butterfly.yaml"), r, example_provenance("butterfly.yaml"));
  const flatland::Scene scene = flatland::parse_scene(text, "fitted.yaml");
  EXPECT_EQ(scene.sim.contact.mu.value(), 0.9);
  EXPECT_EQ(scene.sim.contact.mu_kinetic.value(), 0.45);
  EXPECT_NE(text.find("mu: 0.9  # the static coefficient the fit simulated with (not identified)"),
            std::string::npos)
      << text;
}

TEST(FittedScene, ASectionMissingOrInFlowStyleIsStillWritten) {
  const std::string base = read_asset("butterfly.yaml");
  // Without a contact section: one is appended.
  std::string no_contact = base.substr(0, base.find("contact:"));
  IdentifyResult r;
  r.parameters = {determined("mu_static", 0.7, 0.05), determined("mu_kinetic", 0.5, 0.04)};
  const flatland::Scene a =
      flatland::parse_scene(fitted_scene(no_contact, r, example_provenance("a.yaml")), "a");
  EXPECT_EQ(a.sim.contact.mu.value(), 0.7);
  EXPECT_EQ(a.sim.contact.mu_kinetic.value(), 0.5);
  // A flow-style section: the document is written anew and still carries the values.
  const std::string flow =
      no_contact + "contact: {model: rolling, mu: 0.9, stop_on_contact_loss: true}\n";
  const flatland::Scene b =
      flatland::parse_scene(fitted_scene(flow, r, example_provenance("b.yaml")), "b");
  EXPECT_EQ(b.sim.contact.mu.value(), 0.7);
  EXPECT_EQ(b.sim.contact.mu_kinetic.value(), 0.5);
  EXPECT_EQ(b.sim.run.model, flatland::sim::ContactModel::kHybrid);
  EXPECT_EQ(b.sim.hand.c, a.sim.hand.c);
}

TEST(FittedScene, NotAMappingIsRefused) {
  EXPECT_THROW(fitted_scene("- 1\n- 2\n", example_result(), example_provenance("x.yaml")),
               std::invalid_argument);
  EXPECT_THROW(fitted_scene("a: [1, \n", example_result(), example_provenance("x.yaml")),
               std::invalid_argument);
}

TEST(FittedScene, SceneKeysOfTheParameters) {
  for (const std::string& name : parameter_names()) {
    const auto key = scene_key(name);
    EXPECT_EQ(key.has_value(), name != "angle_offset" && name != "time_offset") << name;
  }
  EXPECT_EQ(scene_key("tilt")->key, "tilt_deg");
  EXPECT_DOUBLE_EQ(scene_key("tilt")->scale, 180 / std::numbers::pi);
}

}  // namespace
