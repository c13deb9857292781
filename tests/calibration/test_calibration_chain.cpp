// The real-camera workflow end to end on a rendered session: render-calibration films what a lab
// films, calibrate measures the intrinsics, the table pose and the joint from it, render films a
// run, and track maps that run to s_h through the calibrated camera file, with no hand-written
// file. The truth comes from the scene (camera::CameraModel::from_spec, the hand pivoting at the
// table origin with its encoder reading the true angle), never from the code under test.
#include "cli_support.hpp"
#include "flatland/model/compile.hpp"
#include "test_scale.hpp"
#include "units.hpp"

#include "flatland/calibration/session.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

using flatland_test::Result;
namespace fs = std::filesystem;
using namespace flatland;

namespace {

using flatland_test::kDeg;

std::string camera_scene() {
  return (fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly-camera.yaml").string();
}

// One column of a CSV with a header, by name.
std::vector<double> column(const fs::path& csv, const std::string& name) {
  const std::vector<std::string> lines = flatland_test::lines_of(flatland_test::read_text(csv));
  std::vector<double> out;
  if (lines.empty()) return out;
  std::size_t index = 0;
  {
    std::stringstream ss(lines[0]);
    std::string field;
    std::size_t i = 0;
    bool found = false;
    while (std::getline(ss, field, ',')) {
      if (field == name) {
        index = i;
        found = true;
      }
      ++i;
    }
    if (!found) ADD_FAILURE() << csv << " has no column " << name;
  }
  for (std::size_t r = 1; r < lines.size(); ++r) {
    std::stringstream ss(lines[r]);
    std::string field;
    for (std::size_t i = 0; i <= index; ++i) std::getline(ss, field, ',');
    out.push_back(field.empty() ? std::nan("") : std::stod(field));
  }
  return out;
}

double rotation_angle(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a * b.t();
  return std::acos(std::clamp((cv::trace(d) - 1) / 2, -1.0, 1.0));
}

bool one_line_ending_in_newline(const std::string& s) {
  return !s.empty() && s.find('\n') == s.size() - 1;
}

class CalibrationChain : public flatland_test::CliTestBase {
 protected:
  // A session of the camera scene in DIR/sess.
  void render_session() {
    const Result r = run("render-calibration --scene " + flatland_test::quote(camera_scene()) +
                         " --out sess --json");
    ASSERT_EQ(r.code, 0) << r.err;
    board_ = nlohmann::json::parse(r.out).at("board").get<std::string>();
  }
  std::string board_;
};

}  // namespace

TEST_F(CalibrationChain, RenderedSessionCalibratesAndTracksToTheTrueSh) {
  render_session();
  const Result c = run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                       " --table sess/table.csv --joint sess/joint.csv --scene " +
                       flatland_test::quote(camera_scene()) + " --out camera.yaml --json");
  ASSERT_EQ(c.code, 0) << c.err;
  const nlohmann::json j = nlohmann::json::parse(c.out);
  EXPECT_EQ(j.at("sections"), nlohmann::json::array({"intrinsics", "table", "joint"}));

