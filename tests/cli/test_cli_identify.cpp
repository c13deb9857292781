// flatland identify on the command line: bad input is one line naming the option or file:line,
// exit 2, nothing written (docs/CLI.md, docs/IDENTIFY.md).
#include "cli_support.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/scene/scene.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <random>
#include <sstream>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <vector>

namespace {

using flatland_test::CliTestBase;
namespace fs = std::filesystem;
using flatland_test::Result;
using flatland_test::write_text;

class CliIdentify : public CliTestBase {
 protected:
  std::string scene() const {
    return std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-5deg.yaml";
  }
  /// A plain recording of `rows` rows (t, theta, s_h, sigma), valid unless edited.
  void write_plain(const std::string& name, int rows = 8) const {
    std::string text = "t,theta,s_h,sigma\n";
    for (int i = 0; i < rows; ++i)
      text += std::to_string(0.1 * i) + "," + std::to_string(0.01 * i) + ",-1,0.001\n";
    write_text(dir_ / name, text);
  }
  /// Exit 2, exactly one line on stderr holding `expected`, and no --out directory.
  void expect_refused(const std::string& args, const std::string& expected) const {
    const Result r = run("identify " + args + " --out out");
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    const auto lines = flatland_test::lines_of(r.err);
    ASSERT_EQ(lines.size(), 1u) << args << "\n" << r.err;
    EXPECT_EQ(lines[0].rfind("flatland: error: ", 0), 0u) << lines[0];
    EXPECT_NE(lines[0].find(expected), std::string::npos)
        << "expected '" << expected << "' in: " << lines[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "out")) << args;
  }
};

TEST_F(CliIdentify, UnknownParameterNamesAreRefused) {
  write_plain("a.csv");
  expect_refused(scene() + " a.csv --unknowns mu_kinetic,friction",
                 "--unknowns: unknown parameter 'friction' (known: mu_static, mu_kinetic");
  expect_refused(scene() + " a.csv --unknowns drag,drag", "--unknowns: 'drag' given twice");
  expect_refused(scene() + " a.csv --unknowns ,", "--unknowns: an empty name");
}

TEST_F(CliIdentify, BadOptionsAreRefused) {
  write_plain("a.csv");
  expect_refused(scene() + " a.csv --unknowns drag --segment 0", "--segment");
  expect_refused(scene() + " a.csv --unknowns drag --segment -1", "--segment");
  expect_refused(scene() + " a.csv --unknowns drag --max-iterations 0", "--max-iterations");
  expect_refused(scene() + " a.csv --unknowns drag --format csv", "--format: unknown format 'csv'");
  expect_refused(scene() + " a.csv --unknowns drag --encoder a.csv",
                 "--encoder: 1 given but only 0 track.csv recordings take one");
  expect_refused("nope.yaml a.csv --unknowns drag", "nope.yaml");
  expect_refused(scene() + " --unknowns drag", "recordings");
}

