// End-to-end tests of choosing the closed loop's controller and estimator by name: `flatland
// experiment --controller NAME --estimator NAME` and the scene's `controller.type` /
// `estimator.type`. A run reports what ran (result.json `controller_type`, `estimator`); bad
// names and bad config values are one line naming the option or field, exit 2, nothing written.
// What a run must do is known without the program: the butterfly carries the disk from the palm
// well to the back well (s_h from -1 to about +1) and turns the hand from 0 to pi.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <numbers>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::lines_of;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

class CliLoopChoiceTest : public flatland_test::CliTestBase {
 protected:
  /// Bad input: exit 2, one line "flatland: error: ..." containing every one of `what`, nothing
  /// on stdout, `out` not created.
  void expect_bad_input(const std::string& args, const std::vector<std::string>& what) const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << "stderr: " << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    for (const std::string& w : what)
      EXPECT_NE(err[0].find(w), std::string::npos)
          << "message does not name " << w << ": " << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "out")) << "created out";
  }

  /// The bundled closed-loop scene with one line replaced (`from` must occur once).
  void write_scene(const std::string& name, const std::string& from, const std::string& to) const {
    std::string scene =
        read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "airtable-feedback.yaml");
    const auto at = scene.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    ASSERT_EQ(scene.find(from, at + 1), std::string::npos) << from;
    scene.replace(at, from.size(), to);
    write_text(dir_ / name, scene);
  }
};

TEST_F(CliLoopChoiceTest, HelpListsTheKnownControllersAndEstimators) {
  const Result r = run("experiment --help");
  EXPECT_EQ(r.code, 0) << r.err;
  for (const char* s :
       {"--controller", "open-loop", "feedback", "paper", "--estimator", "ekf", "ukf"})
    EXPECT_NE(r.out.find(s), std::string::npos) << "help does not mention " << s << ":\n" << r.out;
}

// The unscented filter in the loop on the default scene (the paper's controller, the synthetic
// air table): the motion succeeds, and the result names what ran.
TEST_F(CliLoopChoiceTest, AnExperimentWithTheUnscentedFilterSucceeds) {
  const Result r = run("experiment --estimator ukf --controller paper --out out --no-plot --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["estimator"], "ukf");
  EXPECT_EQ(j["controller_type"], "paper");
  EXPECT_EQ(j["controller"], "paper");
  EXPECT_EQ(j["success"], true) << j.dump();
  EXPECT_EQ(j["safe_stop"], false) << j.dump();
  EXPECT_NEAR(j["s_end"].get<double>(), 1.0, 0.1);
  // The filter stayed consistent with the world it estimated: time-averaged NEES of 2 degrees of
  // freedom is 2; a filter that is off (overconfident, lagging) gives tens to thousands.
  EXPECT_LT(j["nees_mean"].get<double>(), 6.0);
  EXPECT_EQ(json::parse(read_text(dir_ / "out" / "result.json")), j);
  // The paper controller's modes, in its order, are in the log.
  const std::string log = read_text(dir_ / "out" / "log.csv");
  for (const char* mode : {",dip,", ",servo,", ",finish,", ",done,"})
    EXPECT_NE(log.find(mode), std::string::npos) << mode;
}

// The default run names the scene's choice: the paper's controller and the EKF.
TEST_F(CliLoopChoiceTest, TheDefaultRunReportsThePaperControllerAndTheEkf) {
  const Result r = run("experiment --controller open-loop --out out --no-plot --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["controller"], "open-loop");
  EXPECT_EQ(j["controller_type"], "paper");
  EXPECT_EQ(j["estimator"], "ekf");
  EXPECT_NE(read_text(dir_ / "out" / "log.csv").find(",open-loop,"), std::string::npos);
}

TEST_F(CliLoopChoiceTest, BadNamesAndConfigsExit2AndWriteNothing) {
  expect_bad_input("experiment --controller pid --out out",
                   {"--controller: unknown type 'pid'", "open-loop", "feedback", "paper"});
  expect_bad_input("experiment --estimator particle --out out",
                   {"--estimator: unknown type 'particle'", "ekf", "ukf"});

  write_scene("controller.yaml", "  mode: feedback ", "  type: pid\n  mode: feedback ");
  expect_bad_input("experiment --scene controller.yaml --out out",
                   {"controller.yaml", "controller.type: unknown type 'pid'", "(known: paper"});
  write_scene("estimator.yaml", "  model: rolling ", "  type: particle\n  model: rolling ");
  expect_bad_input("experiment --scene estimator.yaml --out out",
                   {"estimator.yaml", "estimator.type: unknown type 'particle' (known: ekf, ukf)"});
  // Monte Carlo refuses the same scenes before it starts (no banner line before the error).
  expect_bad_input("montecarlo --scene controller.yaml --n 2 --out out",
                   {"controller.yaml", "controller.type: unknown type 'pid'"});
  expect_bad_input("montecarlo --scene estimator.yaml --n 2 --out out",
                   {"estimator.yaml", "estimator.type: unknown type 'particle'"});
  // A controller config key of the wrong kind, and one out of range.
  write_scene("kp.yaml", "  kp: 900 ", "  kp: \"fast\" ");
  expect_bad_input("experiment --scene kp.yaml --out out", {"kp.yaml", "controller.kp", "string"});
  write_scene("kd.yaml", "  kd: 120 ", "  kd: fast ");
  expect_bad_input("experiment --scene kd.yaml --out out",
                   {"controller.kd: expected a number, got 'fast'"});
  // The unscented filter's own section is strict too.
  write_scene("alpha.yaml", "  latency_compensation: true",
              "  latency_compensation: true\n  ukf:\n    alpha: 2");
  expect_bad_input("experiment --scene alpha.yaml --out out",
                   {"estimator.ukf.alpha: must be in [1e-04, 1], got 2"});
  write_scene("sigma.yaml", "  latency_compensation: true",
              "  latency_compensation: true\n  ukf:\n    lambda: 1");
  expect_bad_input("experiment --scene sigma.yaml --out out",
                   {"estimator.ukf.lambda: unknown key (allowed: alpha, beta, kappa)"});
}

}  // namespace