  // Against the scene's camera, computed by the renderer's camera model from the scene file.
  const Scene scene = load_scene(camera_scene());
  const camera::CameraModel truth = flatland::model::compile_camera(*scene.camera);
  const camera::CameraFile cal = camera::read_camera_file((dir_ / "camera.yaml").string());
  ASSERT_TRUE(cal.has_table_pose);
  ASSERT_TRUE(cal.joint.has_value());
  ASSERT_TRUE(cal.table_report.has_value());
  ASSERT_TRUE(cal.joint_report.has_value());
  EXPECT_NEAR(cal.camera.K(0, 0), truth.K(0, 0), 0.005 * truth.K(0, 0));
  EXPECT_NEAR(cal.camera.K(0, 2), truth.K(0, 2), 3.0);
  EXPECT_LT(rotation_angle(cal.camera.R, truth.R), 0.1 * kDeg);
  EXPECT_LT(cv::norm(cal.camera.position_in_table() - truth.position_in_table()), 2e-3);
  EXPECT_LT(std::hypot(cal.joint->axis_table.x, cal.joint->axis_table.y), 0.5e-3);
  EXPECT_LT(std::abs(cal.joint->encoder_offset), 0.1 * kDeg);
  EXPECT_EQ(cal.joint_report->inliers, 8);
  EXPECT_TRUE(cal.unsupported.empty());
  // Every figure within 3 of its reported sigma of the truth (the table pose's sigma and the
  // joint's carry the intrinsics' and the table pose's uncertainty).
  const double fx_sigma = j.at("std").at("fx").get<double>();
  const nlohmann::json& table = j.at("table");
  const nlohmann::json& joint = j.at("joint");
  const cv::Vec3d c_true = truth.position_in_table(), centre = cal.camera.position_in_table();
  std::printf(
      "within sigma: fx %.2f, camera centre (%.2f, %.2f, %.2f), axis (%.2f, %.2f), "
      "offset %.2f\n",
      (cal.camera.K(0, 0) - truth.K(0, 0)) / fx_sigma,
      (centre[0] - c_true[0]) / table.at("sigma_camera_in_table")[0].get<double>(),
      (centre[1] - c_true[1]) / table.at("sigma_camera_in_table")[1].get<double>(),
      (centre[2] - c_true[2]) / table.at("sigma_camera_in_table")[2].get<double>(),
      cal.joint->axis_table.x / joint.at("sigma_axis_m").get<double>(),
      cal.joint->axis_table.y / joint.at("sigma_axis_m").get<double>(),
      cal.joint->encoder_offset / joint.at("sigma_offset_rad").get<double>());
  EXPECT_LT(std::abs(cal.camera.K(0, 0) - truth.K(0, 0)), 3 * fx_sigma);
  for (int k = 0; k < 3; ++k)
    EXPECT_LT(std::abs(centre[k] - c_true[k]),
              3 * table.at("sigma_camera_in_table")[static_cast<std::size_t>(k)].get<double>());
  EXPECT_LT(std::abs(cal.joint->axis_table.x), 3 * joint.at("sigma_axis_m").get<double>());
  EXPECT_LT(std::abs(cal.joint->axis_table.y), 3 * joint.at("sigma_axis_m").get<double>());
  EXPECT_LT(std::abs(cal.joint->encoder_offset), 3 * joint.at("sigma_offset_rad").get<double>());
  EXPECT_EQ(joint.at("unsupported"), nullptr);
  EXPECT_EQ(table.at("unsupported"), nullptr);

  // A run filmed by render, tracked through the calibrated file and render's encoder log.
  const Result r =
      run("render --scene " + flatland_test::quote(camera_scene()) + " --duration 1 --out frames");
  ASSERT_EQ(r.code, 0) << r.err;
  ASSERT_TRUE(fs::exists(dir_ / "frames" / "camera.yaml"));
  ASSERT_TRUE(fs::exists(dir_ / "frames" / "encoder.csv"));
  const Result t =
      run("track --images 'frames/*.png' --camera camera.yaml --encoder "
          "frames/encoder.csv --scene " +
          flatland_test::quote(camera_scene()) + " --out track.csv");
  ASSERT_EQ(t.code, 0) << t.err;
  const std::vector<double> s = column(dir_ / "track.csv", "s_h");
  const std::vector<double> s_true = column(dir_ / "frames" / "truth.csv", "s_h");
  ASSERT_EQ(s.size(), 31u);
  ASSERT_EQ(s_true.size(), s.size());
  double worst = 0;
  for (std::size_t i = 0; i < s.size(); ++i) worst = std::max(worst, std::abs(s[i] - s_true[i]));
  std::printf("calibrated chain: max |s_h - truth| = %.2e over %zu frames\n", worst, s.size());
  EXPECT_LT(worst, 0.005);

  // render's own camera file is the scene's camera: pose, axis at the origin, offset 0.
  const camera::CameraFile rendered =
      camera::read_camera_file((dir_ / "frames" / "camera.yaml").string());
  ASSERT_TRUE(rendered.has_table_pose);
  ASSERT_TRUE(rendered.joint.has_value());
  EXPECT_LT(rotation_angle(rendered.camera.R, truth.R), 1e-12);
  EXPECT_LT(cv::norm(rendered.camera.t - truth.t), 1e-12);
  EXPECT_EQ(rendered.camera.K, truth.K);
  EXPECT_EQ(rendered.joint->encoder_offset, 0.0);
  // The encoder log is the hand's angle: the truth's theta at the frame times.
  const std::vector<double> enc_t = column(dir_ / "frames" / "encoder.csv", "t");
  const std::vector<double> enc = column(dir_ / "frames" / "encoder.csv", "theta");
  const std::vector<double> theta = column(dir_ / "frames" / "truth.csv", "theta");
  ASSERT_EQ(enc_t.size(), 1001u);
  for (std::size_t i = 0; i < theta.size(); ++i) EXPECT_NEAR(enc[i * 1000 / 30], theta[i], 1e-3);
}