TEST_F(CliIdentify, BadRecordingsNameFileAndLine) {
  write_plain("good.csv");
  expect_refused(scene() + " missing.csv --unknowns drag", "RECORDING: no such file: missing.csv");
  expect_refused(scene() + " good.csv --unknowns drag --validate gone.csv",
                 "--validate: no such file: gone.csv");
  write_text(dir_ / "text.csv", "t,theta,s_h,sigma\n0,0,-1,0.001\n0.1,x,-1,0.001\n");
  expect_refused(scene() + " text.csv --unknowns drag", "text.csv:3: theta: not a number: 'x'");
  write_text(dir_ / "back.csv",
             "t,theta,s_h,sigma\n0,0,-1,0.001\n0.2,0,-1,0.001\n0.1,0,-1,0.001\n0.3,0,-1,0.001\n");
  expect_refused(scene() + " back.csv --unknowns drag",
                 "back.csv:4: t 0.1 is not after the previous row's 0.2");
  write_text(dir_ / "nan.csv",
             "t,theta,s_h,sigma\n0,0,-1,0.001\n0.1,0,nan,0.001\n0.2,0,-1,0.001\n0.3,0,-1,0.001\n");
  expect_refused(scene() + " nan.csv --unknowns drag", "nan.csv:3: s_h: not finite");
  write_plain("short.csv", 3);
  expect_refused(scene() + " short.csv --unknowns drag", "short.csv: 3 data rows");
  write_text(dir_ / "nosigma.csv", "t,theta,s_h\n0,0,-1\n0.1,0,-1\n0.2,0,-1\n0.3,0,-1\n");
  expect_refused(scene() + " nosigma.csv --unknowns drag", "no sigma column and no sigma given");
  write_text(dir_ / "what.csv", "a,b,c\n1,2,3\n");
  expect_refused(scene() + " what.csv --unknowns drag",
                 "cannot tell the recording's format from its header");
  write_text(dir_ / "track.csv",
             "frame,t,u,v,sigma_px,quality,state,s_h\n0,0,300,200,0.1,0.9,found,\n");
  expect_refused(scene() + " track.csv --unknowns drag --camera x.yaml",
                 "track.csv recording (track.csv) needs the joint's encoder log");
  write_text(dir_ / "px.csv", "t,u,v,theta,sigma_px\n0,300,200,0,0.1\n");
  expect_refused(scene() + " px.csv --unknowns drag", "--camera: required");
  fs::create_directories(dir_ / "run");
  expect_refused(scene() + " run --unknowns drag", "log.csv: no such file");
}

TEST_F(CliIdentify, AnExistingOutputDirectoryIsKept) {
  write_plain("a.csv");
  fs::create_directories(dir_ / "out");
  write_text(dir_ / "out" / "keep.txt", "mine");
  const Result r = run("identify " + scene() + " a.csv --unknowns drag --out out");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  EXPECT_EQ(flatland_test::read_text(dir_ / "out" / "keep.txt"), "mine");
}

/// The air-table world's own motion (flatland simulate, 4 s at 30 Hz) with Gaussian noise of
/// sigma on s_h, as a plain recording: its truth is the scene's drag (0.015 N s/m) and rolling
/// resistance (5e-5 m).
void write_synthetic(const fs::path& dir, const std::string& trajectory, const std::string& name,
                     unsigned seed, double sigma) {
  std::stringstream in(flatland_test::read_text(dir / trajectory));
  std::string line;
  std::getline(in, line);
  const auto columns = [](const std::string& row) {
    std::vector<std::string> cells;
    std::stringstream ss(row);
    for (std::string cell; std::getline(ss, cell, ',');) cells.push_back(cell);
    return cells;
  };
  const std::vector<std::string> header = columns(line);
  const auto index = [&header](const std::string& n) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), n) - header.begin());
  };
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, sigma);
  std::string out = "t[s],theta[rad],s_h,sigma\n";
  while (std::getline(in, line)) {
    const std::vector<std::string> c = columns(line);
    out += c[index("t")] + "," + c[index("theta")] + "," +
           std::to_string(std::stod(c[index("s_h")]) + noise(rng)) + "," + std::to_string(sigma) +
           "\n";
  }
  write_text(dir / name, out);
}

