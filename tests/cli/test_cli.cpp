// End-to-end tests of the `flatland` program: run the built binary in a fresh temporary directory
// and check exit codes, stdout JSON, stderr messages and the files it leaves behind. Reference
// numbers come from the paper (section 4.3), never from the program's own output.
#include "cli_support.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

class CliFixture : public flatland_test::CliTestBase {
 protected:
  // A copy of the bundled paper scene with `from` replaced by `to` (which must occur).
  fs::path scene_with(const std::string& name, const std::string& from,
                      const std::string& to) const {
    std::string text = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly.yaml");
    const auto pos = text.find(from);
    EXPECT_NE(pos, std::string::npos) << "the bundled scene no longer contains '" << from << "'";
    if (pos != std::string::npos) text.replace(pos, from.size(), to);
    const fs::path p = dir_ / name;
    write_text(p, text);
    return p;
  }

  // Bad input: exit 2, one line "flatland: error: ..." naming `field`, nothing on stdout, and
  // `out` (relative to the working directory) not created.
  void expect_bad_input(const std::string& args, const std::string& field,
                        const std::string& out, const std::string& env = "") const {
    const Result r = run(args, env);
    EXPECT_EQ(r.code, 2) << args << "\nstderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << args << "\nstderr: " << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(field), std::string::npos)
        << "message does not name " << field << ": " << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / out)) << args << " created " << out;
  }

  static json parse_json(const Result& r) {
    json j;
    EXPECT_NO_THROW(j = json::parse(r.out)) << "stdout is not one JSON value:\n" << r.out;
    EXPECT_TRUE(j.is_object());
    return j;
  }

  static void expect_keys(const json& j, const std::set<std::string>& required,
                          const std::set<std::string>& optional) {
    for (const auto& k : required) EXPECT_TRUE(j.contains(k)) << "missing key " << k;
    for (const auto& [k, v] : j.items())
      EXPECT_TRUE(required.count(k) || optional.count(k)) << "unexpected key " << k;
  }

  // Files left in `d` whose name contains ".tmp-" (staging leftovers).
  static int temporaries_in(const fs::path& d) {
    int n = 0;
    for (const auto& e : fs::recursive_directory_iterator(d))
      if (e.path().filename().string().find(".tmp-") != std::string::npos) ++n;
    return n;
  }

  static bool is_png(const fs::path& p) {
    const std::string s = read_text(p);
    return s.size() > 8 && s.compare(1, 3, "PNG") == 0;
  }

  static bool have_gnuplot() { return std::system("command -v gnuplot > /dev/null 2>&1") == 0; }
};

using CliHelp = CliFixture;
using CliSimulate = CliFixture;
using CliSolve = CliFixture;
using CliLocus = CliFixture;
using CliSurface = CliFixture;
using CliTimeOptimal = CliFixture;
using CliDesign = CliFixture;
using CliBadInput = CliFixture;
using CliRuntimeFailure = CliFixture;

const char* const kTrajectoryHeader =
    "t,theta,theta_dot,theta_ddot,s_h,sdot_h,sddot_h,s_o,sdot_o,x,y,object_angle,vx,vy,omega,f_n,f_"
    "t,"
    "fn_ratio,ft_ratio,mu_required,constraint_residual,redundant_residual,mode,slip_velocity,gap,"
    "rolling_couple";

// ---- help -------------------------------------------------------------------------------------

TEST_F(CliHelp, TopLevelListsCommandsAndUnits) {
  const Result r = run("--help");
  EXPECT_EQ(r.code, 0);
  for (const char* cmd : {"simulate", "solve", "locus", "surface", "time-optimal", "design"})
    EXPECT_NE(r.out.find(cmd), std::string::npos) << cmd;
  EXPECT_NE(r.out.find("lengths in m"), std::string::npos);
  EXPECT_NE(r.out.find("times in s"), std::string::npos);
  EXPECT_NE(r.out.find("Exit codes"), std::string::npos);
}

