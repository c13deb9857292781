// End-to-end tests of `flatland study render` and `flatland study tracker` (--quick): the CSV has
// the documented columns and one row per grid cell, the numbers obey what the renderer and the
// tracker promise (acceptance bounds, monotone trends, the pinhole scale between px and mm worked
// out from the camera), and bad input exits 2 without writing anything.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::cells_of;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

/// A CSV as one map column -> text per row; the header separately.
struct CsvByName {
  std::vector<std::string> header;
  std::vector<std::map<std::string, std::string>> rows;
  double num(std::size_t row, const std::string& col) const {
    return std::stod(rows.at(row).at(col));
  }
};

CsvByName read_csv_by_name(const fs::path& p) {
  CsvByName csv;
  const auto lines = lines_of(read_text(p));
  if (lines.empty()) return csv;
  csv.header = cells_of(lines[0]);
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto c = cells_of(lines[i]);
    EXPECT_EQ(c.size(), csv.header.size()) << "row " << i << ": " << lines[i];
    std::map<std::string, std::string> row;
    for (std::size_t k = 0; k < c.size() && k < csv.header.size(); ++k) row[csv.header[k]] = c[k];
    csv.rows.push_back(row);
  }
  return csv;
}

bool have_gnuplot() { return std::system("command -v gnuplot > /dev/null 2>&1") == 0; }

class StudyVision : public flatland_test::CliTestBase {
 protected:
  /// Run a study that must succeed and print exactly one JSON object on stdout.
  json run_json(const std::string& args) {
    const Result r = run(args);
    EXPECT_EQ(r.code, 0) << r.err;
    json j;
    try {
      j = json::parse(r.out);  // throws on anything but exactly one JSON document
    } catch (const std::exception& e) {
      ADD_FAILURE() << "stdout is not one JSON object: " << e.what() << "\n" << r.out;
    }
    EXPECT_TRUE(j.is_object());
    return j;
  }

  /// `args` (which writes `out`) is refused while `out` holds an old file: exit 2, one error
  /// line naming --out, the old file untouched and nothing else created.
  void expect_refused(const std::string& args, const std::string& out) {
    fs::create_directories(dir_ / out);
    write_text(dir_ / out / "old.txt", "old\n");
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << r.err;
    const auto err = lines_of(r.err);
    ASSERT_FALSE(err.empty());
    EXPECT_EQ(err.back().rfind("flatland: error: --out: ", 0), 0u) << r.err;
    EXPECT_NE(err.back().find("--force"), std::string::npos) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
    std::set<std::string> names;
    for (const auto& e : fs::recursive_directory_iterator(dir_))
      names.insert(fs::relative(e.path(), dir_).string());
    EXPECT_EQ(names, (std::set<std::string>{out, out + "/old.txt"}));
    EXPECT_EQ(read_text(dir_ / out / "old.txt"), "old\n");
  }
};

}  // namespace