TEST_F(CliIdentify, FitsTheWorldOfASyntheticRecordingAndWritesItsScene) {
  const double sigma = 1e-3;
  ASSERT_EQ(run("simulate --scene " + scene() +
                " --duration 4 --sample-dt 0.0333333333333333 --out traj.csv")
                .code,
            0);
  write_synthetic(dir_, "traj.csv", "fit.csv", 1, sigma);
  write_synthetic(dir_, "traj.csv", "held.csv", 2, sigma);
  // Under the sanitizers one iteration: the outputs' code paths; the values are Release's.
  const bool short_run = flatland::test::short_tests();
  const Result r =
      run("identify " + scene() +
          " fit.csv --unknowns drag,rolling_resistance --validate held.csv --out out --json" +
          (short_run ? " --max-iterations 1" : ""));
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const nlohmann::json report =
      nlohmann::json::parse(flatland_test::read_text(dir_ / "out" / "report.json"));
  EXPECT_EQ(j["parameters"], report["parameters"]);
  // Truth (the scene's values) within 3 sigma; both determined.
  const std::map<std::string, double> truth = {{"drag", 0.015}, {"rolling_resistance", 5e-5}};
  ASSERT_EQ(j["parameters"].size(), 2u);
  for (const auto& p : j["parameters"]) {
    ASSERT_TRUE(p["determined"].get<bool>()) << p;
    const double value = p["value"], sd = p["sigma"];
    EXPECT_GT(sd, 0.0);
    if (!short_run) {
      EXPECT_LT(std::abs(value - truth.at(p["name"])), 3 * sd) << p;
    }
  }
  // chi^2 of noise of the stated sigma: its dof within a generous 5 sigma of sqrt(2 dof).
  const double dof = j["degrees_of_freedom"];
  if (!short_run) {
    EXPECT_LT(std::abs(j["chi2"].get<double>() - dof), 5 * std::sqrt(2 * dof)) << j["chi2"];
  }
  EXPECT_EQ(j["correlation"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["correlation"][0][0].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(j["correlation"][0][1].get<double>(), j["correlation"][1][0].get<double>());
  // residuals.csv: one row per sample, the residual its definition.
  const auto rows =
      flatland_test::lines_of(flatland_test::read_text(dir_ / "out" / "residuals.csv"));
  ASSERT_EQ(rows.size(), 1 + j["recordings"][0]["samples"].get<std::size_t>());
  EXPECT_EQ(rows[0], "recording,t,measured,fitted,normalised_residual");
  for (std::size_t i = 1; i < rows.size(); ++i) {
    double rec, t, measured, fitted, normalised;
    ASSERT_EQ(std::sscanf(rows[i].c_str(), "%lf,%lf,%lf,%lf,%lf", &rec, &t, &measured, &fitted,
                          &normalised),
              5);
    EXPECT_NEAR(normalised, (fitted - measured) / sigma, 1e-6);
  }
  // The prediction check.
  const nlohmann::json v = j["validation"];
  ASSERT_TRUE(v.is_object());
  EXPECT_EQ(v["recording"], "held.csv");
  EXPECT_GT(v["samples"].get<int>(), 100);
  EXPECT_GE(v["max_abs_error"].get<double>(), v["rms_error"].get<double>());
  for (const char* f : {"fitted.yaml", "residuals.csv", "residuals.png", "report.json",
                        "validation.csv", "validation.png"})
    EXPECT_TRUE(fs::exists(dir_ / "out" / f)) << f;
  // The fitted scene runs, and carries the fitted values to the last bit.
  EXPECT_EQ(run("simulate --scene out/fitted.yaml --duration 0.5").code, 0);
  const std::string fitted = flatland_test::read_text(dir_ / "out" / "fitted.yaml");
  for (const auto& p : j["parameters"]) {
    const std::string key = "\n  " + p["name"].get<std::string>() + ": ";
    const auto at = fitted.find(key);
    ASSERT_NE(at, std::string::npos) << key << "\n" << fitted;
    EXPECT_EQ(std::stod(fitted.substr(at + key.size())), p["value"].get<double>()) << key;
  }
  EXPECT_NE(fitted.find("#   command:         flatland identify"), std::string::npos);
}

/// Pixel centres with a camera file: the simulated disk's top-face centre projected by a pinhole
/// camera straight above the pivot (written here in closed form: u = cx + fx X/Z, v = cy + fy
/// Y/Z), with 0.1 px of noise, become s_h through the camera file and are fitted like any
/// recording: the scene's drag and rolling resistance within 3 sigma.
TEST_F(CliIdentify, PixelCentresWithACameraFileAreFitted) {
  const flatland::Scene world = flatland::load_scene(scene());
  const double fx = 900, cx = 639.5, cy = 479.5, height = 1.2, sigma_px = 0.1;
  flatland::camera::CameraFile file;
  file.camera.width = 1280;
  file.camera.height = 960;
  file.camera.K = cv::Matx33d(fx, 0, cx, 0, fx, cy, 0, 0, 1);
  // Looking down at the table: camera x = table x, camera y = -table y, z = -table z.
  file.camera.R = cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1);
  file.camera.t = cv::Vec3d(0, 0, height);
  file.has_table_pose = true;
  flatland::camera::write_camera_file((dir_ / "camera.yaml").string(), file);
  ASSERT_EQ(run("simulate --scene " + scene() +
                " --duration 4 --sample-dt 0.0333333333333333 --out traj.csv")
                .code,
            0);
  std::stringstream in(flatland_test::read_text(dir_ / "traj.csv"));
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  {
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) header.push_back(c);
  }
  const auto col = [&header](const std::string& n) {
    return static_cast<std::size_t>(std::find(header.begin(), header.end(), n) - header.begin());
  };
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, sigma_px);
  std::string csv = "t,u,v,theta,sigma_px\n";
  int rows = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> c;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) c.push_back(cell);
    const double x = std::stod(c[col("x")]), y = std::stod(c[col("y")]);
    const double depth = height - world.render.disk_thickness;  // the tracked top face
    const double u = cx + fx * x / depth + noise(rng), v = cy + fx * (-y) / depth + noise(rng);
    char row[200];
    std::snprintf(row, sizeof row, "%s,%.17g,%.17g,%s,%g\n", c[col("t")].c_str(), u, v,
                  c[col("theta")].c_str(), sigma_px);
    csv += row;
    ++rows;
  }
  write_text(dir_ / "px.csv", csv);
  // Under the sanitizers one iteration: the pixel reader's code paths; the values are Release's.
  const bool short_run = flatland::test::short_tests();
  const Result r = run("identify " + scene() +
                       " px.csv --camera camera.yaml --unknowns drag,rolling_resistance --json" +
                       (short_run ? " --max-iterations 1" : ""));
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["recordings"][0]["format"], "pixels");
  EXPECT_EQ(j["recordings"][0]["samples"].get<int>(), rows);
  if (short_run) return;
  const std::map<std::string, double> truth = {{"drag", 0.015}, {"rolling_resistance", 5e-5}};
  for (const auto& p : j["parameters"]) {
    ASSERT_TRUE(p["determined"].get<bool>()) << p;
    EXPECT_LT(std::abs(p["value"].get<double>() - truth.at(p["name"])),
              3 * p["sigma"].get<double>())
        << p;
  }
  const double dof = j["degrees_of_freedom"];
  EXPECT_LT(std::abs(j["chi2"].get<double>() - dof), 5 * std::sqrt(2 * dof)) << j["chi2"];
}