TEST_F(CliHelp, EveryCommandExplainsUnitsAndDefaults) {
  for (const char* cmd : {"simulate", "solve", "locus", "surface", "time-optimal", "design"}) {
    const Result r = run(std::string(cmd) + " --help");
    EXPECT_EQ(r.code, 0) << cmd;
    EXPECT_NE(r.out.find("2T"), std::string::npos) << cmd;
    EXPECT_NE(r.out.find(", s ("), std::string::npos) << cmd << ": no option states seconds";
    EXPECT_NE(r.out.find("Default:"), std::string::npos) << cmd;
    for (const char* opt : {"--scene", "--json", "--out"})
      EXPECT_NE(r.out.find(opt), std::string::npos) << cmd << " " << opt;
    // Every option line states its default.
    for (const auto& line : lines_of(r.out)) {
      if (line.rfind("  --", 0) == 0 && line.find("--help") == std::string::npos &&
          line.find("{") == std::string::npos) {  // enum options wrap their help onto the next line
        EXPECT_NE(line.find("Default"), std::string::npos) << cmd << ": " << line;
      }
    }
  }
}

// ---- simulate ---------------------------------------------------------------------------------

TEST_F(CliSimulate, JsonHasRequiredKeys) {
  const Result r = run("simulate --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  expect_keys(j,
              {"period", "k", "s_T", "s_end", "sdot_end", "fn_apex_ratio", "fn_min_ratio",
               "mu_required", "steps", "rhs_evals", "contact_lost", "energy"},
              {"formulation", "method", "stop_reason", "rejected", "restarts", "junction_crossings",
               "max_constraint_residual", "max_redundant_residual", "t_end", "csv", "model", "mu",
               "end_mode", "mode_changes", "impacts", "mode_time", "flights", "events", "object"});
  // The scene is the paper's Figure 2 motion: 2T = 1.181 s, k = -1.1393 (inputs, echoed).
  EXPECT_DOUBLE_EQ(j["period"].get<double>(), 1.181);
  EXPECT_DOUBLE_EQ(j["k"].get<double>(), -1.1393);
  EXPECT_GT(j["steps"].get<long>(), 0);
  // Paper: that motion keeps contact and brings the disk to the back of the hand (s_h = 1).
  EXPECT_FALSE(j["contact_lost"].get<bool>());
  EXPECT_NEAR(j["s_end"].get<double>(), 1.0, 0.05);
}