// The render study: refused over an old output, then (--force) the CSV has one row per
// (supersampling, resolution) cell, the best supersampling meets the renderer's 0.05 px bound and
// is no worse than none, and more pixels cost frames/s.
TEST_F(StudyVision, RenderQuick) {
  expect_refused("study render --quick --json --no-plot --out r", "r");
  const json j = run_json("study render --quick --json --no-plot --out r --force");
  EXPECT_EQ(j["study"], "render");
  EXPECT_FALSE(fs::exists(dir_ / "r" / "old.txt")) << "--force replaces the directory";
  EXPECT_TRUE(fs::exists(dir_ / "r" / "render.json"));
  EXPECT_FALSE(fs::exists(dir_ / "r" / "render_error.png")) << "--no-plot draws nothing";
  EXPECT_EQ(json::parse(read_text(dir_ / "r" / "render.json"))["rows"].size(), j["rows"].size());

  const CsvByName csv = read_csv_by_name(dir_ / "r" / "render.csv");
  EXPECT_EQ(csv.header,
            (std::vector<std::string>{
                "supersample", "width_px", "height_px", "fx_px", "disk_radius_px", "positions",
                "frames", "centroid_rms_px", "centroid_max_px", "bias_x_px", "bias_y_px",
                "frame_ms_median", "frame_ms_p95", "fps_median", "fps_mean"}));
  const auto factors = j["supersample"].get<std::vector<int>>();
  const auto sizes = j["resolutions"];
  ASSERT_GE(factors.size(), 2u);
  ASSERT_GE(sizes.size(), 2u);
  ASSERT_EQ(csv.rows.size(), factors.size() * sizes.size());
  const int lo = *std::min_element(factors.begin(), factors.end());
  const int hi = *std::max_element(factors.begin(), factors.end());
  // (supersample, width) -> row: every cell exactly once.
  std::map<std::pair<int, int>, std::size_t> cell;
  for (std::size_t i = 0; i < csv.rows.size(); ++i) {
    const auto key = std::make_pair(static_cast<int>(csv.num(i, "supersample")),
                                    static_cast<int>(csv.num(i, "width_px")));
    EXPECT_TRUE(cell.emplace(key, i).second) << "cell listed twice";
    EXPECT_GE(csv.num(i, "centroid_max_px"), csv.num(i, "centroid_rms_px"));
    EXPECT_EQ(csv.num(i, "positions"), static_cast<double>(j["positions"].size()));
    // Timed: every rendered state (each disk and it turned by pi) at least once.
    EXPECT_GE(csv.num(i, "frames"), 2 * csv.num(i, "positions"));
    EXPECT_GT(csv.num(i, "fps_median"), 0.0);
  }
  int w_min = 1 << 30, w_max = 0;
  for (const auto& s : sizes) {
    const int w = s[0].get<int>();
    w_min = std::min(w_min, w);
    w_max = std::max(w_max, w);
    ASSERT_TRUE(cell.count({lo, w}) && cell.count({hi, w})) << "missing cells at width " << w;
    const double best = csv.num(cell[{hi, w}], "centroid_rms_px");
    const double none = csv.num(cell[{lo, w}], "centroid_rms_px");
    EXPECT_LT(best, 0.05) << "supersample " << hi << " at width " << w;
    EXPECT_LE(best, none) << "supersampling made the centroid worse at width " << w;
  }
  // 16x the pixels (or more) per frame cannot be rendered as fast, even on a loaded machine.
  EXPECT_LT(csv.num(cell[{hi, w_max}], "fps_median"), csv.num(cell[{lo, w_min}], "fps_median"));
}

