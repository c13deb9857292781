// Rolling objects through the `flatland` program (issue 26): a ring and a ball (solid, hollow, on
// two rails) simulate, `simulate --json` reports the rolling radius and inertia the run used
// (checked against their closed forms), a ball on rails oscillates in a circular well with the
// period of its own closed form under the hybrid contact model with its energy audit holding, bad
// object descriptions are one line naming the field, and `montecarlo` records a drawn world that
// cannot exist instead of dying of it.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>
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

/// A CSV with a header, each column by name; cells that are not numbers are kept as text too.
struct Table {
  std::map<std::string, std::vector<double>> numbers;
  std::map<std::string, std::vector<std::string>> text;
};

std::vector<std::string> csv_cells(const std::string& line) {
  // Quoted cells (the runs' failure messages hold commas) with doubled quotes inside.
  std::vector<std::string> cells;
  std::string cell;
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        cell += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        cell += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      cells.push_back(cell);
      cell.clear();
    } else {
      cell += c;
    }
  }
  cells.push_back(cell);
  return cells;
}

Table read_table(const fs::path& p) {
  const std::vector<std::string> lines = lines_of(read_text(p));
  Table t;
  if (lines.empty()) return t;
  const std::vector<std::string> names = csv_cells(lines[0]);
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> cells = csv_cells(lines[i]);
    for (std::size_t k = 0; k < names.size(); ++k) {
      const std::string cell = k < cells.size() ? cells[k] : "";
      char* end = nullptr;
      const double v = std::strtod(cell.c_str(), &end);
      t.numbers[names[k]].push_back(end != cell.c_str() ? v : std::nan(""));
      t.text[names[k]].push_back(cell);
    }
  }
  return t;
}

class CliObjects : public flatland_test::CliTestBase {
 protected:
  /// A planar scene with `hand`, `object`, `motion` and `contact` as YAML flow maps.
  fs::path scene(const std::string& name, const std::string& object,
                 const std::string& hand =
                     "{shape: polynomial, a: 0.18, b: -0.18, c: -0.252, "
                     "d: 0.216}",
                 const std::string& motion = "{type: butterfly, period: 1.181, k: -1.1393}",
                 const std::string& extra = "") const {
    const fs::path p = dir_ / (name + ".yaml");
    write_text(p, "gravity: {g: 9.8}\nhand: " + hand + "\nobject: " + object +
                      "\nmotion: " + motion + "\n" + extra);
    return p;
  }

  json simulate_json(const fs::path& s, const std::string& more = "") const {
    const Result r = run("simulate --scene " + quote(s.string()) + " --json" + more);
    EXPECT_EQ(r.code, 0) << r.err;
    json j;
    EXPECT_NO_THROW(j = json::parse(r.out)) << r.out;
    return j;
  }

  /// Bad input: exit 2, one line naming `field`, nothing on stdout, `out` not written.
  void expect_refused(const std::string& args, const std::string& field,
                      const std::string& out) const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(field), std::string::npos) << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / out));
  }
};

