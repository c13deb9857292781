// End-to-end tests of `flatland render`: run the built binary in a fresh temporary directory and
// check exit codes, stdout JSON, stderr, the frames, the ground truth and the metadata it writes.
// Image geometry is checked against the pinhole model worked out by hand for a camera looking
// straight down, never against the program's own numbers.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using flatland_test::have_tool;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
using nlohmann::json;

const char* kTruthHeader =
    "frame,t,dropped,theta,s_h,disk_x,disk_y,disk_z,disk_u,disk_v,marker_x,marker_y,marker_z,"
    "marker_u,marker_v";

std::vector<double> fields_of(const std::string& line) {
  std::vector<double> out;
  std::stringstream ss(line);
  for (std::string cell; std::getline(ss, cell, ',');) out.push_back(std::stod(cell));
  return out;
}

/// Width and height from a PNG's IHDR chunk; {0, 0} if `p` is not a PNG.
std::pair<std::uint32_t, std::uint32_t> png_size(const fs::path& p) {
  const std::string s = read_text(p);
  if (s.size() < 24 || s.compare(0, 8, "\x89PNG\r\n\x1a\n") != 0 || s.compare(12, 4, "IHDR") != 0)
    return {0, 0};
  const auto be32 = [&](std::size_t i) {
    return (static_cast<std::uint32_t>(static_cast<unsigned char>(s[i])) << 24) |
           (static_cast<std::uint32_t>(static_cast<unsigned char>(s[i + 1])) << 16) |
           (static_cast<std::uint32_t>(static_cast<unsigned char>(s[i + 2])) << 8) |
           static_cast<std::uint32_t>(static_cast<unsigned char>(s[i + 3]));
  };
  return {be32(16), be32(20)};
}

class CliRenderTest : public flatland_test::CliTestBase {
 protected:
  static fs::path camera_scene() {
    return fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly-camera.yaml";
  }

  /// A copy of the bundled camera scene with each `from` replaced by its `to` (which must occur).
  fs::path camera_scene_with(const std::string& name,
                             const std::vector<std::pair<std::string, std::string>>& edits) const {
    return scene_with(camera_scene(), name, edits);
  }

  /// A copy of `source` with each `from` replaced by its `to` (which must occur).
  fs::path scene_with(const fs::path& source, const std::string& name,
                      const std::vector<std::pair<std::string, std::string>>& edits) const {
    std::string text = read_text(source);
    for (const auto& [from, to] : edits) {
      const auto pos = text.find(from);
      EXPECT_NE(pos, std::string::npos) << "the bundled scene no longer contains '" << from << "'";
      if (pos != std::string::npos) text.replace(pos, from.size(), to);
    }
    const fs::path p = dir_ / name;
    write_text(p, text);
    return p;
  }

  /// A 160 x 120 px camera 1.2 m over the pivot, looking straight down (fx = fy = 225 px keeps the
  /// bundled scene's field of view).
  fs::path small_scene() const {
    return camera_scene_with("small.yaml", {{"width: 640 ", "width: 160 "},
                                            {"height: 480 ", "height: 120 "},
                                            {"fx: 900 ", "fx: 225 "},
                                            {"fy: 900 ", "fy: 225 "},
                                            {"cx: 319.5 ", "cx: 79.5 "},
                                            {"cy: 239.5 ", "cy: 59.5 "}});
  }

