// `flatland simulate` on spatial scenes (space: 3d): the JSON report, the CSV and its plot, the
// events as stop reasons, and bad input refused with exit 2 and nothing written.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

class CliSpatial : public flatland_test::CliTestBase {
 protected:
  static std::string bowl() {
    return quote(std::string(FLATLAND_ASSET_DIR) + "/scenes/ball-in-bowl.yaml");
  }
};

TEST_F(CliSpatial, TheBowlsConicalOrbitKeepsItsHeight) {
  const Result r = run("simulate --scene " + bowl() + " --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["space"], "3d");
  EXPECT_EQ(j["stop_reason"], "end_time");
  EXPECT_TRUE(j["success"].get<bool>());
  EXPECT_EQ(j["t_end"].get<double>(), 5.0);
  // The centre stays on the orbit's latitude: rho cos(0.6) below the bowl's centre (the scene's
  // start velocity is the closed form's to 7 digits).
  const double rho = 0.3 - 0.05;
  EXPECT_NEAR(j["final"]["position"][2].get<double>(), -rho * std::cos(0.6), 1e-7);
  EXPECT_NEAR(
      std::hypot(j["final"]["position"][0].get<double>(), j["final"]["position"][1].get<double>()),
      rho * std::sin(0.6), 1e-7);
  EXPECT_LT(std::abs(j["energy_change"].get<double>()), 1e-9);
  // The run's own audit: a fixed bowl does (next to) no work, and the balance holds.
  EXPECT_TRUE(j["energy"]["holds"].get<bool>());
  EXPECT_LT(std::abs(j["energy"]["work_hand"].get<double>()), 1e-9);
  EXPECT_EQ(j["duration"].get<double>(), 5.0);
  EXPECT_LT(j["max_constraint_residual"].get<double>(), 1e-12);
  EXPECT_GT(j["steps"].get<long>(), 0);
  EXPECT_TRUE(j["csv"].is_null());
}

TEST_F(CliSpatial, TheCsvHasOneRowPerSampleAndThePlotSitsBesideIt) {
  Result r = run("simulate --scene " + bowl() +
                 " --duration 0.5 --sample-dt 0.01 --out run.csv --no-plot");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::vector<std::string> lines = lines_of(read_text(dir_ / "run.csv"));
  ASSERT_EQ(lines.size(), 1u + 51u);
  EXPECT_EQ(lines[0].rfind("t,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz,so_u,so_v,sh_u,sh_v,", 0), 0u);
  EXPECT_EQ(lines[1].rfind("0,", 0), 0u);
  EXPECT_EQ(lines[51].rfind("0.5,", 0), 0u);
  EXPECT_FALSE(fs::exists(dir_ / "run.png"));
  r = run("simulate --scene " + bowl() + " --duration 0.5 --out run.csv --force");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "run.png"));
  EXPECT_TRUE(fs::exists(dir_ / "run.gp"));
  EXPECT_NE(r.out.find("wrote"), std::string::npos);
}

TEST_F(CliSpatial, SlipStopsTheRunAndIsNoSuccess) {
  // The orbit needs |f_t| / f_n = 0.146 throughout: with mu = 0.1 it slips at once.
  const Result r = run("simulate --scene " + bowl() + " --mu 0.1 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["stop_reason"], "slip");
  EXPECT_FALSE(j["success"].get<bool>());
  EXPECT_LT(j["t_end"].get<double>(), 1e-9);
}

TEST_F(CliSpatial, BadInputIsRefusedWithNothingWritten) {
  write_text(dir_ / "big.yaml",
             "space: 3d\ngravity: [0, 0, -9.8]\n"
             "hand: {surface: sphere, side: inside, radius: 0.3}\n"
             "object: {type: ball, radius: 0.4}\nmotion: {type: fixed}\n"
             "initial: {s_h: [0, -1.2]}\n");
  Result r = run("simulate --scene big.yaml --out run.csv");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(lines_of(r.err).size(), 1u) << r.err;
  EXPECT_NE(r.err.find("big.yaml: initial: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("does not fit the hand's curvature"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "run.csv"));
  for (const std::string& args :
       {std::string("solve --scene ") + bowl(), "simulate --scene " + bowl() + " --k -1",
        "simulate --scene " + bowl() + " --formulation reduced",
        "simulate --scene " + bowl() + " --model hybrid", "simulate --scene " + bowl() + " --mu -1",
        "simulate --scene " + bowl() + " --sample-dt 0", "locus --scene " + bowl()}) {
    r = run(args + " --out x");
    EXPECT_EQ(r.code, 2) << args << ": " << r.err;
    EXPECT_EQ(lines_of(r.err).size(), 1u) << args << ": " << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "x")) << args;
  }
}

TEST_F(CliSpatial, RenderFilmsTheRunThroughTheScenesCamera) {
  const Result r = run("render --scene " + bowl() + " --duration 0.2 --out frames --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["space"], "3d");
  EXPECT_EQ(j["frames"], 7);  // t = 0, 1/30, ..., 0.2 s
  for (int i = 0; i < 7; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.png", i);
    EXPECT_TRUE(fs::exists(dir_ / "frames" / name)) << name;
  }
  const std::vector<std::string> truth = lines_of(read_text(dir_ / "frames" / "truth.csv"));
  ASSERT_EQ(truth.size(), 8u);
  EXPECT_EQ(truth[0], "frame,t,x,y,z,u,v");
  EXPECT_TRUE(fs::exists(dir_ / "frames" / "camera.yaml"));
  // Planar-only options and effects are refused, with nothing written.
  for (const std::string& extra : {std::string(" --overlay"), std::string(" --view side")}) {
    const Result bad = run("render --scene " + bowl() + " --duration 0.2 --out more" + extra);
    EXPECT_EQ(bad.code, 2) << extra << ": " << bad.err;
    EXPECT_FALSE(fs::exists(dir_ / "more")) << extra;
  }
}

}  // namespace

// A quantity that stays constant (the turntable ball's height, 0.02 m to 14 digits) is drawn on a
// range around itself and its panel says so, instead of its rounding at full scale; one that
// varies (the ellipsoid's height in its dish) is left to gnuplot's autoscale.
TEST_F(CliSpatial, APlotSaysWhatStaysConstantInsteadOfDrawingItsRounding) {
  const std::string scenes = std::string(FLATLAND_ASSET_DIR) + "/scenes/";
  Result r = run("simulate --scene " + quote(scenes + "ball-on-turntable.yaml") +
                 " --duration 1 --out turntable.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string turntable = read_text(dir_ / "turntable.gp");
  EXPECT_NE(turntable.find("set title 'object centre height (constant: 0.02 to "),
            std::string::npos)
      << turntable;
  EXPECT_NE(turntable.find("set yrange [0.01998:0.02002]"), std::string::npos) << turntable;
  r = run("simulate --scene " + quote(scenes + "ellipsoid-in-dish.yaml") +
          " --duration 1 --out dish.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  const std::string dish = read_text(dir_ / "dish.gp");
  EXPECT_NE(dish.find("set title 'object centre height'"), std::string::npos) << dish;
  EXPECT_EQ(dish.find("constant"), std::string::npos) << dish;
}