TEST_F(CalibrationChain, CameraFileGrowsOneSectionAtATime) {
  render_session();
  const std::string scene = " --scene " + flatland_test::quote(camera_scene());
  Result r =
      run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ + " --out camera.yaml");
  ASSERT_EQ(r.code, 0) << r.err;
  camera::CameraFile f = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_FALSE(f.has_table_pose);
  EXPECT_FALSE(f.joint.has_value());
  const cv::Matx33d K = f.camera.K;

  // The joint needs the table pose first.
  r = run("calibrate --camera camera.yaml --joint sess/joint.csv" + scene);
  EXPECT_EQ(r.code, 2);
  EXPECT_TRUE(one_line_ending_in_newline(r.err)) << r.err;
  EXPECT_NE(r.err.find("--joint: needs the table pose"), std::string::npos) << r.err;

  r = run("calibrate --camera camera.yaml --table sess/table.csv --table-board " + board_);
  ASSERT_EQ(r.code, 0) << r.err;
  f = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_TRUE(f.has_table_pose);
  EXPECT_EQ(f.camera.K, K);  // the intrinsics are kept as they were
  ASSERT_TRUE(f.report.has_value());

  // --out naming the --camera file another way is the same update in place (no --force).
  r = run("calibrate --camera camera.yaml --joint sess/joint.csv --out ./camera.yaml" + scene);
  ASSERT_EQ(r.code, 0) << r.err;
  f = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_TRUE(f.has_table_pose);
  ASSERT_TRUE(f.joint.has_value());
  EXPECT_LT(std::hypot(f.joint->axis_table.x, f.joint->axis_table.y), 0.5e-3);

  // New intrinsics make the old table pose and joint stale: they are dropped, with a warning.
  r = run("calibrate --camera camera.yaml --images 'sess/intrinsics/*.png' --board " + board_);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.err.find("are dropped"), std::string::npos) << r.err;
  f = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_FALSE(f.has_table_pose);
  EXPECT_FALSE(f.joint.has_value());
}

TEST_F(CalibrationChain, BadSessionInputExitsTwoWithOneLine) {
  render_session();
  const std::string table = "sess/table.csv";
  const auto expect_refused = [&](const std::string& args, const std::string& needle) {
    const Result r = run("calibrate " + args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    EXPECT_TRUE(one_line_ending_in_newline(r.err)) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.yaml")) << args;
  };
  expect_refused("--out out.yaml", "nothing to calibrate");
  expect_refused("--table " + table + " --board " + board_ + " --out out.yaml",
                 "--table: needs the camera's intrinsics");
  expect_refused("--images 'sess/intrinsics/*.png' --out out.yaml", "--board: required");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_, "--out: required");

  flatland_test::write_text(dir_ / "sess" / "bad1.csv", "image,x,y\ntable/board_00.png,0,0\n");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_ +
                     " --table sess/bad1.csv --out out.yaml",
                 "sess/bad1.csv:1: missing column 'yaw'");
  flatland_test::write_text(dir_ / "sess" / "bad2.csv",
                            "image,x,y,yaw,tilt\ntable/board_00.png,0,0,0,0\n");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_ +
                     " --table sess/bad2.csv --out out.yaml",
                 "unknown column 'tilt'");
  flatland_test::write_text(dir_ / "sess" / "bad3.csv", "image,encoder\njoint/hand_00.png,zero\n");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_ + " --table " + table +
                     " --joint sess/bad3.csv --out out.yaml",
                 "sess/bad3.csv:2: encoder: expected a finite number, got 'zero'");
  flatland_test::write_text(dir_ / "sess" / "bad4.csv", "image,encoder\nnowhere.png,0\n");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_ + " --table " + table +
                     " --joint sess/bad4.csv --out out.yaml",
                 "nowhere.png");
  expect_refused(
      "--images 'sess/intrinsics/*.png' --board " + board_ + " --table /dev/zero --out out.yaml",
      "/dev/zero: larger than 1 MiB");
  // A table image of another size than the camera's.
  fs::copy_file(dir_ / "sess" / "intrinsics" / "view_00.png", dir_ / "sess" / "small.png");
  const cv::Mat small(240, 320, CV_8UC3, cv::Scalar::all(60));
  ASSERT_TRUE(cv::imwrite((dir_ / "sess" / "small.png").string(), small));
  flatland_test::write_text(dir_ / "sess" / "bad5.csv", "image,x,y,yaw\nsmall.png,0,0,0\n");
  expect_refused("--images 'sess/intrinsics/*.png' --board " + board_ +
                     " --table sess/bad5.csv --out out.yaml",
                 "is 320 x 240 px but the camera is 640 x 480 px");

  const Result r = run("render-calibration --scene " + flatland_test::quote(camera_scene()) +
                       " --out s2 --table-views 0");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--table-views: must be in [1, 50], got 0"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(dir_ / "s2"));
  const Result sym = run("render-calibration --scene " + flatland_test::quote(camera_scene()) +
                         " --out s3 --board chessboard:8x6:0.02");
  EXPECT_EQ(sym.code, 2);
  EXPECT_TRUE(one_line_ending_in_newline(sym.err)) << sym.err;
  EXPECT_NE(sym.err.find("add to an odd number"), std::string::npos) << sym.err;
  EXPECT_FALSE(fs::exists(dir_ / "s3"));
}