  /// Bad input: exit 2, one line "flatland: error: ..." naming `field`, nothing on stdout, `out`
  /// not created.
  void expect_bad_input(const std::string& args, const std::string& field,
                        const std::string& out) const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << "stderr: " << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(field), std::string::npos)
        << "message does not name " << field << ": " << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    EXPECT_FALSE(fs::exists(dir_ / out)) << "created " << out;
  }

  static json parse_json(const Result& r) {
    json j;
    EXPECT_NO_THROW(j = json::parse(r.out)) << "stdout is not one JSON value:\n" << r.out;
    EXPECT_TRUE(j.is_object());
    return j;
  }

  static int temporaries_in(const fs::path& d) {
    int n = 0;
    for (const auto& e : fs::recursive_directory_iterator(d))
      if (e.path().filename().string().find(".tmp-") != std::string::npos) ++n;
    return n;
  }

  /// truth.csv: the header, then one row per frame; checks each row's frame number and nominal
  /// time (no jitter in these scenes) and that the image points are the pinhole projection of the
  /// table points for a camera at height `z_cam` looking straight down with image up = +y.
  static std::vector<std::vector<double>> check_truth(const fs::path& csv, long frames, double fps,
                                                      double f, double cx, double cy,
                                                      double z_cam) {
    const auto lines = lines_of(read_text(csv));
    EXPECT_FALSE(lines.empty());
    if (lines.empty()) return {};
    EXPECT_EQ(lines[0], kTruthHeader);
    EXPECT_EQ(static_cast<long>(lines.size()) - 1, frames) << "one row per frame";
    std::vector<std::vector<double>> rows;
    for (std::size_t i = 1; i < lines.size(); ++i) {
      const std::vector<double> v = fields_of(lines[i]);
      EXPECT_EQ(v.size(), 15u) << lines[i];
      if (v.size() != 15u) continue;
      const double frame = static_cast<double>(i - 1);
      EXPECT_EQ(v[0], frame);
      EXPECT_NEAR(v[1], frame / fps, 1e-12);
      EXPECT_EQ(v[2], 0.0);  // not dropped
      // disk (5, 6, 7) -> (8, 9); marker (10, 11, 12) -> (13, 14)
      for (int p : {5, 10}) {
        const double depth = z_cam - v[p + 2];
        EXPECT_NEAR(v[p + 3], cx + f * v[p] / depth, 1e-6) << lines[i];
        EXPECT_NEAR(v[p + 4], cy - f * v[p + 1] / depth, 1e-6) << lines[i];
      }
      rows.push_back(v);
    }
    return rows;
  }
};

// --------------------------------------------------------------------------------------------

TEST_F(CliRenderTest, HelpListsTheOptionsWithUnits) {
  const Result r = run("render --help");
  EXPECT_EQ(r.code, 0) << r.err;
  for (const char* s : {"--scene", "--out", "--view", "overhead", "side", "--overlay", "--gl",
                        "osmesa", "egl", "--json", "--fps", "frames per s", "--duration", "s (> 0)",
                        "--solve", "FILE.mp4", "truth.csv", "px", "REQUIRED"})
    EXPECT_NE(r.out.find(s), std::string::npos) << "help does not mention " << s << ":\n" << r.out;
}

TEST_F(CliRenderTest, TheMainHelpListsTheCommand) {
  const Result r = run("--help");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("render"), std::string::npos) << r.out;
}

