// End-to-end tests of `flatland study closed-loop --quick`: the JSON is one object whose rows are
// the grid's cells, each row's counts, rate and Wilson interval agree with each other, a camera
// whose latency is beyond the safety monitor's timeout (0.3 s) fails more often than the scene's
// own camera, the files agree with the JSON, and bad input exits 2 writing nothing. The checks are
// relations between the numbers the study reports and what is known independently (the grid it
// was asked for, the scene's camera), never the numbers themselves.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::cells_of;
using flatland_test::have_tool;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

// The bundled closed-loop scene's camera (assets/scenes/airtable-feedback.yaml): the study's
// default scene, whose cell must be in every grid.
constexpr double kSceneRate = 30, kSceneLatency = 0.033;

bool near(double a, double b) { return std::abs(a - b) < 1e-9; }

class CliStudyClosedLoop : public flatland_test::CliTestBase {
 protected:
  static json parse_json(const Result& r) {
    json j;
    EXPECT_NO_THROW(j = json::parse(r.out)) << "stdout is not one JSON value:\n" << r.out;
    EXPECT_TRUE(j.is_object());
    return j;
  }

  /// The row of `controller` at (rate, latency); null if none.
  static json row_at(const json& j, double rate, double latency,
                     const std::string& controller = "feedback") {
    for (const json& r : j["rows"])
      if (r["controller"] == controller && near(r["rate_hz"].get<double>(), rate) &&
          near(r["latency_s"].get<double>(), latency))
        return r;
    return nullptr;
  }

  /// Bad input: exit 2, one line naming `what`, nothing on stdout, `out` not created.
  void expect_bad_input(const std::string& args, const std::string& what) const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << "stderr: " << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(what), std::string::npos) << "does not name " << what << ": " << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / "out")) << "created out/";
  }
};