TEST_F(CalibrationChain, HeldParametersAndReportPictures) {
  render_session();
  const Result r = run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                       " --fix k3,tangential --report rep --out camera.yaml --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("fixed"), nlohmann::json::array({"k3", "tangential"}));
  EXPECT_EQ(j.at("dist")[2].get<double>(), 0.0);
  EXPECT_EQ(j.at("dist")[3].get<double>(), 0.0);
  EXPECT_EQ(j.at("dist")[4].get<double>(), 0.0);
  EXPECT_EQ(j.at("std").at("k3").get<double>(), 0.0);
  const auto& pictures = j.at("report").at("views");
  ASSERT_EQ(pictures.size(), 16u);
  for (const auto& p : pictures) {
    const cv::Mat drawn = cv::imread((dir_ / p.get<std::string>()).string());
    ASSERT_EQ(drawn.size(), cv::Size(640, 480)) << p;
  }
  // The pictures are drawn over the views: not the views themselves.
  const cv::Mat first = cv::imread((dir_ / "sess/intrinsics/view_00.png").string());
  const cv::Mat drawn = cv::imread((dir_ / pictures[0].get<std::string>()).string());
  EXPECT_GT(cv::norm(first, drawn, cv::NORM_L1), 1000.0);
  EXPECT_TRUE(fs::exists(dir_ / "rep" / "coverage.png"));
  const double coverage = j.at("report").at("coverage_fraction").get<double>();
  EXPECT_GT(coverage, 0.25);
  EXPECT_LE(coverage, 1.0);

  // Bad input: one line, exit 2, nothing written.
  Result bad = run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                   " --fix k4 --out other.yaml");
  EXPECT_EQ(bad.code, 2);
  EXPECT_TRUE(one_line_ending_in_newline(bad.err)) << bad.err;
  EXPECT_NE(bad.err.find("--fix: unknown parameter 'k4'"), std::string::npos) << bad.err;
  bad = run("calibrate --camera camera.yaml --table sess/table.csv --report rep2 --out other.yaml");
  EXPECT_EQ(bad.code, 2);
  EXPECT_NE(bad.err.find("--report: pictures the intrinsics; needs --images"), std::string::npos)
      << bad.err;
  EXPECT_FALSE(fs::exists(dir_ / "other.yaml"));
  EXPECT_FALSE(fs::exists(dir_ / "rep2"));
}