// The tracker study: one row per (method, exposure, noise), every frame accounted for, the error
// grows with noise, the edge fit meets the tracker's acceptance (docs/VISION.md: <= 0.1 px with
// noise and blur, nothing lost), and the mm column is the px column times the pinhole scale of
// the overhead camera, distance / f.
TEST_F(StudyVision, TrackerQuick) {
  const json j = run_json("study tracker --quick --json --no-plot --out t");
  EXPECT_EQ(j["study"], "tracker");
  EXPECT_TRUE(fs::exists(dir_ / "t" / "tracker.json"));
  EXPECT_FALSE(fs::exists(dir_ / "t" / "tracker_error.png"));

  const CsvByName csv = read_csv_by_name(dir_ / "t" / "tracker.csv");
  EXPECT_EQ(csv.header, (std::vector<std::string>{"method",
                                                  "fit",
                                                  "blur_level",
                                                  "exposure_s",
                                                  "blur_subframes",
                                                  "blur_px_mean",
                                                  "blur_px_max",
                                                  "noise_dn",
                                                  "frames",
                                                  "lost",
                                                  "reacquired",
                                                  "gross",
                                                  "err_rms_px",
                                                  "err_max_px",
                                                  "err_rms_mm",
                                                  "err_max_mm",
                                                  "latency_median_ms",
                                                  "latency_p95_ms",
                                                  "latency_max_ms",
                                                  "sigma_median_px",
                                                  "err_over_sigma_median",
                                                  "beyond_3_sigma"}));
  const auto noises = j["noise_dn"].get<std::vector<double>>();
  const auto& exposures = j["exposures"];
  std::set<std::string> methods;
  for (const auto& m : j["methods"]) methods.insert(m["name"].get<std::string>());
  EXPECT_TRUE(methods.count("edge") && methods.count("moments") && methods.count("hough"));
  ASSERT_GE(noises.size(), 2u);
  ASSERT_GE(exposures.size(), 2u);
  ASSERT_EQ(csv.rows.size(), methods.size() * noises.size() * exposures.size());
  // The longest exposure blurs by a few px at the fastest frame, the shortest not at all.
  EXPECT_EQ(exposures[0]["blur_px_max"].get<double>(), 0.0);
  EXPECT_GT(exposures.back()["blur_px_max"].get<double>(), 2.0);

  const double lo_noise = *std::min_element(noises.begin(), noises.end());
  const double hi_noise = *std::max_element(noises.begin(), noises.end());
  const double height = j["camera"]["position"][2].get<double>();  // straight down (asserted)
  ASSERT_TRUE(j["camera"]["fronto_parallel"].get<bool>());
  const double mm_per_px = 1e3 * (height - 0.006) / j["camera"]["fx"].get<double>();
  // (method, blur level, noise) -> row
  std::map<std::tuple<std::string, int, double>, std::size_t> cell;
  for (std::size_t i = 0; i < csv.rows.size(); ++i) {
    const auto& r = csv.rows[i];
    EXPECT_TRUE(methods.count(r.at("method"))) << r.at("method");
    EXPECT_TRUE(
        cell.emplace(std::make_tuple(r.at("method"), static_cast<int>(csv.num(i, "blur_level")),
                                     csv.num(i, "noise_dn")),
                     i)
            .second);
    EXPECT_EQ(csv.num(i, "frames"), j["frames"].get<double>());
    EXPECT_LE(csv.num(i, "lost"), csv.num(i, "frames"));
    EXPECT_GE(csv.num(i, "latency_p95_ms"), csv.num(i, "latency_median_ms"));
    EXPECT_GT(csv.num(i, "latency_median_ms"), 0.0);
    if (csv.num(i, "lost") < csv.num(i, "frames")) {
      EXPECT_GE(csv.num(i, "err_max_px"), csv.num(i, "err_rms_px"));
      EXPECT_NEAR(csv.num(i, "err_rms_mm"), mm_per_px * csv.num(i, "err_rms_px"),
                  0.01 * mm_per_px * csv.num(i, "err_rms_px") + 1e-9)
          << "mm error is not the px error times distance / f";
      // Whether sigma tells the truth: a share of the frames tracked, a whole number of them.
      EXPECT_GE(csv.num(i, "beyond_3_sigma"), 0.0);
      EXPECT_LE(csv.num(i, "beyond_3_sigma"), 1.0);
      const double tracked = csv.num(i, "frames") - csv.num(i, "lost");
      const double beyond = csv.num(i, "beyond_3_sigma") * tracked;
      EXPECT_NEAR(beyond, std::round(beyond), 1e-3 * tracked) << "not a share of the frames";
      EXPECT_GT(csv.num(i, "sigma_median_px"), 0.0);
      EXPECT_LE(csv.num(i, "err_over_sigma_median") * csv.num(i, "sigma_median_px"),
                csv.num(i, "err_max_px") * (1 + 1e-6))
          << "a median error above the largest";
    }
  }
  // Noise hurts: at the sharpest exposure, some method is worse at the highest noise level.
  int worse = 0;
  for (const std::string& m : methods)
    if (csv.num(cell.at({m, 0, hi_noise}), "err_rms_px") >
        csv.num(cell.at({m, 0, lo_noise}), "err_rms_px"))
      ++worse;
  EXPECT_GE(worse, 1) << "no method got worse with noise";
  // The tracker's acceptance at 2 DN with the longest exposure (docs/VISION.md).
  const int last = static_cast<int>(exposures.size()) - 1;
  if (std::find(noises.begin(), noises.end(), 2.0) != noises.end()) {
    const std::size_t e = cell.at({"edge", last, 2.0});
    EXPECT_EQ(csv.num(e, "lost"), 0.0);
    EXPECT_LE(csv.num(e, "err_rms_px"), 0.1);
  } else {
    ADD_FAILURE() << "the quick grid has no 2 DN level";
  }
}