/// A synthetic closed-loop experiment (rendered frames, the tracker's centres mapped to s_h with
/// their sigma, the 1 kHz joint log thinned to 20 ms) fitted as recorded: the world's drag and
/// rolling resistance within 3 sigma of the scene's, chi^2 near its degrees of freedom, the fit
/// converged within the default iterations. The disk never slides there, so mu_kinetic added to
/// the unknowns is not determined: it is held at its starting value and the same drag and rolling
/// resistance come out (before, with it free, a difference run's numerical failure ended the
/// solve early at a worse chi^2, the rolling resistance 3 sigma off).
TEST_F(CliIdentify, AnExperimentsRecordingIsFittedToItsWorld) {
  const std::string world = std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-feedback.yaml";
  const Result e = run("experiment --scene " + world + " --out run --no-plot");
  ASSERT_EQ(e.code, 0) << e.err;
  // Under the sanitizers the fit runs one iteration per solve: its code paths, at a tenth of
  // the ~160 s it takes there to converge; the values are the Release stage's to check.
  const bool short_run = flatland::test::short_tests();
  const Result r = run("identify " + world + " run --unknowns drag,rolling_resistance --json" +
                       (short_run ? " --max-iterations 1" : ""));
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["recordings"][0]["format"], "experiment");
  EXPECT_GT(j["recordings"][0]["samples"].get<int>(), 100);
  if (short_run) {
    if (!j["converged"].get<bool>()) {
      EXPECT_FALSE(j["warnings"].empty()) << j;
    }
    return;
  }
  EXPECT_TRUE(j["converged"].get<bool>()) << j["termination"];
  EXPECT_EQ(j["termination_type"], "CONVERGENCE");
  const std::map<std::string, double> truth = {{"drag", 0.015}, {"rolling_resistance", 5e-5}};
  for (const auto& p : j["parameters"]) {
    ASSERT_TRUE(p["determined"].get<bool>()) << p;
    EXPECT_LT(std::abs(p["value"].get<double>() - truth.at(p["name"])),
              3 * p["sigma"].get<double>())
        << p;
  }
  const double dof = j["degrees_of_freedom"];
  EXPECT_LT(std::abs(j["chi2"].get<double>() - dof), 5 * std::sqrt(2 * dof)) << j["chi2"];

  const Result with_mu =
      run("identify " + world + " run --unknowns mu_kinetic,drag,rolling_resistance --json");
  ASSERT_EQ(with_mu.code, 0) << with_mu.err;
  const nlohmann::json k = nlohmann::json::parse(with_mu.out);
  EXPECT_TRUE(k["converged"].get<bool>()) << k["termination"];
  const nlohmann::json& mu = k["parameters"][0];
  EXPECT_FALSE(mu["determined"].get<bool>()) << mu;
  EXPECT_TRUE(mu["held"].get<bool>()) << mu;
  EXPECT_EQ(mu["value"].get<double>(), mu["initial"].get<double>());
  for (std::size_t i = 0; i < 2; ++i) {
    const nlohmann::json &p = j["parameters"][i], &q = k["parameters"][i + 1];
    ASSERT_EQ(p["name"], q["name"]);
    ASSERT_TRUE(q["determined"].get<bool>()) << q;
    const double sd = p["sigma"].get<double>();
    std::printf("[ identify ] %s: %.6g +- %.2g without mu_kinetic, %.6g +- %.2g with it\n",
                p["name"].get<std::string>().c_str(), p["value"].get<double>(), sd,
                q["value"].get<double>(), q["sigma"].get<double>());
    EXPECT_LT(std::abs(q["value"].get<double>() - p["value"].get<double>()), 0.1 * sd) << q;
    EXPECT_NEAR(q["sigma"].get<double>(), sd, 0.05 * sd) << q;
  }
  EXPECT_NEAR(k["chi2"].get<double>(), j["chi2"].get<double>(), 0.1);
}