// The object the run used, against the closed forms of each description: a ring's J = m (R^2 +
// R_i^2) / 2, a solid ball's 2/5 m R^2, a hollow one's 2/3 m R^2, on rails the rolling radius
// sqrt(R^2 - (w/2)^2) with the ball's own inertia (here 1.31 m r^2: above what a disk of that
// radius could have, and taken), a given inertia as given.
TEST_F(CliObjects, SimulateReportsTheRollingRadiusAndInertiaOfEachObject) {
  struct Case {
    std::string object;
    std::string type;
    double radius, rolling_radius, inertia;
  };
  const double m = 0.3, R = 0.06, w = 0.1, Ri = 0.03;
  const std::string mass = ", mass: 0.3}";
  const std::vector<Case> cases = {
      {"{type: disk, radius: 0.051" + mass, "disk", 0.051, 0.051, 0.5 * m * 0.051 * 0.051},
      {"{type: ring, radius: 0.06, inner_radius: 0.03" + mass, "ring", R, R,
       0.5 * m * (R * R + Ri * Ri)},
      {"{type: ball, radius: 0.06" + mass, "ball", R, R, 0.4 * m * R * R},
      {"{type: ball, radius: 0.06, hollow: true" + mass, "ball", R, R, 2.0 / 3.0 * m * R * R},
      {"{type: ball, radius: 0.06, rails: {gap: 0.1}" + mass, "ball", R,
       std::sqrt(R * R - w * w / 4), 0.4 * m * R * R},
      {"{type: ring, radius: 0.06, inner_radius: 0.03, inertia: 0.0008" + mass, "ring", R, R,
       0.0008},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.object);
    const json j = simulate_json(scene("object", c.object), " --duration 0.3");
    ASSERT_TRUE(j.contains("object")) << j.dump();
    const json& o = j.at("object");
    EXPECT_EQ(o.at("type"), c.type);
    EXPECT_NEAR(o.at("radius").get<double>(), c.radius, 1e-15);
    EXPECT_NEAR(o.at("rolling_radius").get<double>(), c.rolling_radius, 1e-15);
    EXPECT_NEAR(o.at("inertia").get<double>() / c.inertia, 1.0, 1e-14);
    EXPECT_NEAR(o.at("mass").get<double>(), m, 1e-15);
    EXPECT_TRUE(j.at("energy").at("holds").get<bool>());
  }
  // On rails the ball's inertia exceeds m r^2 of its rolling radius: 2/5 R^2 / (R^2 - w^2/4).
  EXPECT_GT(0.4 * R * R / (R * R - w * w / 4), 1.3);
  // And an ellipse has no rolling radius: its J is m (a^2 + b^2) / 4.
  const json e = simulate_json(
      scene("ellipse", "{type: ellipse, semi_axes: [0.05, 0.04], mass: 2}"), " --duration 0.2");
  EXPECT_EQ(e.at("object").at("type"), "ellipse");
  EXPECT_TRUE(e.at("object").at("rolling_radius").is_null());
  EXPECT_NEAR(e.at("object").at("inertia").get<double>(), 2 * (0.05 * 0.05 + 0.04 * 0.04) / 4,
              1e-15);
}

// A ball on two rails (R = 6 cm, gap 10 cm: it rolls at r = 3.3 cm with J = 1.31 m r^2) in a
// circular well of radius 0.2 m, under the hybrid contact model with enough friction to roll: its
// centre swings on the circle of radius R_w - r, and energy gives (R_w - r)(1 + J/(m r^2)) phi'' =
// -g sin(phi), a pendulum of length L = (1 + J/(m r^2))(R_w - r) with phi = s_h. Its period is
// 4 sqrt(L/g) K(sin(A/2)) at amplitude A, and the run's energy audit holds (no losses: the
// amplitude stays).
TEST_F(CliObjects, ABallOnRailsInACircularWellSwingsWithItsPendulumsPeriodUnderTheHybridModel) {
  const double R = 0.06, w = 0.1, Rw = 0.2, amplitude = 0.01, tilt_deg = 30;
  const double r = std::sqrt(R * R - w * w / 4), J_ratio = 0.4 * R * R / (r * r);
  const double g = 9.8 * std::sin(tilt_deg * std::numbers::pi / 180);
  const double L = (1 + J_ratio) * (Rw - r);
  const double exact = 4 * std::sqrt(L / g) * std::comp_ellint_1(std::sin(amplitude / 2));
  const fs::path p = dir_ / "well.yaml";
  write_text(p,
             "gravity: {g: 9.8, tilt_deg: 30}\nhand: {shape: circle, radius: 0.2}\n"
             "object: {type: ball, radius: 0.06, rails: {gap: 0.1}}\n"
             "motion: {type: fixed, angle_deg: 0}\ninitial: {s_h: 0.01, sdot_h: 0}\n"
             "duration: 6.0\ncontact: {model: hybrid, mu: 1.0}\n");
  const json j = simulate_json(p, " --out run.csv --sample-dt 0.001");
  EXPECT_EQ(j.at("model"), "hybrid");
  EXPECT_TRUE(j.at("energy").at("holds").get<bool>()) << j.at("energy").dump();
  EXPECT_EQ(j.at("impacts"), 0);
  EXPECT_EQ(j.at("mode_time").at("sliding").get<double>(), 0.0);
  EXPECT_EQ(j.at("mode_time").at("flight").get<double>(), 0.0);
  EXPECT_NEAR(j.at("object").at("rolling_radius").get<double>(), r, 1e-15);
  const Table t = read_table(dir_ / "run.csv");
  const std::vector<double>& time = t.numbers.at("t");
  const std::vector<double>& s = t.numbers.at("s_h");
  std::vector<double> down;
  for (std::size_t i = 1; i < time.size(); ++i)
    if (s[i - 1] > 0 && s[i] <= 0)
      down.push_back(time[i - 1] + s[i - 1] / (s[i - 1] - s[i]) * (time[i] - time[i - 1]));
  ASSERT_GE(down.size(), 4u);
  const double period = (down.back() - down.front()) / static_cast<double>(down.size() - 1);
  // The integrator (rtol 1e-10) and the crossings' interpolation between 1 ms samples, where s_h
  // is nearly straight: 1e-7 as for the disk in the well (tests/cli/test_cli_hand_shapes.cpp).
  EXPECT_NEAR(period / exact, 1.0, 1e-7) << period << " s against " << exact << " s";
  double peak = 0;
  for (std::size_t i = 0; i < time.size(); ++i)
    if (time[i] > 4.0) peak = std::max(peak, std::abs(s[i]));
  EXPECT_NEAR(peak, amplitude, 1e-6);
}

