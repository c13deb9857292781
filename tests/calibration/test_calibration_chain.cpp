// The real-camera workflow end to end on a rendered session: render-calibration films what a lab
// films, calibrate measures the intrinsics, the table pose and the joint from it, render films a
// run, and track maps that run to s_h through the calibrated camera file, with no hand-written
// file. The truth comes from the scene (camera::CameraModel::from_spec, the hand pivoting at the table
// origin with its encoder reading the true angle), never from the code under test.
#include "flatland/model/compile.hpp"
#include "cli_support.hpp"

#include "flatland/camera/camera_file.hpp"
#include "flatland/calibration/session.hpp"
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

using flatland_test::Result;
namespace fs = std::filesystem;
using namespace flatland;

namespace {

constexpr double kDeg = std::numbers::pi / 180;

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

bool one_line(const std::string& s) { return !s.empty() && s.find('\n') == s.size() - 1; }

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
  const camera::CameraFile cal =
      camera::read_camera_file((dir_ / "camera.yaml").string());
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
  EXPECT_TRUE(one_line(r.err)) << r.err;
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
    EXPECT_TRUE(one_line(r.err)) << r.err;
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
  EXPECT_TRUE(one_line(sym.err)) << sym.err;
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
  EXPECT_TRUE(one_line(bad.err)) << bad.err;
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
  const camera::CameraFile cal =
      camera::read_camera_file((dir_ / "camera.yaml").string());
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