TEST_F(CalibrationChain, RationalModelCalibratesAndTracks) {
  render_session();
  const std::string scene = flatland_test::quote(camera_scene());
  const Result c = run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                       " --rational --table sess/table.csv --joint sess/joint.csv --scene " +
                       scene + " --out camera.yaml --json");
  ASSERT_EQ(c.code, 0) << c.err;
  const nlohmann::json j = nlohmann::json::parse(c.out);
  EXPECT_EQ(j.at("model"), "rational_polynomial");
  EXPECT_EQ(j.at("dist").size(), 8u);
  EXPECT_TRUE(j.at("std").contains("k6"));
  const camera::CameraFile cal = camera::read_camera_file((dir_ / "camera.yaml").string());
  EXPECT_TRUE(cal.rational_model);
  // Through the rational file, track still maps the run to the true s_h.
  ASSERT_EQ(run("render --scene " + scene + " --duration 0.5 --out frames").code, 0);
  const Result t =
      run("track --images 'frames/*.png' --camera camera.yaml --encoder "
          "frames/encoder.csv --scene " +
          scene + " --out track.csv");
  ASSERT_EQ(t.code, 0) << t.err;
  const std::vector<double> s = column(dir_ / "track.csv", "s_h");
  const std::vector<double> s_true = column(dir_ / "frames" / "truth.csv", "s_h");
  ASSERT_EQ(s.size(), s_true.size());
  for (std::size_t i = 0; i < s.size(); ++i) EXPECT_NEAR(s[i], s_true[i], 0.005) << "frame " << i;
}

TEST(CalibrationSessionCsv, PathsResolveAgainstTheCsvAndZIsOptional) {
  const fs::path dir = fs::temp_directory_path() / ("flatland_csv_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  flatland_test::write_text(dir / "t.csv", "yaw,image,y,x\n0.5, a/b.png ,-0.25,0.125\n\n# note\n");
  const std::vector<calibration::TablePlacement> t =
      calibration::read_table_csv((dir / "t.csv").string());
  ASSERT_EQ(t.size(), 1u);
  EXPECT_EQ(t[0].image, (dir / "a" / "b.png").string());
  EXPECT_EQ(t[0].x, 0.125);
  EXPECT_EQ(t[0].y, -0.25);
  EXPECT_EQ(t[0].z, 0.0);
  EXPECT_EQ(t[0].yaw, 0.5);
  // Written and read back: the same placements.
  calibration::TablePlacement p{"x.png", 0.1, 0.2, 0.001, 3.0};
  flatland_test::write_text(dir / "u.csv", calibration::table_csv({p}));
  const auto u = calibration::read_table_csv((dir / "u.csv").string());
  ASSERT_EQ(u.size(), 1u);
  EXPECT_EQ(u[0].z, 0.001);
  EXPECT_EQ(u[0].yaw, 3.0);
  flatland_test::write_text(dir / "e.csv", "image,encoder\n");
  EXPECT_THROW(calibration::read_joint_csv((dir / "e.csv").string()), std::invalid_argument);
  fs::remove_all(dir);
}

namespace {

#if defined(__SANITIZE_ADDRESS__)
// AddressSanitizer holds freed memory back (a 256 MB quarantine, to catch use after free) and
// adds its shadow: a peak RSS then says little about what the program keeps. The probe runs the
// child without the quarantine and checks the growth only; the Release stage checks both bounds.
constexpr bool kAddressSanitizer = true;
#else
constexpr bool kAddressSanitizer = false;
#endif

// Runs `flatland args` in `dir` and returns its peak resident set size (kB) from wait4's rusage:
// flatland replaces itself with flatland-camera (execv), so the child is that process.
long peak_rss_kb(const fs::path& dir, const std::string& args, int& code) {
  const std::string env =
      kAddressSanitizer ? "ASAN_OPTIONS=\"${ASAN_OPTIONS:+$ASAN_OPTIONS:}quarantine_size_mb=0\" " : "";
  const std::string cmd = "cd " + flatland_test::quote(dir.string()) + " && " + env + "exec " +
                          flatland_test::quote(FLATLAND_CLI_PATH) + " " + args +
                          " > /dev/null 2> stderr.txt";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  int status = 0;
  rusage usage{};
  if (pid < 0 || ::wait4(pid, &status, 0, &usage) != pid) return -1;
  code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return usage.ru_maxrss;
}

// A CSV listing the session's rows again and again, `rows` rows in all.
void repeat_rows(const fs::path& from, const fs::path& to, std::size_t rows) {
  const std::vector<std::string> lines = flatland_test::lines_of(flatland_test::read_text(from));
  std::string text = lines.at(0) + "\n";
  for (std::size_t i = 0; i < rows; ++i) text += lines.at(1 + i % (lines.size() - 1)) + "\n";
  flatland_test::write_text(to, text);
}

}  // namespace

TEST_F(CalibrationChain, TableAndJointStreamTheirImages) {
  render_session();
  ASSERT_EQ(run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                " --table sess/table.csv --out camera.yaml")
                .code,
            0);
  // Each 640 x 480 image held would cost 0.9 MB: 380 more rows would add 350 MB. The sanitizer
  // stage streams 100 (80 more would add 72 MB) and 64 joint rows (48 more: 43 MB).
  const bool short_run = flatland::test::short_tests();
  const int table_rows = short_run ? 100 : 400, joint_rows = short_run ? 64 : 200;
  repeat_rows(dir_ / "sess" / "table.csv", dir_ / "sess" / "t20.csv", 20);
  repeat_rows(dir_ / "sess" / "table.csv", dir_ / "sess" / "t400.csv", table_rows);
  int code = -1;
  const long small = peak_rss_kb(dir_,
                                 "calibrate --camera camera.yaml --table sess/t20.csv "
                                 "--table-board " +
                                     board_ + " --out t20.yaml",
                                 code);
  ASSERT_EQ(code, 0) << flatland_test::read_text(dir_ / "stderr.txt");
  const long large = peak_rss_kb(dir_,
                                 "calibrate --camera camera.yaml --table sess/t400.csv "
                                 "--table-board " +
                                     board_ + " --out t400.yaml",
                                 code);
  ASSERT_EQ(code, 0) << flatland_test::read_text(dir_ / "stderr.txt");
  std::printf("calibrate --table peak RSS: %ld kB at 20 rows, %ld kB at %d rows\n", small, large,
              table_rows);
  EXPECT_LT(large - small, 20 * 1024);
  if (!kAddressSanitizer) {
    EXPECT_LT(large, 300 * 1024);
  }

  const std::string scene = " --scene " + flatland_test::quote(camera_scene());
  repeat_rows(dir_ / "sess" / "joint.csv", dir_ / "sess" / "j16.csv", 16);
  repeat_rows(dir_ / "sess" / "joint.csv", dir_ / "sess" / "j200.csv", joint_rows);
  const long joint_small = peak_rss_kb(
      dir_, "calibrate --camera camera.yaml --joint sess/j16.csv --out j16.yaml" + scene, code);
  ASSERT_EQ(code, 0) << flatland_test::read_text(dir_ / "stderr.txt");
  const long joint_large = peak_rss_kb(
      dir_, "calibrate --camera camera.yaml --joint sess/j200.csv --out j200.yaml" + scene, code);
  ASSERT_EQ(code, 0) << flatland_test::read_text(dir_ / "stderr.txt");
  std::printf("calibrate --joint peak RSS: %ld kB at 16 rows, %ld kB at %d rows\n", joint_small,
              joint_large, joint_rows);
  EXPECT_LT(joint_large - joint_small, 20 * 1024);
}