TEST_F(CliStudyClosedLoop, QuickJsonRowsAreTheGridAndConsistent) {
  const Result r = run("study closed-loop --quick --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  ASSERT_TRUE(j.contains("rows") && j["rows"].is_array()) << r.out;
  EXPECT_EQ(j["study"], "closed-loop");
  const int n = j["runs_per_cell"].get<int>();
  ASSERT_GE(n, 1);

  // Rows = one feedback row per (rate, latency) of the grid, plus one open-loop baseline.
  const auto rates = j["rates_hz"].get<std::vector<double>>();
  const auto latencies = j["latencies_s"].get<std::vector<double>>();
  ASSERT_FALSE(rates.empty());
  ASSERT_FALSE(latencies.empty());
  EXPECT_EQ(j["rows"].size(), rates.size() * latencies.size() + 1) << r.out;
  std::set<std::pair<double, double>> seen;
  int baselines = 0;
  for (const json& row : j["rows"]) {
    SCOPED_TRACE(row.dump());
    const std::string c = row["controller"];
    ASSERT_TRUE(c == "feedback" || c == "open-loop");
    if (c == "open-loop") {
      ++baselines;
    } else {
      const double rate = row["rate_hz"], latency = row["latency_s"];
      EXPECT_TRUE(seen.insert({rate, latency}).second) << "cell repeated";
      bool in_grid = false;
      for (double a : rates)
        for (double b : latencies) in_grid = in_grid || (near(a, rate) && near(b, latency));
      EXPECT_TRUE(in_grid);
    }
    // Counts, rate and interval agree.
    EXPECT_EQ(row["runs"].get<int>(), n);
    const int k = row["successes"];
    ASSERT_GE(k, 0);
    ASSERT_LE(k, n);
    const double p = row["success_rate"];
    EXPECT_NEAR(p, static_cast<double>(k) / n, 1e-12);
    const double lo = row["ci95"][0], hi = row["ci95"][1];
    EXPECT_LE(0.0, lo);
    EXPECT_LE(lo, p);
    EXPECT_LE(p, hi);
    EXPECT_LE(hi, 1.0);
    EXPECT_LT(lo, hi) << "a 95 % interval of a handful of runs cannot be a point";
    int failed = 0;
    for (const auto& [cls, count] : row["failures"].items()) {
      EXPECT_GT(count.get<int>(), 0) << cls;
      failed += count.get<int>();
    }
    EXPECT_EQ(failed, n - k) << "the failure breakdown does not add up";
    const double jitter = row["latency_jitter_s"];
    EXPECT_LE(jitter, row["latency_s"].get<double>()) << "a frame cannot arrive before capture";
    EXPECT_GT(row["wall_s"].get<double>(), 0);
    EXPECT_GT(row["cpu_s"].get<double>(), 0);
  }
  EXPECT_EQ(baselines, 1);

  // The scene's own camera is a cell, and so is its open-loop baseline.
  const json nominal = row_at(j, kSceneRate, kSceneLatency);
  ASSERT_FALSE(nominal.is_null()) << "no cell for the scene's camera:\n" << r.out;
  ASSERT_FALSE(row_at(j, kSceneRate, kSceneLatency, "open-loop").is_null()) << r.out;
  // A latency beyond the safety monitor's lost_timeout (0.25 s in the scene) must fail more often
  // than the scene's camera, at every rate.
  const double absurd = latencies.back();
  ASSERT_GE(absurd, 0.25) << "the quick grid has no absurd latency";
  for (double rate : rates) {
    const json bad = row_at(j, rate, absurd);
    ASSERT_FALSE(bad.is_null());
    EXPECT_LT(bad["successes"].get<int>(), nominal["successes"].get<int>())
        << rate << " Hz with " << absurd << " s latency:\n"
        << bad.dump() << "\nnominal:\n"
        << nominal.dump();
  }
  EXPECT_TRUE(j["files"].empty());
}

TEST_F(CliStudyClosedLoop, OutputsAgreeWithTheJsonAndAreNotOverwritten) {
  const bool plots = have_tool("gnuplot");
  const Result r =
      run(std::string("study closed-loop --quick --json --out res") + (plots ? "" : " --no-plot"));
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  std::vector<std::string> names = {"closed_loop.csv", "closed_loop.json"};
  if (plots) names.insert(names.end(), {"closed_loop.gp", "closed_loop.png"});
  for (const auto& name : names) {
    EXPECT_TRUE(fs::is_regular_file(dir_ / "res" / name)) << name;
    EXPECT_GT(fs::file_size(dir_ / "res" / name), 0u) << name;
  }
  EXPECT_EQ(j["files"].size(), names.size());

  // The CSV: a header with units, one line per JSON row, the same counts and intervals.
  const auto lines = lines_of(read_text(dir_ / "res" / "closed_loop.csv"));
  ASSERT_EQ(lines.size(), j["rows"].size() + 1);
  const auto header = cells_of(lines[0]);
  const auto col = [&](const std::string& name) {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return static_cast<int>(i);
    ADD_FAILURE() << "no column " << name << " in " << lines[0];
    return 0;
  };
  const int c_rate = col("rate[Hz]"), c_lat = col("latency[s]"), c_ctl = col("controller"),
            c_ok = col("successes"), c_lo = col("ci95_lo"), c_hi = col("ci95_hi");
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto cells = cells_of(lines[i]);
    ASSERT_EQ(cells.size(), header.size()) << lines[i];
    const json& row = j["rows"][i - 1];
    EXPECT_TRUE(near(std::stod(cells[c_rate]), row["rate_hz"].get<double>())) << lines[i];
    EXPECT_TRUE(near(std::stod(cells[c_lat]), row["latency_s"].get<double>())) << lines[i];
    EXPECT_EQ(cells[c_ctl], row["controller"].get<std::string>());
    EXPECT_EQ(std::stoi(cells[c_ok]), row["successes"].get<int>());
    EXPECT_TRUE(near(std::stod(cells[c_lo]), row["ci95"][0].get<double>())) << lines[i];
    EXPECT_TRUE(near(std::stod(cells[c_hi]), row["ci95"][1].get<double>())) << lines[i];
  }
  // closed_loop.json holds the same rows.
  const json file = json::parse(read_text(dir_ / "res" / "closed_loop.json"));
  EXPECT_EQ(file["rows"], j["rows"]);

  // A second run is refused before any work, and the first run's files are left as they were.
  const std::string csv = read_text(dir_ / "res" / "closed_loop.csv");
  const Result again = run("study closed-loop --quick --no-plot --out res");
  EXPECT_EQ(again.code, 2) << again.err;
  EXPECT_NE(again.err.find("--force"), std::string::npos) << again.err;
  EXPECT_EQ(read_text(dir_ / "res" / "closed_loop.csv"), csv);
}

TEST_F(CliStudyClosedLoop, BadInputExitsTwoAndWritesNothing) {
  expect_bad_input("study closed-loop --quick --out out --scene missing.yaml", "missing.yaml");
  // The paper's butterfly in full gravity has no camera: there is no loop to close.
  const std::string no_camera = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly.yaml";
  expect_bad_input("study closed-loop --quick --out out --scene " + quote(no_camera), "camera");
  // A scene the loop cannot use: a negative latency.
  std::string scene = read_text(std::string(FLATLAND_ASSET_DIR) + "/scenes/airtable-feedback.yaml");
  const std::string key = "latency: 0.033";
  const auto at = scene.find(key);
  ASSERT_NE(at, std::string::npos);
  scene.replace(at, key.size(), "latency: -0.01");
  write_text(dir_ / "bad.yaml", scene);
  expect_bad_input("study closed-loop --quick --out out --scene bad.yaml", "latency");
  expect_bad_input("study closed-loop --quick --out out --no-such-option", "--no-such-option");
  // The controller axis: unknown or repeated names, and the option on a study without the axis.
  expect_bad_input("study closed-loop --quick --out out --controller paper,bogus",
                   "--controller: unknown type 'bogus' (known: open-loop, feedback, paper");
  expect_bad_input("study closed-loop --quick --out out --controller paper --controller paper",
                   "given twice");
  expect_bad_input("study sim --quick --out out --controller paper", "--controller");
}

}  // namespace