TEST_F(CliObjects, BadObjectsAreOneLineNamingTheFieldAndWriteNothing) {
  const auto refused = [&](const std::string& object, const std::string& field) {
    const fs::path p = scene("bad", object);
    expect_refused("simulate --scene " + quote(p.string()) + " --out bad.csv", field, "bad.csv");
  };
  refused("{type: ball, radius: 0.06, rails: {gap: 0.12}}", "object.rails.gap");  // = 2R
  refused("{type: ball, radius: 0.06, rails: {gap: 0.13}}", "object.rails.gap");  // > 2R
  refused("{type: ring, radius: 0.051, inner_radius: 0.051}", "object.inner_radius");
  refused("{type: ring, radius: 0.051, inner_radius: 0.06}", "object.inner_radius");
  refused("{type: ball, radius: 0.06, hollow: true, inertia: 0.001}", "object.hollow");
  refused("{type: disk, radius: 0.051, inertia: 0.0027}", "object.inertia");  // > m R^2
  refused("{type: ball, radius: 0.06, rails: {gap: 0.1}, inertia: 0.0037}", "object.inertia");
  refused("{type: ring, radius: 0.06, inner_radius: 0.05, inertia: 0.002}", "object.inertia");
}

// montecarlo on a disk whose given inertia is 99.2 % of m R^2: a radius drawn more than 0.4 %
// small leaves the inertia above m R'^2, a body that cannot exist. Such a world is recorded with
// its seed and run (outcome invalid_world, the reason naming object.inertia), left out of the
// rates, and the run goes on; every other world has a physical outcome. Which worlds those are
// is computed here from the drawn radii in runs.csv.
/// The closed-loop experiment with a disk whose inertia (0.00258 kg m^2) is close to m R^2 of its
/// radius (1 kg, 0.051 m: 0.002601): a radius drawn 0.4 % smaller cannot carry it, so a perturbed
/// world may not exist. Its plan is solved for this disk's own k.
constexpr double kHeavyInertia = 0.00258;
std::string heavy_disk_scene() {
  std::string text = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "airtable-feedback.yaml");
  const auto mass = text.find("\n  mass: 1.0");
  const auto plan = text.find("\n  plan: scene");
  if (mass == std::string::npos || plan == std::string::npos)
    throw std::runtime_error("airtable-feedback.yaml changed: no object mass 1.0 or plan: scene");
  text.replace(plan, 14, "\n  plan: solve");
  return text.insert(mass, "\n  inertia: 0.00258");
}