/// The same experiment fitted from two starts: the truth (the scene's drag 0.015 N s/m and
/// rolling resistance 5e-5 m) and drag 0.02, 4e-5 m. Before the continuation of the continuity
/// conditions (docs/IDENTIFY.md, "Convergence"), the fit from the truth did not move at all
/// (chi^2 176.2, a stop short of the minimum) and the other one stopped at chi^2 204.4, drag 5.8
/// sigma and rolling resistance 3.6 sigma from the truth, both with Ceres reporting CONVERGENCE.
/// Now both reach the minimum: converged (the Gauss-Newton step at the solution within 0.3
/// sigma), the truth within 2 sigma, chi^2 within 1 of each other and each value within 1 sigma
/// of the other fit's.
TEST_F(CliIdentify, AFitStartedAwayFromTheTruthReachesTheSameMinimum) {
  if (flatland::test::short_tests())  // the sanitizer stage: AnExperimentsRecording's code paths
    GTEST_SKIP()
        << "two fits of AnExperimentsRecordingIsFittedToItsWorld's recording: Release only";
  const std::string world = std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-feedback.yaml";
  const Result e = run("experiment --scene " + world + " --out run --no-plot");
  ASSERT_EQ(e.code, 0) << e.err;
  std::string text = flatland_test::read_text(world);
  // Each key's value up to its comment replaced (std::regex would do it too, but GCC 12 warns
  // inside its std::function under the sanitizer build's -O1).
  const auto with_value = [](std::string t, const std::string& key, const std::string& value) {
    const auto at = t.find("\n  " + key + ": ");
    if (at == std::string::npos) return t;
    const auto from = at + 4 + key.size() + 2;
    const auto to = t.find_first_of("#\n", from);
    return t.replace(from, to - from, value + " ");
  };
  const std::string started =
      with_value(with_value(text, "drag", "0.02"), "rolling_resistance", "4.0e-5");
  ASSERT_NE(started, text);
  write_text(dir_ / "start.yaml", started);
  const auto fit = [this](const std::string& scene) {
    const Result r = run("identify " + scene + " run --unknowns drag,rolling_resistance --json");
    EXPECT_EQ(r.code, 0) << r.err;
    return r.code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json();
  };
  const nlohmann::json away = fit("start.yaml");
  ASSERT_TRUE(away.is_object());
  ASSERT_EQ(away["parameters"][0]["initial"].get<double>(), 0.02);
  const nlohmann::json near = fit(world);
  ASSERT_TRUE(near.is_object());
  const std::map<std::string, double> truth = {{"drag", 0.015}, {"rolling_resistance", 5e-5}};
  for (const nlohmann::json* j : {&near, &away}) {
    EXPECT_TRUE((*j)["converged"].get<bool>()) << (*j)["termination"] << (*j)["warnings"];
    EXPECT_LE(j->value("step_in_sigma", std::numeric_limits<double>::infinity()), 0.3);
    for (const auto& p : (*j)["parameters"]) {
      ASSERT_TRUE(p["determined"].get<bool>()) << p;
      EXPECT_LT(std::abs(p["value"].get<double>() - truth.at(p["name"])),
                2 * p["sigma"].get<double>())
          << p;
    }
  }
  std::printf("[ identify ] chi^2 %.3f from the truth, %.3f from drag 0.02, 4e-5 m\n",
              near["chi2"].get<double>(), away["chi2"].get<double>());
  EXPECT_NEAR(away["chi2"].get<double>(), near["chi2"].get<double>(), 1.0);
  for (std::size_t i = 0; i < 2; ++i) {
    const nlohmann::json &p = near["parameters"][i], &q = away["parameters"][i];
    const double sd = std::max(p["sigma"].get<double>(), q["sigma"].get<double>());
    std::printf("[ identify ] %s: %.6g +- %.2g from the truth, %.6g +- %.2g from away\n",
                p["name"].get<std::string>().c_str(), p["value"].get<double>(),
                p["sigma"].get<double>(), q["value"].get<double>(), q["sigma"].get<double>());
    EXPECT_LT(std::abs(q["value"].get<double>() - p["value"].get<double>()), sd) << q;
  }
}