// Bad input exits 2 with one line and writes nothing: a scene without a camera, a missing scene,
// an unknown option, an existing --out without --force.
TEST_F(StudyVision, BadInputWritesNothing) {
  const std::string no_camera = std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly.yaml";
  for (const std::string study : {"render", "tracker"}) {
    SCOPED_TRACE(study);
    Result r = run("study " + study + " --quick --scene " + quote(no_camera) + " --out o");
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_EQ(lines_of(r.err).size(), 1u) << r.err;
    EXPECT_NE(r.err.find("camera"), std::string::npos) << r.err;
    r = run("study " + study + " --quick --scene missing.yaml --out o");
    EXPECT_EQ(r.code, 2) << r.err;
    r = run("study " + study + " --quick --supersample 3 --out o");
    EXPECT_EQ(r.code, 2) << r.err;
    EXPECT_TRUE(fs::is_empty(dir_)) << "something was written";
    expect_refused("study " + study + " --quick --no-plot --out o", "o");
    fs::remove_all(dir_ / "o");
  }
}

// With gnuplot: the plots and the scripts that drew them, next to the CSV and the summary.
TEST_F(StudyVision, Plots) {
  if (!have_gnuplot()) GTEST_SKIP() << "gnuplot is not installed";
  for (const std::string study : {"render", "tracker"}) {
    const Result r = run("study " + study + " --quick --out " + study);
    ASSERT_EQ(r.code, 0) << r.err;
    const std::vector<std::string> files =
        study == "render"
            ? std::vector<std::string>{"render.csv",      "render.json",    "render_error.png",
                                       "render_error.gp", "render_fps.png", "render_fps.gp"}
            : std::vector<std::string>{"tracker.csv",         "tracker.json",
                                       "tracker_error.png",   "tracker_error.gp",
                                       "tracker_latency.png", "tracker_latency.gp"};
    std::set<std::string> found;
    for (const auto& e : fs::directory_iterator(dir_ / study)) {
      found.insert(e.path().filename().string());
      EXPECT_GT(fs::file_size(e.path()), 0u) << e.path();
    }
    EXPECT_EQ(found, std::set<std::string>(files.begin(), files.end()));
    for (const std::string& f : files)
      EXPECT_NE(r.out.find("wrote " + study + "/" + f), std::string::npos) << r.out;
  }
}

// An interlaced camera exposes each field for at most the field interval (1/(2 fps)), so the
// study's exposures are fractions of that, and its fields are tracked like any frame: the edge
// fit within the tracker's acceptance (docs/VISION.md: 0.1 px) on the combed frames, nothing lost.
TEST_F(StudyVision, TrackerQuickOnAnInterlacedCamera) {
  std::string scene = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly-camera.yaml");
  const auto at = scene.find("\n  exposure: ");
  ASSERT_NE(at, std::string::npos);
  scene.insert(at + 1, "  readout: interlaced\n");
  const auto d = scene.find("\nduration: ");
  ASSERT_NE(d, std::string::npos);
  scene.replace(d + 1, scene.find('\n', d + 1) - d - 1, "duration: 1.0");
  write_text(dir_ / "interlaced.yaml", scene);
  const json j = run_json("study tracker --scene interlaced.yaml --quick --json --no-plot --out t");
  EXPECT_EQ(j["readout"], "interlaced");
  const double fps = j["camera"]["fps"].get<double>();
  ASSERT_GE(j["exposures"].size(), 2u);
  EXPECT_NEAR(j["exposures"].back()["exposure_s"].get<double>(), 0.5 / fps, 1e-12);
  const CsvByName csv = read_csv_by_name(dir_ / "t" / "tracker.csv");
  int edge_rows = 0;
  for (std::size_t i = 0; i < csv.rows.size(); ++i) {
    if (csv.rows[i].at("method") != "edge") continue;
    ++edge_rows;
    EXPECT_EQ(csv.num(i, "lost"), 0.0) << "row " << i;
    EXPECT_LT(csv.num(i, "err_rms_px"), 0.1) << "row " << i;
  }
  EXPECT_GT(edge_rows, 0);
}