TEST_F(CliSimulate, FastMotionLosesContactAndReportsNull) {
  // Paper: no motion faster than 2T = 1.095 s keeps contact. The run stops where contact is lost,
  // before T, so s_h(T) does not exist: JSON null, not NaN.
  const Result r = run("simulate --period 1.0 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  EXPECT_TRUE(j["contact_lost"].get<bool>());
  EXPECT_TRUE(j["s_T"].is_null());
  EXPECT_EQ(j["stop_reason"], "contact_lost");
}

// The bundled throw-and-catch scene (paper section 5): the disk leaves the hand before the
// fingertip, lands on the back half (0 < s_h < 1), bounces, is caught and stays on the hand.
TEST_F(CliSimulate, ThrowAndCatchReportsTheFlight) {
  const Result r = run("simulate --scene " + std::string(FLATLAND_ASSET_DIR) +
                       "/scenes/throw-catch.yaml --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  EXPECT_EQ(j["model"], "hybrid");
  ASSERT_EQ(j["flights"].size(), 1u) << j.dump(2);
  const json& f = j["flights"][0];
  EXPECT_LT(f["s_lift_off"].get<double>(), 0.0);  // before the tip
  ASSERT_FALSE(f["t_landing"].is_null());
  EXPECT_GT(f["t_landing"].get<double>(), f["t_lift_off"].get<double>());
  EXPECT_NEAR(f["duration"].get<double>(),
              f["t_landing"].get<double>() - f["t_lift_off"].get<double>(), 1e-12);
  EXPECT_GT(f["s_landing"].get<double>(), 0.0);  // past the tip, on the back half
  EXPECT_LT(f["s_landing"].get<double>(), 1.0);
  EXPECT_GT(f["impulse_normal"].get<double>(), 0.0);
  ASSERT_FALSE(f["t_caught"].is_null());
  EXPECT_GE(f["t_caught"].get<double>(), f["t_landing"].get<double>());
  EXPECT_FALSE(f["dropped"].get<bool>());
  EXPECT_GT(j["mode_time"]["flight"].get<double>(), 0.0);
  EXPECT_NE(j["end_mode"], "flight");
  // The events in time order: the lift-off, then the impacts (the last one caught).
  std::vector<std::string> kinds;
  double t_prev = -1e9;
  for (const auto& e : j["events"]) {
    EXPECT_GE(e["t"].get<double>(), t_prev);
    t_prev = e["t"].get<double>();
    kinds.push_back(e["kind"]);
  }
  const auto lift = std::find(kinds.begin(), kinds.end(), "lift_off");
  ASSERT_NE(lift, kinds.end());
  EXPECT_NE(std::find(lift, kinds.end(), "impact"), kinds.end());
  EXPECT_EQ(j["impacts"].get<int>(),
            static_cast<int>(std::count(kinds.begin(), kinds.end(), "impact")));
}

TEST_F(CliSimulate, WritesSampledCsv) {
  const Result r = run("simulate --out traj/run.csv --sample-dt 0.01");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rows = lines_of(read_text(dir_ / "traj" / "run.csv"));
  ASSERT_GE(rows.size(), 2u);
  EXPECT_EQ(rows[0], kTrajectoryHeader);
  // 0, 0.01, ..., 1.18 and the end time 1.181 s (the scene's duration).
  EXPECT_GE(rows.size() - 1, 119u);
  EXPECT_LE(rows.size() - 1, 121u);
  EXPECT_EQ(rows[1].substr(0, 2), "0,");
  EXPECT_NEAR(std::stod(rows.back().substr(0, rows.back().find(','))), 1.181, 1e-12);
  EXPECT_EQ(temporaries_in(dir_), 0);
}

TEST_F(CliSimulate, HumanSummaryOnStdout) {
  const Result r = run("simulate");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("required mu"), std::string::npos) << r.out;
}

// ---- solve ------------------------------------------------------------------------------------

TEST_F(CliSolve, JsonMatchesPaper) {
  const Result r = run("solve --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  expect_keys(j,
              {"period", "k", "s_T", "s_end", "sdot_end", "fn_apex_ratio", "fn_min_ratio",
               "mu_required", "energy"},
              {"simulations", "rhs_evals", "contact_lost", "files", "friction_margin"});
  // Paper section 4.3: 2T = 1.181 s is solved by k = -1.1393, with the normal force at the apex
  // 17.5 % of m g and a required friction coefficient of 0.306.
  EXPECT_NEAR(j["k"].get<double>(), -1.1393, 1e-3);
  EXPECT_NEAR(j["fn_apex_ratio"].get<double>(), 0.175, 0.01);
  EXPECT_NEAR(j["mu_required"].get<double>(), 0.306, 0.01);
  // A solution is symmetric: at the fingertip at T, at rest on the back (s_h = 1) at 2T.
  EXPECT_NEAR(j["s_T"].get<double>(), 0.0, 1e-6);
  EXPECT_NEAR(j["s_end"].get<double>(), 1.0, 1e-4);
  EXPECT_NEAR(j["sdot_end"].get<double>(), 0.0, 1e-3);
  EXPECT_FALSE(j["contact_lost"].get<bool>());
}

TEST_F(CliSolve, WritesTrajectoryAndPlots) {
  const bool plots = have_gnuplot();
  const Result r = run(std::string("solve --out results/") + (plots ? "" : " --no-plot"));
  ASSERT_EQ(r.code, 0) << r.err;
  const fs::path d = dir_ / "results";
  const auto rows = lines_of(read_text(d / "trajectory.csv"));
  ASSERT_GE(rows.size(), 2u);
  EXPECT_EQ(rows[0], kTrajectoryHeader);
  EXPECT_NEAR(static_cast<double>(rows.size() - 1), 1182.0, 1.0);  // every 1 ms over 1.181 s
  if (plots) {
    EXPECT_TRUE(is_png(d / "trajectory.png"));
    EXPECT_TRUE(is_png(d / "forces.png"));
    EXPECT_TRUE(fs::exists(d / "trajectory.gp"));
  }
  EXPECT_EQ(temporaries_in(d), 0);
}

TEST_F(CliSolve, ForcePlotSaysWhatTheForcesAreDividedBy) {
  // The ratios are over the in-plane weight m g sin(tilt), not the weight m g (at the air table's
  // 5 degrees the two differ 11.5 times). The gnuplot script names it.
  const Result r = run("solve --out results/");
  if (!have_gnuplot()) GTEST_SKIP() << "no gnuplot";
  ASSERT_EQ(r.code, 0) << r.err;
  std::vector<std::string> ylabels;
  for (const std::string& line : lines_of(read_text(dir_ / "results" / "forces.gp")))
    if (line.rfind("set ylabel", 0) == 0) ylabels.push_back(line);
  ASSERT_EQ(ylabels.size(), 2u);
  EXPECT_EQ(ylabels[0], "set ylabel 'force / (m g sin(tilt)), the in-plane weight'");
  EXPECT_NE(ylabels[1].find("required mu"), std::string::npos) << ylabels[1];
  const std::string script = read_text(dir_ / "results" / "forces.gp");
  EXPECT_EQ(script.find("/mg"), std::string::npos);
  EXPECT_EQ(script.find("(m g)"), std::string::npos);
  // The text summary uses the same unit.
  const Result text = run("solve");
  EXPECT_NE(text.out.find("f_n at apex        0.1"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find(" m g sin(tilt)"), std::string::npos) << text.out;
  EXPECT_EQ(text.out.find("/ mg"), std::string::npos) << text.out;
}

TEST_F(CliHelp, HelpIsTrueAboutScenesAndWeights) {
  const Result top = run("--help");
  EXPECT_NE(top.out.find("in-plane weight m g sin(tilt)"), std::string::npos) << top.out;
  // Every command reads a scene, as the top-level help says.
  for (const char* cmd :
       {"simulate", "solve", "locus", "surface", "time-optimal", "render", "render-calibration",
        "calibrate", "track", "experiment", "montecarlo", "study"}) {
    const Result r = run(std::string(cmd) + " --help");
    EXPECT_EQ(r.code, 0) << cmd;
    EXPECT_NE(r.out.find("--scene"), std::string::npos) << cmd;
    EXPECT_EQ(r.out.find(" m g)"), std::string::npos) << cmd;
    EXPECT_EQ(r.out.find("per m g)"), std::string::npos) << cmd;
  }
}

TEST_F(CliSolve, StudyCalibrationPrintsATable) {
  const Result r = run("study calibration --quick");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto lines = lines_of(r.out);
  ASSERT_GE(lines.size(), 18u) << r.out;  // title, header, 4 x 4 cells
  // A header of named columns, then rows of as many aligned fields: not CSV.
  std::istringstream header(lines[1]);
  std::vector<std::string> names;
  for (std::string w; header >> w;) names.push_back(w);
  EXPECT_EQ(names, (std::vector<std::string>{"views", "noise_px", "failures", "fx", "fy", "cx",
                                             "cy", "k1", "k2", "rms_px", "time_s"}));
  for (std::size_t i = 2; i < 18; ++i) {
    EXPECT_EQ(lines[i].find(','), std::string::npos) << lines[i];
    EXPECT_EQ(lines[i].size(), lines[1].size()) << lines[i];
  }
}

TEST_F(CliSolve, StudySimQuickRunsAQuarterOfTheSettings) {
  const Result full_help = run("study --help");
  EXPECT_NE(full_help.out.find("sim: RK4 at 2 steps"), std::string::npos) << full_help.out;
  const Result r = run("study sim --quick --json --min-cpu 0.001");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  // 2 formulations x (2 RK4 steps + 2 methods x 4 tolerances), against 2 x (7 + 2 x 11).
  EXPECT_EQ(j.at("rows").size(), 20u) << r.out.substr(0, 400);
}

TEST_F(CliSolve, MissingGnuplotFailsNamingThePackage) {
  const Result r = run("solve --out results", "PATH=/nonexistent");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("gnuplot-nox"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "results"));
  // --no-plot needs no gnuplot.
  const Result ok = run("solve --out results --no-plot", "PATH=/nonexistent");
  EXPECT_EQ(ok.code, 0) << ok.err;
  EXPECT_TRUE(fs::exists(dir_ / "results" / "trajectory.csv"));
  EXPECT_FALSE(fs::exists(dir_ / "results" / "trajectory.png"));
}

TEST_F(CliSolve, FailingGnuplotLeavesNoFiles) {
  fs::create_directories(dir_ / "bin");
  write_text(dir_ / "bin" / "gnuplot", "#!/bin/sh\nexit 3\n");
  fs::permissions(dir_ / "bin" / "gnuplot", fs::perms::owner_all);
  const Result r =
      run("solve --out results/deep", "PATH=" + quote((dir_ / "bin").string()) + ":\"$PATH\"");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_NE(r.err.find("gnuplot"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "results"));
}

// ---- locus, surface, time-optimal ---------------------------------------------------------------

TEST_F(CliLocus, KIncreasesWithPeriod) {
  const bool plots = have_gnuplot();
  const Result r = run(std::string("locus --from 1.2 --to 2.0 --n 3 --json --out loc") +
                       (plots ? "" : " --no-plot"));
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  expect_keys(j, {"points", "csv", "png"}, {"seconds", "mu"});
  ASSERT_EQ(j["points"].size(), 3u);
  // Paper: along the locus k increases with 2T (a smaller initial dip).
  double prev = -1e9;
  for (const auto& p : j["points"]) {
    for (const char* k : {"period", "k", "fn_min_ratio", "mu_required"})
      EXPECT_TRUE(p.contains(k)) << k;
    EXPECT_GT(p["k"].get<double>(), prev);
    prev = p["k"].get<double>();
  }
  EXPECT_DOUBLE_EQ(j["points"][0]["period"].get<double>(), 1.2);
  EXPECT_DOUBLE_EQ(j["points"][2]["period"].get<double>(), 2.0);
  const auto rows = lines_of(read_text(dir_ / "loc" / "locus.csv"));
  ASSERT_EQ(rows.size(), 4u);
  EXPECT_EQ(rows[0], "period,k,fn_min_ratio,fn_apex_ratio,mu_required,s_end,sdot_end,friction_margin");
  if (plots) {
    EXPECT_TRUE(is_png(dir_ / "loc" / "locus.png"));
  }
}

TEST_F(CliSurface, SmallGrid) {
  const bool plots = have_gnuplot();
  const Result r = run(std::string("surface --nk 3 --np 4 --threads 2 --json --out surf") +
                       (plots ? "" : " --no-plot"));
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  expect_keys(j, {"nk", "np", "csv", "png", "rhs_evals", "seconds", "numerical_failures"}, {});
  EXPECT_EQ(j["nk"], 3);
  EXPECT_EQ(j["np"], 4);
  EXPECT_TRUE(j["numerical_failures"].empty());  // every point's run balanced
  const auto rows = lines_of(read_text(dir_ / "surf" / "surface.csv"));
  ASSERT_EQ(rows.size(), 13u);
  EXPECT_EQ(rows[0], "k,period,s_T");
  EXPECT_EQ(rows[1].rfind("-1.6,0.8,", 0), 0u) << rows[1];  // the documented default corner
  if (plots) {
    EXPECT_TRUE(is_png(dir_ / "surf" / "surface.png"));
  }
}

TEST_F(CliTimeOptimal, MatchesPaper) {
  const Result r = run("time-optimal --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  for (const char* k : {"period", "k", "fn_min_ratio", "solves"}) EXPECT_TRUE(j.contains(k)) << k;
  // Paper section 4.3: the fastest contact-keeping butterfly is 2T = 1.095 s with k = -1.1493,
  // the normal force reaching zero at the apex.
  EXPECT_NEAR(j["period"].get<double>(), 1.095, 0.003);
  EXPECT_NEAR(j["k"].get<double>(), -1.1493, 1e-3);
  EXPECT_NEAR(j["fn_min_ratio"].get<double>(), 0.0, 1e-4);
}

// ---- design (docs/DESIGN.md) ------------------------------------------------------------------

// The motion-only design is `solve`'s solution (k alone, fixed by s_h(T) = 0); with the shape
// free, the design needs less friction, and its files hold the best design's own run and every
// evaluation.
TEST_F(CliDesign, MotionOnlyIsSolvesSolutionAndTheShapeNeedsLessFriction) {
  const Result solve = run("solve --json");
  ASSERT_EQ(solve.code, 0) << solve.err;
  const json solved = parse_json(solve);
  const Result motion = run("design --motion-only --json");
  ASSERT_EQ(motion.code, 0) << motion.err;
  const json m = parse_json(motion);
  expect_keys(m,
              {"objective", "period", "mu", "start", "best", "improvement", "active", "restored",
               "restore_stop", "stop", "evaluations", "simulations", "iterates", "files"},
              {});
  EXPECT_TRUE(m["best"]["feasible"].get<bool>());
  EXPECT_NEAR(m["best"]["k"].get<double>(), solved["k"].get<double>(), 1e-6);
  EXPECT_NEAR(m["best"]["mu_required"].get<double>(), solved["mu_required"].get<double>(), 1e-6);
  EXPECT_EQ(m["iterates"].size(), m["evaluations"].get<std::size_t>());

  const Result both = run("design --json --no-plot --out best");
  ASSERT_EQ(both.code, 0) << both.err;
  const json d = parse_json(both);
  EXPECT_TRUE(d["best"]["feasible"].get<bool>());
  EXPECT_LT(d["best"]["mu_required"].get<double>(), m["best"]["mu_required"].get<double>());
  EXPECT_GT(d["improvement"].get<double>(), 0.0);
  // Each evaluation's line on stderr (progress), none on stdout but the JSON.
  EXPECT_GE(lines_of(both.err).size(), d["evaluations"].get<std::size_t>());
  EXPECT_EQ(read_text(dir_ / "best" / "trajectory.csv").rfind(kTrajectoryHeader, 0), 0u);
  const auto rows = lines_of(read_text(dir_ / "best" / "iterates.csv"));
  EXPECT_EQ(rows.size(), d["evaluations"].get<std::size_t>() + 1);  // and the header
}

// The robustness objective at the paper's mu: the margin grows from the paper's (almost none: its
// 1.181 s butterfly needs mu = 0.303) by the improvement reported.
TEST_F(CliDesign, RobustnessGrowsTheMargin) {
  const Result r = run("design --objective robustness --mu 0.306 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  EXPECT_EQ(j["objective"].get<std::string>(), "robustness");
  EXPECT_DOUBLE_EQ(j["mu"].get<double>(), 0.306);
  const double start = j["start"]["robustness"].get<double>();
  const double best = j["best"]["robustness"].get<double>();
  EXPECT_LT(start, 0.01);
  EXPECT_GT(best, start + 0.1);
  EXPECT_NEAR(j["improvement"].get<double>(), best - start, 1e-12);
}

// ---- bad input: exit 2, one line, no files
// -------------------------------------------------------

TEST_F(CliBadInput, DesignOptions) {
  expect_bad_input("design --objective shortest-period --out out", "--objective", "out");
  expect_bad_input("design --objective robustness --mu 0 --out out", "--mu", "out");
  expect_bad_input("design --mu 0.5 --out out", "--mu", "out");  // least-friction finds mu
  expect_bad_input("design --shape-range 1 --out out", "--shape-range", "out");
  expect_bad_input("design --fn-margin -0.1 --out out", "--fn-margin", "out");
  expect_bad_input("design --period 0 --out out", "--period", "out");
  expect_bad_input("design --max-evaluations 0 --out out", "--max-evaluations", "out");
}

TEST_F(CliBadInput, MissingSceneFile) {
  expect_bad_input("solve --scene no-such-scene.yaml --out out", "no-such-scene.yaml", "out");
}

TEST_F(CliBadInput, SceneWithUnknownKey) {
  scene_with("unknown.yaml", "duration:", "bogus_key: 1\nduration:");
  expect_bad_input("solve --scene unknown.yaml --out out", "bogus_key", "out");
}

TEST_F(CliBadInput, SceneWithNegativeRadius) {
  scene_with("negative.yaml", "radius: 0.051", "radius: -0.051");
  expect_bad_input("simulate --scene negative.yaml --out out/run.csv", "radius", "out");
}

TEST_F(CliBadInput, KMinusTwo) {
  expect_bad_input("simulate --k -2 --out out/run.csv", "--k", "out");
  expect_bad_input("solve --k -2 --out out", "--k", "out");
}

TEST_F(CliBadInput, NegativePeriod) {
  expect_bad_input("simulate --period -1 --out out/run.csv", "--period", "out");
  expect_bad_input("solve --period -1 --out out", "--period", "out");
}

TEST_F(CliBadInput, NonFiniteNumbers) {
  expect_bad_input("simulate --period nan --out out/run.csv", "--period", "out");
  expect_bad_input("simulate --k inf --out out/run.csv", "--k", "out");
}

TEST_F(CliBadInput, LocusZeroPoints) { expect_bad_input("locus --n 0 --out out", "--n", "out"); }

TEST_F(CliBadInput, LocusEmptyRange) {
  expect_bad_input("locus --from 2 --to 1.5 --out out", "--to", "out");
}

TEST_F(CliBadInput, SurfaceRangeContainingKMinusTwo) {
  expect_bad_input("surface --k-from -2.5 --k-to -1.5 --out out", "--k-from", "out");
}

TEST_F(CliBadInput, UnknownMethod) {
  expect_bad_input("simulate --method euler --out out/run.csv", "--method", "out");
}

TEST_F(CliBadInput, NonPositiveSampleInterval) {
  expect_bad_input("simulate --sample-dt 0 --out out/run.csv", "--sample-dt", "out");
}

TEST_F(CliBadInput, ContactOptionsAndScene) {
  expect_bad_input("simulate --mu -0.1 --out out/run.csv", "--mu", "out");
  expect_bad_input("simulate --mu nan --out out/run.csv", "--mu", "out");
  expect_bad_input("locus --mu -1 --out out", "--mu", "out");
  expect_bad_input("time-optimal --mu -1 --out out", "--mu", "out");
  expect_bad_input("simulate --model soft --out out/run.csv", "--model", "out");
  expect_bad_input("simulate --model hybrid --no-stop-on-contact-loss --out out/run.csv",
                   "--no-stop-on-contact-loss", "out");
  scene_with("mu.yaml", "stop_on_contact_loss: true", "model: hybrid\n  mu: 0.5\n  mu_kinetic: 0.7");
  expect_bad_input("simulate --scene mu.yaml --out out/run.csv", "contact.mu_kinetic", "out");
  // --mu below the scene's kinetic coefficient.
  scene_with("mu2.yaml", "stop_on_contact_loss: true", "model: hybrid\n  mu: 0.5\n  mu_kinetic: 0.4");
  expect_bad_input("simulate --scene mu2.yaml --mu 0.3 --out out/run.csv", "--mu", "out");
  scene_with("e.yaml", "stop_on_contact_loss: true", "model: hybrid\n  restitution: 2");
  expect_bad_input("simulate --scene e.yaml --out out/run.csv", "contact.restitution", "out");
  scene_with("loss.yaml", "stop_on_contact_loss: true", "model: hybrid\n  drag: -0.1");
  expect_bad_input("simulate --scene loss.yaml --out out/run.csv", "contact.drag", "out");
  scene_with("rr.yaml", "stop_on_contact_loss: true",
             "model: hybrid\n  mu: 0.1\n  rolling_resistance: 0.01");
  expect_bad_input("simulate --scene rr.yaml --out out/run.csv", "contact.rolling_resistance",
                   "out");
}

// The calibration workflow's options: each bad value exits 2 with one line naming its option.
TEST_F(CliBadInput, CalibrationWorkflowOptions) {
  const std::string camera_file = std::string(FLATLAND_FUZZ_DIR) + "/camera_file/minimal-ros.yaml";
  const std::string scene = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml";
  for (const char* q : {"1.5", "-0.1", "nan"})
    expect_bad_input("track --camera " + quote(camera_file) + " --images 'x/*.png' --min-quality " +
                         q + " --out out/t.csv",
                     "--min-quality", "out");
  expect_bad_input("render-calibration --scene " + quote(scene) + " --seed -1 --out out", "--seed",
                   "out");
  expect_bad_input("render-calibration --scene " + quote(scene) + " --intrinsics-views 2 --out out",
                   "--intrinsics-views", "out");
  expect_bad_input("render-calibration --scene " + quote(scene) + " --table-views 51 --out out",
                   "--table-views", "out");
  expect_bad_input("render-calibration --scene " + quote(scene) + " --joint-views 2 --out out",
                   "--joint-views", "out");
  expect_bad_input("calibrate --rational --table t.csv --camera " + quote(camera_file) +
                       " --out out/c.yaml",
                   "--rational", "out");
  // The table's board is named as the option it came from, not as --board.
  const Result r = run("calibrate --images 'x/*.png' --board chessboard:9x6:0.02 --table-board "
                       "bogus --table t.csv --out out/c.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(lines_of(r.err).size(), 1u) << r.err;
  EXPECT_EQ(r.err.rfind("flatland: error: --table-board: ", 0), 0u) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "out"));
}

// Inputs that once ran without limit: each is refused at once, in little memory (1 GB of address
// space, where the sanitizers allow a limit) and bounded time (a 20 s watchdog; they take ~0.2 s).
TEST_F(CliBadInput, UnboundedInputsAreRefused) {
  const std::string env = std::string(flatland::test::short_tests() ? "" : "ulimit -v 1048576; ") +
                          "timeout 20";
  const std::string camera = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml";
  expect_bad_input("simulate --scene /dev/zero --out out/run.csv", "/dev/zero", "out", env);
  expect_bad_input("render --scene " + camera + " --fps 1e6 --out out", "--fps", "out", env);
  expect_bad_input("render --scene " + camera + " --fps 999 --duration 1000 --out out",
                   "--fps/--duration", "out", env);
  expect_bad_input("surface --nk 100000 --np 100000 --out out", "--nk", "out", env);
  expect_bad_input("surface --nk 2000 --np 2000 --out out", "--nk/--np", "out", env);
  expect_bad_input("locus --n 1000000000 --out out", "--n", "out", env);
  expect_bad_input("montecarlo --seed -1 --out out", "--seed", "out", env);
  expect_bad_input("montecarlo --n 100000000 --out out", "--n", "out", env);
  // A camera the schema once allowed, and a supersampled frame beyond the bound.
  std::string text = read_text(camera);
  text.replace(text.find("width: 640 "), 11, "width: 16384 ");
  text.replace(text.find("height: 480 "), 12, "height: 16384 ");
  write_text(dir_ / "huge.yaml", text);
  expect_bad_input("render --scene huge.yaml --out out", "camera.width", "out", env);
  text = read_text(camera);
  text.replace(text.find("width: 640 "), 11, "width: 4096 ");
  text.replace(text.find("height: 480 "), 12, "height: 3072 ");
  text.replace(text.find("supersample: 2 "), 15, "supersample: 8 ");
  write_text(dir_ / "supersampled.yaml", text);
  expect_bad_input("render --scene supersampled.yaml --out out", "effects.supersample", "out", env);
  // Files read with a bound: a device that never ends.
  fs::create_directories(dir_ / "frames");
  ASSERT_EQ(run("render --scene " + camera + " --duration 0.05 --out frames --force").code, 0);
  expect_bad_input("track --images 'frames/frame_*.png' --camera /dev/zero --out out/t.csv",
                   "/dev/zero", "out", env);
  expect_bad_input("track --images 'frames/frame_*.png' --camera " +
                       std::string(FLATLAND_FUZZ_DIR) +
                       "/camera_file/full-flatland.yaml --encoder /dev/zero --out out/t.csv",
                   "--encoder", "out", env);
}

// track's --exposure: a time in [0, 1/fps] (a longer one cannot be a video camera's), reported
// back with --interlaced in the JSON.
TEST_F(CliBadInput, TrackExposure) {
  const std::string scene = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml";
  ASSERT_EQ(run("render --scene " + quote(scene) + " --duration 0.05 --out frames").code, 0);
  const std::string track = "track --images 'frames/frame_*.png' --camera frames/camera.yaml ";
  for (const char* e : {"-0.001", "nan", "inf"})
    expect_bad_input(track + "--exposure " + e + " --out out/t.csv", "--exposure", "out");
  expect_bad_input(track + "--fps 30 --exposure 0.05 --out out/t.csv", "--exposure", "out");
  const Result r = run(track + "--fps 30 --exposure 0.02 --interlaced --out out/t.csv --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["exposure_s"].get<double>(), 0.02);
  EXPECT_TRUE(j["interlaced"].get<bool>());
  EXPECT_GT(j["found"].get<int>(), 0);
}

TEST_F(CliBadInput, UnknownCommandAndOption) {
  expect_bad_input("frobnicate", "frobnicate", "out");
  expect_bad_input("solve --frobnicate", "--frobnicate", "out");
}

// ---- runtime failure: exit 1, no files
// ------------------------------------------------------------

TEST_F(CliRuntimeFailure, TimeOptimalBracketWithoutTheOptimum) {
  // Every solution in [1.3, 1.5] s keeps contact (the optimum is 1.095 s), so the bracket does not
  // contain the point where the minimum normal force crosses zero.
  const Result r = run("time-optimal --from 1.3 --to 1.5 --out out");
  EXPECT_EQ(r.code, 1) << r.err;
  const auto err = lines_of(r.err);
  ASSERT_FALSE(err.empty());
  EXPECT_EQ(err.back().rfind("flatland: error: ", 0), 0u) << err.back();
  EXPECT_TRUE(r.out.empty());
  EXPECT_FALSE(fs::exists(dir_ / "out"));
}

}  // namespace