TEST_F(CliRenderTest, BadInputExits2AndWritesNothing) {
  const std::string scene = "--scene " + quote(small_scene().string());
  // The paper scene has no camera.
  expect_bad_input(
      "render --scene " +
          quote((fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly.yaml").string()) +
          " --out frames",
      "camera: the scene has no camera section (needed by render)", "frames");
  expect_bad_input("render " + scene + " --view top --out frames", "--view", "frames");
  expect_bad_input("render " + scene + " --gl vulkan --out frames", "--gl", "frames");
  expect_bad_input("render --scene " +
                       quote(camera_scene_with("below.yaml", {{"position: [0.0, 0.0, 1.2]",
                                                               "position: [0.0, 0.0, -1]"}})
                                 .string()) +
                       " --out frames",
                   "camera.position: the camera must be above the table (z > 0)", "frames");
  expect_bad_input("render --scene " +
                       quote(camera_scene_with("fx0.yaml", {{"fx: 900 ", "fx: 0 "}}).string()) +
                       " --out run.mp4",
                   "camera.fx", "run.mp4");
  expect_bad_input(
      "render --scene " +
          quote(camera_scene_with("fxneg.yaml", {{"fx: 900 ", "fx: -900 "}}).string()) +
          " --out frames",
      "camera.fx", "frames");
  expect_bad_input(
      "render --scene " +
          quote(camera_scene_with("zero.yaml", {{"width: 640 ", "width: 0 "}}).string()) +
          " --out frames",
      "camera.width", "frames");
  expect_bad_input(
      "render --scene " +
          quote(camera_scene_with("zeroh.yaml", {{"height: 480 ", "height: 0 "}}).string()) +
          " --out frames",
      "camera.height", "frames");
  expect_bad_input("render --scene missing.yaml --out frames", "cannot read scene file", "frames");
  expect_bad_input("render --scene " + quote(dir_.string()) + " --out frames",
                   "cannot read scene file", "frames");
  expect_bad_input("render " + scene + " --fps 0 --out frames", "--fps", "frames");
  expect_bad_input("render " + scene + " --duration -1 --out frames", "--duration", "frames");
  expect_bad_input("render " + scene + " --out run.avi", "--out", "run.avi");
  expect_bad_input("render " + scene, "--out", "frames");  // --out is required
  // A fixed hand has no butterfly k to solve.
  expect_bad_input("render --scene " +
                       quote(camera_scene_with("fixed.yaml", {{"  type: butterfly\n  period: 4.0 ",
                                                               "  type: fixed\n  #"},
                                                              {"  k: -1.1393 ", "  #"}})
                                 .string()) +
                       " --solve --out frames",
                   "--solve", "frames");
  // --out naming an existing file that is not a directory.
  write_text(dir_ / "afile", "x");
  const Result r = run("render " + scene + " --out afile");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_EQ(read_text(dir_ / "afile"), "x");
}

TEST_F(CliRenderTest, RendersPngFramesWithTruthAndMetadata) {
  const Result r = run("render --scene " + quote(small_scene().string()) +
                       " --out out/frames --duration 0.2 "
                       "--json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  for (const char* k :
       {"frames", "width", "height", "fps_rendered", "output", "dropped", "truth", "gl"})
    EXPECT_TRUE(j.contains(k)) << "missing key " << k << "\n" << r.out;
  // 0.2 s at 30 fps: t = 0, 1/30, ..., 6/30.
  EXPECT_EQ(j.value("frames", -1), 7);
  EXPECT_EQ(j.value("dropped", -1), 0);
  EXPECT_EQ(j.value("width", -1), 160);
  EXPECT_EQ(j.value("height", -1), 120);
  EXPECT_TRUE(j["fps_rendered"].is_number() && j["fps_rendered"].get<double>() > 0) << r.out;
  EXPECT_EQ(j.value("output", ""), "out/frames");
  EXPECT_EQ(j.value("truth", ""), "out/frames/truth.csv");

  const fs::path d = dir_ / "out" / "frames";
  std::set<std::string> pngs;
  for (const auto& e : fs::directory_iterator(d))
    if (e.path().extension() == ".png") pngs.insert(e.path().filename().string());
  ASSERT_EQ(pngs.size(), 7u);
  for (int i = 0; i < 7; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06d.png", i);
    ASSERT_TRUE(pngs.count(name)) << name;
    const auto [w, h] = png_size(d / name);
    EXPECT_EQ(w, 160u) << name;
    EXPECT_EQ(h, 120u) << name;
  }
  EXPECT_EQ(temporaries_in(dir_), 0);

  // The disk starts at rest in the palm well, on the hand's axis of symmetry above the pivot, so
  // the overhead camera (image up = table +y) sees it above the image centre.
  const auto rows = check_truth(d / "truth.csv", 7, 30.0, 225.0, 79.5, 59.5, 1.2);
  ASSERT_EQ(rows.size(), 7u);
  EXPECT_NEAR(rows[0][3], 0.0, 1e-9);   // theta(0)
  EXPECT_NEAR(rows[0][4], -1.0, 1e-9);  // s_h(0): the palm well
  EXPECT_NEAR(rows[0][5], 0.0, 1e-9);   // disk x
  // Palm well at y(-1) = -(b + d + f) = 0.0576 m, disk centre one radius (0.051 m) above it.
  EXPECT_NEAR(rows[0][6], 0.0576 + 0.051, 1e-9);
  EXPECT_LT(rows[0][9], 59.5);  // above the image centre

  json meta;
  ASSERT_NO_THROW(meta = json::parse(read_text(d / "meta.json")));
  ASSERT_TRUE(meta.contains("camera"));
  const json& cam = meta["camera"];
  EXPECT_EQ(cam.value("width", -1), 160);
  EXPECT_EQ(cam.value("height", -1), 120);
  EXPECT_DOUBLE_EQ(cam.value("fx", 0.0), 225.0);
  EXPECT_DOUBLE_EQ(cam.value("fy", 0.0), 225.0);
  EXPECT_DOUBLE_EQ(cam.value("cx", 0.0), 79.5);
  EXPECT_DOUBLE_EQ(cam.value("cy", 0.0), 59.5);
  ASSERT_TRUE(cam.contains("distortion") && cam["distortion"].size() == 5u);
  ASSERT_TRUE(cam.contains("rvec") && cam["rvec"].size() == 3u);
  ASSERT_TRUE(cam.contains("tvec") && cam["tvec"].size() == 3u);
  // x_cam = R x_table + t, and the camera centre (0, 0, 1.2) maps to the origin: |t| = 1.2.
  const double tx = cam["tvec"][0], ty = cam["tvec"][1], tz = cam["tvec"][2];
  EXPECT_NEAR(std::sqrt(tx * tx + ty * ty + tz * tz), 1.2, 1e-9);
  EXPECT_NEAR(tz, 1.2, 1e-9);  // looking straight down at the origin
  EXPECT_DOUBLE_EQ(cam.value("fps", 0.0), 30.0);
  EXPECT_TRUE(meta.contains("effects"));
  EXPECT_TRUE(meta.contains("gl"));
  EXPECT_EQ(meta.value("frames", -1), 7);
}

// The throw and the catch (assets/scenes/throw-catch.yaml, at 160 x 120 px): the metadata reports
// the flight, and the frames' truth in it is the free disk's parabola in the tilted plane: x
// linear in t, y with the curvature -g sin 5 deg / 2 (the air drag bends it by well under 1 %).
TEST_F(CliRenderTest, TheThrowAndCatchSceneShowsTheFlight) {
  scene_with(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "throw-catch.yaml", "throw.yaml",
             {{"width: 640 ", "width: 160 "},
              {"height: 480 ", "height: 120 "},
              {"fx: 900 ", "fx: 225 "},
              {"fy: 900 ", "fy: 225 "},
              {"cx: 319.5 ", "cx: 79.5 "},
              {"cy: 239.5 ", "cy: 59.5 "},
              {"supersample: 2 ", "supersample: 1 "}});
  const Result r = run("render --scene throw.yaml --overlay --out frames --duration 2.5 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json meta = json::parse(read_text(dir_ / "frames" / "meta.json"));
  EXPECT_EQ(meta.value("model", ""), "hybrid");
  ASSERT_EQ(meta["contact"]["flights"].size(), 1u) << meta["contact"].dump(2);
  const json& f = meta["contact"]["flights"][0];
  const double t0 = f["t_lift_off"], t1 = f["t_landing"];
  ASSERT_LT(t0, t1);
  // The frames within the flight, and a least-squares quadratic through their centres.
  const auto rows = check_truth(dir_ / "frames" / "truth.csv", 76, 30.0, 225.0, 79.5, 59.5, 1.2);
  std::vector<std::vector<double>> flight;
  for (const auto& row : rows)
    if (row[1] > t0 + 1e-9 && row[1] < t1 - 1e-9) flight.push_back(row);
  ASSERT_GE(flight.size(), 8u);
  Eigen::MatrixXd A(flight.size(), 3);
  Eigen::VectorXd x(flight.size()), y(flight.size());
  for (std::size_t i = 0; i < flight.size(); ++i) {
    const double t = flight[i][1] - t0;
    A.row(static_cast<Eigen::Index>(i)) << 1.0, t, t * t;
    x[static_cast<Eigen::Index>(i)] = flight[i][5];
    y[static_cast<Eigen::Index>(i)] = flight[i][6];
  }
  const Eigen::Vector3d cx = A.colPivHouseholderQr().solve(x);
  const Eigen::Vector3d cy = A.colPivHouseholderQr().solve(y);
  const double g = 9.8 * std::sin(5.0 * M_PI / 180.0);
  EXPECT_NEAR(cy[2] / (-0.5 * g) - 1.0, 0.0, 0.01);
  EXPECT_NEAR(cx[2], 0.0, 0.01 * 0.5 * g);
}

TEST_F(CliRenderTest, TheDiskIsWhereTheTruthSaysIfFfmpegCanDecodeTheFrame) {
  if (!have_tool("ffmpeg")) GTEST_SKIP() << "ffmpeg not installed";
  const Result r =
      run("render --scene " + quote(small_scene().string()) + " --out frames --duration 0.1");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rows = check_truth(dir_ / "frames" / "truth.csv", 4, 30.0, 225.0, 79.5, 59.5, 1.2);
  ASSERT_FALSE(rows.empty());
  // Decode frame 0 to 8-bit grey: the disk (light) against the table (dark).
  const std::string cmd = "cd " + quote(dir_.string()) +
                          " && ffmpeg -v error -y -i frames/frame_000000.png -f rawvideo "
                          "-pix_fmt gray grey.raw";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const std::string grey = read_text(dir_ / "grey.raw");
  ASSERT_EQ(grey.size(), 160u * 120u);
  const auto at = [&](double u, double v) {
    return static_cast<int>(
        static_cast<unsigned char>(grey[static_cast<std::size_t>(std::lround(v)) * 160 +
                                        static_cast<std::size_t>(std::lround(u))]));
  };
  const int disk = at(rows[0][8], rows[0][9]);
  const int table = at(5, 115);  // bottom-left corner: bare table
  EXPECT_GT(disk, table + 40) << "disk " << disk << ", table " << table;
}

TEST_F(CliRenderTest, SideViewMovesTheCamera) {
  const Result r = run("render --scene " + quote(small_scene().string()) +
                       " --view side --out side --duration 0.1 --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  EXPECT_EQ(j.value("frames", -1), 4);
  EXPECT_EQ(j.value("view", ""), "side");
  json meta;
  ASSERT_NO_THROW(meta = json::parse(read_text(dir_ / "side" / "meta.json")));
  EXPECT_EQ(meta["camera"]["position"], json::parse("[0.0, -1.2, 0.4]"));
  EXPECT_DOUBLE_EQ(meta["camera"].value("fx", 0.0), 225.0);  // same intrinsics
  // The camera centre is at distance |t| from the table origin.
  const double tx = meta["camera"]["tvec"][0], ty = meta["camera"]["tvec"][1],
               tz = meta["camera"]["tvec"][2];
  EXPECT_NEAR(std::sqrt(tx * tx + ty * ty + tz * tz), std::sqrt(1.2 * 1.2 + 0.4 * 0.4), 1e-9);
}

TEST_F(CliRenderTest, RefusesToMixWithAnEarlierRender) {
  const std::string args =
      "render --scene " + quote(small_scene().string()) + " --out frames --duration 0.05";
  ASSERT_EQ(run(args).code, 0);
  const std::string truth = read_text(dir_ / "frames" / "truth.csv");
  const Result again = run(args);
  EXPECT_EQ(again.code, 2) << again.err;
  EXPECT_NE(again.err.find("--out"), std::string::npos) << again.err;
  EXPECT_EQ(read_text(dir_ / "frames" / "truth.csv"), truth);
}

TEST_F(CliRenderTest, RuntimeFailureRemovesEverything) {
  // No k in (-2, 2] solves a 0.3 s butterfly: the search fails after the output directory exists.
  const fs::path scene = camera_scene_with("fast.yaml", {{"period: 4.0 ", "period: 0.3 "}});
  const Result r = run("render --scene " + quote(scene.string()) + " --solve --out a/b/frames");
  EXPECT_EQ(r.code, 1) << r.err;
  const auto err = lines_of(r.err);
  ASSERT_FALSE(err.empty());
  EXPECT_EQ(err.back().rfind("flatland: error: ", 0), 0u) << r.err;
  EXPECT_TRUE(r.out.empty()) << r.out;
  EXPECT_FALSE(fs::exists(dir_ / "a")) << "left the output directories behind";
}

TEST_F(CliRenderTest, Mp4VideoHasEveryFrame) {
  const Result r = run("render --scene " + quote(small_scene().string()) +
                       " --out video/run.mp4 --duration 0.2 --overlay --json");
  if (r.code == 1 && r.err.find("MP4 writer") != std::string::npos)
    GTEST_SKIP() << "no MP4 encoder here: " << r.err;
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  EXPECT_EQ(j.value("frames", -1), 7);
  EXPECT_EQ(j.value("output", ""), "video/run.mp4");
  EXPECT_EQ(j.value("truth", ""), "video/run.truth.csv");
  EXPECT_TRUE(j.contains("codec") && (j["codec"] == "avc1" || j["codec"] == "mp4v")) << r.out;
  const fs::path d = dir_ / "video";
  ASSERT_TRUE(fs::exists(d / "run.mp4"));
  EXPECT_GT(fs::file_size(d / "run.mp4"), 0u);
  check_truth(d / "run.truth.csv", 7, 30.0, 225.0, 79.5, 59.5, 1.2);
  json meta;
  ASSERT_NO_THROW(meta = json::parse(read_text(d / "run.json")));
  EXPECT_EQ(meta.value("frames", -1), 7);
  EXPECT_EQ(temporaries_in(dir_), 0);

  if (!have_tool("ffprobe")) GTEST_SKIP() << "ffprobe not installed: frames not counted";
  const std::string cmd = "cd " + quote(dir_.string()) +
                          " && ffprobe -v error -count_frames -select_streams v:0 -show_entries "
                          "stream=width,height,nb_read_frames -of json video/run.mp4 > probe.json";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  json probe;
  ASSERT_NO_THROW(probe = json::parse(read_text(dir_ / "probe.json")));
  ASSERT_TRUE(probe.contains("streams") && probe["streams"].size() == 1u) << probe.dump();
  const json& s = probe["streams"][0];
  EXPECT_EQ(s.value("width", -1), 160);
  EXPECT_EQ(s.value("height", -1), 120);
  EXPECT_EQ(s.value("nb_read_frames", ""), "7");
}

// Each readout key's bad values: one line naming the field, exit 2, nothing written.
TEST_F(CliRenderTest, BadReadoutKeysAreRefused) {
  const std::string exposure = "exposure: 0.0           # s; instantaneous (no motion blur)";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"readout: fast", "camera.readout"},
      {"field_order: even_first", "camera.field_order"},
      {"readout_time: 0.01", "camera.readout_time"},
      {"readout_band_rows: 4", "camera.readout_band_rows"},
      {"readout: interlaced\n  field_order: top", "camera.field_order"},
      {"readout: rolling", "camera.readout_time"},
      {"readout: rolling\n  readout_time: 0", "camera.readout_time"},
      {"readout: rolling\n  readout_time: 0.05", "camera.readout_time"},
      {"readout: rolling\n  readout_time: .nan", "camera.readout_time"},
      {"readout: rolling\n  readout_time: 0.02\n  readout_band_rows: 0",
       "camera.readout_band_rows"},
      {"readout: rolling\n  readout_time: 0.02\n  readout_band_rows: 481",
       "camera.readout_band_rows"},
      {"readout: rolling\n  readout_time: 0.02\n  readout_band_rows: 2.5",
       "camera.readout_band_rows"},
      {"readout: interlaced\n  exposure: 0.02", "camera.exposure"},
  };
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const fs::path scene =
        camera_scene_with("bad" + std::to_string(i) + ".yaml",
                          {{exposure, cases[i].first.find("exposure") == std::string::npos
                                          ? "exposure: 0.0\n  " + cases[i].first
                                          : cases[i].first}});
    expect_bad_input("render --scene " + quote(scene.string()) + " --duration 0.1 --out out",
                     cases[i].second, "out");
  }
  // --fps that a readout cannot keep up with names the option.
  const fs::path rolling = camera_scene_with(
      "rolling.yaml", {{exposure, "exposure: 0.0\n  readout: rolling\n  readout_time: 0.03"}});
  expect_bad_input("render --scene " + quote(rolling.string()) + " --fps 60 --out out", "--fps",
                   "out");
  // A spatial scene's frames have no readout and no mask.
  expect_bad_input(
      "render --scene " +
          quote((fs::path(FLATLAND_ASSET_DIR) / "scenes" / "ball-in-bowl.yaml").string()) +
          " --mask --out out",
      "--mask", "out");
}

// --mask: a mask PNG beside each frame, one 8-bit id per body where the truth puts the bodies; a
// rolling readout adds t_state to the truth and the readout to the metadata. Without the options
// the outputs keep their columns (tests above) and the digests (scripts/output_digest.sh).
TEST_F(CliRenderTest, MaskBesideEachFrameWithItsIds) {
  const fs::path scene = camera_scene_with(
      "rolling.yaml", {{"exposure: 0.0           # s; instantaneous (no motion blur)",
                        "exposure: 0.0\n  readout: rolling\n  readout_time: 0.03"}});
  const Result r =
      run("render --scene " + quote(scene.string()) + " --duration 0.1 --mask --out frames --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const json j = parse_json(r);
  ASSERT_EQ(j.value("frames", -1), 4);
  EXPECT_EQ(j.value("masks", ""), "frames");
  const auto rows = lines_of(read_text(dir_ / "frames" / "truth.csv"));
  ASSERT_EQ(rows.size(), 5u);
  EXPECT_EQ(rows[0], std::string(kTruthHeader) + ",t_state");
  json meta;
  ASSERT_NO_THROW(meta = json::parse(read_text(dir_ / "frames" / "meta.json")));
  EXPECT_EQ(meta["readout"].value("mode", ""), "rolling");
  EXPECT_EQ(meta["mask"]["ids"].value("disk", -1), 3);
  for (int i = 0; i < 4; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "mask_%06d.png", i);
    const cv::Mat mask = cv::imread((dir_ / "frames" / name).string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(mask.type(), CV_8UC1) << name;
    ASSERT_EQ(mask.size(), cv::Size(640, 480));
    const std::vector<double> f = fields_of(rows[static_cast<std::size_t>(i) + 1]);
    const double u = f[8], v = f[9], t = f[1], t_state = f[15];
    // The disk's row is read v line times after the frame's first.
    EXPECT_NEAR(t_state - t, v * 0.03 / 480, 1e-9);
    // The disk's region: centred on the truth's image point (its area's centroid; the disk is
    // seen straight down, so its outline is a circle about that point), 0.051 m at 1.2 m under
    // fx = 900 px: radius 38.25 px, area pi r^2 to a pixel's width of its outline.
    cv::Mat disk = mask == 3;
    const cv::Moments m = cv::moments(disk, true);
    ASSERT_GT(m.m00, 0.0);
    EXPECT_NEAR(m.m10 / m.m00, u, 0.3) << name;
    EXPECT_NEAR(m.m01 / m.m00, v, 0.3) << name;
    const double radius = 0.051 * 900 / (1.2 - 0.006);
    EXPECT_NEAR(m.m00, M_PI * radius * radius, 2 * M_PI * radius) << name;
    // The table all around (the image's corners), the hand under the disk, nothing else.
    EXPECT_EQ(mask.at<unsigned char>(0, 0), 1);
    EXPECT_EQ(mask.at<unsigned char>(479, 639), 1);
    EXPECT_EQ(mask.at<unsigned char>(static_cast<int>(v + radius + 8), static_cast<int>(u)), 2)
        << name;
    double lo = 0, hi = 0;
    cv::minMaxLoc(mask, &lo, &hi);
    EXPECT_EQ(lo, 1.0);
    EXPECT_EQ(hi, 3.0);
  }
}

}  // namespace