TEST_F(CliObjects, MontecarloRecordsAWorldThatCannotExistAndGoesOn) {
  const double J = kHeavyInertia;
  write_text(dir_ / "heavy.yaml", heavy_disk_scene());
  const Result r = run("montecarlo --scene heavy.yaml --n 8 --out mc --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  const Table runs = read_table(dir_ / "mc" / "runs.csv");
  const std::size_t rows = runs.numbers.at("run").size();
  ASSERT_EQ(rows, 16u);  // 8 worlds x (open-loop, feedback)
  std::map<std::string, int> invalid_by_controller;
  int invalid = 0;
  for (std::size_t i = 0; i < rows; ++i) {
    const double radius = runs.numbers.at("radius_m")[i];
    const bool cannot_exist = 1.0 * radius * radius < J;
    const std::string outcome = runs.text.at("outcome")[i];
    SCOPED_TRACE("run " + runs.text.at("run")[i] + " radius " + runs.text.at("radius_m")[i]);
    EXPECT_EQ(outcome == "invalid_world", cannot_exist) << outcome;
    if (!cannot_exist) continue;
    ++invalid;
    ++invalid_by_controller[runs.text.at("controller")[i]];
    const std::string& why = runs.text.at("failure")[i];
    EXPECT_NE(why.find("object.inertia"), std::string::npos) << why;
    EXPECT_NE(why.find("seed 1, run " + runs.text.at("run")[i] + ")"), std::string::npos) << why;
  }
  ASSERT_GT(invalid, 0) << "the seed draws no world that cannot exist: the test proves nothing";
  ASSERT_LT(invalid, static_cast<int>(rows)) << "every world cannot exist";
  EXPECT_EQ(j.at("invalid_world_runs").size(), static_cast<std::size_t>(invalid));
  for (const json& s : j.at("summaries")) {
    const std::string name = s.at("controller");
    EXPECT_EQ(s.at("invalid_worlds").get<int>(), invalid_by_controller[name]) << name;
    EXPECT_EQ(s.at("outcomes").at("invalid_world").get<int>(), invalid_by_controller[name]);
  }
}

// The closed-loop study meets the same worlds: one that cannot exist is counted in invalid_worlds
// (JSON, closed_loop.csv, the table) and, like a numerical failure, left out of the success rate
// and its interval: the rate is over the worlds that have a physical outcome.
TEST_F(CliObjects, StudyClosedLoopLeavesAWorldThatCannotExistOutOfTheRate) {
  write_text(dir_ / "heavy.yaml", heavy_disk_scene());
  const Result r = run("study closed-loop --scene heavy.yaml --quick --out sc --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = json::parse(r.out);
  const auto lines = lines_of(read_text(dir_ / "sc" / "closed_loop.csv"));
  const std::vector<std::string> header = csv_cells(lines.at(0));
  const auto column = std::find(header.begin(), header.end(), "invalid_worlds");
  ASSERT_NE(column, header.end()) << lines[0];
  ASSERT_EQ(lines.size(), j.at("rows").size() + 1);
  int invalid = -1;
  for (std::size_t i = 0; i < j.at("rows").size(); ++i) {
    const json& row = j["rows"][i];
    const int runs = row.at("runs"), successes = row.at("successes");
    const int failed_numerically = row.at("numerical_failures");
    const int cannot_exist = row.at("invalid_worlds");
    if (invalid < 0) invalid = cannot_exist;
    EXPECT_EQ(cannot_exist, invalid) << "every cell meets the same worlds: " << row;
    int failures = 0;
    for (const auto& [cls, count] : row.at("failures").items()) failures += count.get<int>();
    EXPECT_EQ(successes + failures + failed_numerically + cannot_exist, runs) << row;
    const int counted = runs - failed_numerically - cannot_exist;
    ASSERT_GT(counted, 0) << row;
    EXPECT_DOUBLE_EQ(row.at("success_rate").get<double>(), static_cast<double>(successes) / counted)
        << row;
    const std::vector<std::string> cells = csv_cells(lines.at(i + 1));
    ASSERT_EQ(cells.size(), header.size()) << lines[i + 1];
    EXPECT_EQ(std::stoi(cells[static_cast<std::size_t>(column - header.begin())]), cannot_exist);
  }
  ASSERT_GT(invalid, 0) << "the seed draws no world that cannot exist: the test proves nothing";
  const Result text = run("study closed-loop --scene heavy.yaml --quick --out sc2");
  ASSERT_EQ(text.code, 0) << text.err;
  EXPECT_NE(text.out.find(std::to_string(invalid) + " could not exist (not counted)"),
            std::string::npos)
      << text.out;
}

}  // namespace