/// The track format end to end: the world rendered (its camera file and 1 kHz encoder log
/// beside the video), tracked with flatland track, fitted from track.csv: drag and rolling
/// resistance within 3 sigma of the scene's.
TEST_F(CliIdentify, ARenderedAndTrackedVideoIsFittedToItsWorld) {
  const std::string world = std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-feedback.yaml";
  ASSERT_EQ(run("render --scene " + world + " --out vid.mp4").code, 0);
  ASSERT_EQ(run("track --video vid.mp4 --camera vid.camera.yaml --encoder vid.encoder.csv "
                "--scene " +
                world + " --out track.csv")
                .code,
            0);
  // Under the sanitizers one iteration: the track reader's code paths; the values are Release's.
  const bool short_run = flatland::test::short_tests();
  const Result r = run("identify " + world +
                       " track.csv --encoder vid.encoder.csv --camera vid.camera.yaml "
                       "--unknowns drag,rolling_resistance --json" +
                       (short_run ? " --max-iterations 1" : ""));
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["recordings"][0]["format"], "track");
  EXPECT_GT(j["recordings"][0]["samples"].get<int>(), 100);
  if (short_run) return;
  const std::map<std::string, double> truth = {{"drag", 0.015}, {"rolling_resistance", 5e-5}};
  for (const auto& p : j["parameters"]) {
    ASSERT_TRUE(p["determined"].get<bool>()) << p;
    EXPECT_LT(std::abs(p["value"].get<double>() - truth.at(p["name"])),
              3 * p["sigma"].get<double>())
        << p;
  }
}

TEST_F(CliIdentify, IsListedAndHasHelp) {
  const Result list = run("--help");
  EXPECT_NE(list.out.find("identify"), std::string::npos);
  const Result help = run("identify --help");
  EXPECT_EQ(help.code, 0) << help.err;
  for (const char* option : {"--unknowns", "--segment", "--out", "--json", "--validate", "--camera",
                             "--encoder", "--sigma", "--format"})
    EXPECT_NE(help.out.find(option), std::string::npos) << option;
}

}  // namespace