TEST_F(CalibrationChain, JointRefusesDegenerateOrInconsistentData) {
  render_session();
  ASSERT_EQ(run("calibrate --images 'sess/intrinsics/*.png' --board " + board_ +
                " --table sess/table.csv --out camera.yaml")
                .code,
            0);
  const std::vector<std::string> lines =
      flatland_test::lines_of(flatland_test::read_text(dir_ / "sess" / "joint.csv"));
  ASSERT_EQ(lines.size(), 9u);
  std::vector<std::string> image, encoder;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const auto comma = lines[i].find(',');
    image.push_back(lines[i].substr(0, comma));
    encoder.push_back(lines[i].substr(comma + 1));
  }
  std::string same = "image,encoder\n", shuffled = "image,encoder\n", two = "image,encoder\n";
  for (std::size_t i = 0; i < 8; ++i) same += image[3] + "," + encoder[3] + "\n";
  const std::size_t order[8] = {3, 7, 0, 5, 1, 6, 2, 4};  // no reading left in its place
  for (std::size_t i = 0; i < 8; ++i) shuffled += image[i] + "," + encoder[order[i]] + "\n";
  for (std::size_t i : {0, 4}) two += image[i] + "," + encoder[i] + "\n";
  flatland_test::write_text(dir_ / "sess" / "same.csv", same);
  flatland_test::write_text(dir_ / "sess" / "shuffled.csv", shuffled);
  flatland_test::write_text(dir_ / "sess" / "two.csv", two);

  const std::string scene = " --scene " + flatland_test::quote(camera_scene());
  const std::string before = flatland_test::read_text(dir_ / "camera.yaml");
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"same", "1 distinct encoder reading"},
      {"shuffled", "do not follow the encoder readings: chi-square"},
      {"two", "only 2 images"}};
  for (const auto& [name, needle] : cases) {
    // Refused: exit 1, one line naming the problem, nothing written (neither --out nor in place).
    Result r = run("calibrate --camera camera.yaml --joint sess/" + name + ".csv --out " + name +
                   ".yaml" + scene);
    EXPECT_EQ(r.code, 1) << name << ": " << r.err;
    EXPECT_TRUE(one_line_ending_in_newline(r.err)) << r.err;
    EXPECT_NE(r.err.find(needle), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / (name + ".yaml")));
    r = run("calibrate --camera camera.yaml --joint sess/" + name + ".csv" + scene);
    EXPECT_EQ(r.code, 1) << r.err;
    EXPECT_EQ(flatland_test::read_text(dir_ / "camera.yaml"), before);
    // --force writes it, marked: the reader returns the mark and track reports it.
    r = run("calibrate --camera camera.yaml --joint sess/" + name + ".csv --out " + name +
            ".yaml --force --json" + scene);
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("marked unsupported"), std::string::npos) << r.err;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    ASSERT_EQ(j.at("unsupported").size(), 1u);
    const camera::CameraFile forced = camera::read_camera_file((dir_ / (name + ".yaml")).string());
    ASSERT_EQ(forced.unsupported.size(), 1u);
    EXPECT_EQ(forced.unsupported[0].rfind("joint: ", 0), 0u) << forced.unsupported[0];
    EXPECT_NE(forced.unsupported[0].find(needle), std::string::npos);
  }
  // A new joint fit on good data drops the old mark.
  const Result again =
      run("calibrate --camera shuffled.yaml --joint sess/joint.csv --out good.yaml" + scene);
  ASSERT_EQ(again.code, 0) << again.err;
  EXPECT_TRUE(camera::read_camera_file((dir_ / "good.yaml").string()).unsupported.empty());
  // track reports a marked file.
  ASSERT_EQ(
      run("render --scene " + flatland_test::quote(camera_scene()) + " --duration 0.1 --out frames")
          .code,
      0);
  const Result t =
      run("track --images 'frames/*.png' --camera shuffled.yaml --encoder "
          "frames/encoder.csv --out track.csv" +
          scene);
  EXPECT_NE(t.err.find("unsupported"), std::string::npos) << t.err;

  // A table row that puts its board 1 cm from where it lay: refused the same way.
  std::vector<std::string> table =
      flatland_test::lines_of(flatland_test::read_text(dir_ / "sess" / "table.csv"));
  const std::vector<std::string> header = [&] {
    std::vector<std::string> h;
    std::stringstream ss(table[0]);
    for (std::string f; std::getline(ss, f, ',');) h.push_back(f);
    return h;
  }();
  const std::size_t x_column =
      static_cast<std::size_t>(std::find(header.begin(), header.end(), "x") - header.begin());
  std::vector<std::string> fields;
  {
    std::stringstream ss(table[2]);
    for (std::string f; std::getline(ss, f, ',');) fields.push_back(f);
  }
  fields.at(x_column) = std::to_string(std::stod(fields.at(x_column)) + 0.01);
  std::string moved;
  for (std::size_t i = 0; i < table.size(); ++i) {
    std::string line = table[i];
    if (i == 2) {
      line.clear();
      for (std::size_t k = 0; k < fields.size(); ++k) line += (k ? "," : "") + fields[k];
    }
    moved += line + "\n";
  }
  flatland_test::write_text(dir_ / "sess" / "moved.csv", moved);
  const Result m = run("calibrate --camera camera.yaml --table sess/moved.csv --table-board " +
                       board_ + " --out moved.yaml");
  EXPECT_EQ(m.code, 1) << m.err;
  EXPECT_TRUE(one_line_ending_in_newline(m.err)) << m.err;
  EXPECT_NE(m.err.find("do not agree on one table pose"), std::string::npos) << m.err;
  EXPECT_NE(m.err.find("board_01.png is farthest"), std::string::npos) << m.err;
  EXPECT_FALSE(fs::exists(dir_ / "moved.yaml"));
}
