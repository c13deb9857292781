// End-to-end tests of the hand shapes besides the paper's polynomial (`hand.shape: line`, an
// incline, and `circle`, a circular well) through the `flatland` program: simulate against the
// closed forms of a uniform disk rolling on them, render (the plate where the geometry puts it),
// track (pixel -> s_h on a line), and the commands that need a palm and a back refusing them.
#include "cli_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <filesystem>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_columns;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;

class CliHandShapes : public flatland_test::CliTestBase {
 protected:
  /// A planar scene without a camera: `hand` and `motion` as YAML blocks.
  fs::path scene(const std::string& name, double tilt_deg, const std::string& hand,
                 const std::string& motion, const std::string& initial, double duration) const {
    std::ostringstream s;
    s << "name: " << name << "\n"
      << "gravity: {g: 9.8, tilt_deg: " << tilt_deg << "}\n"
      << "hand: " << hand << "\n"
      << "object: {type: disk, radius: 0.051}\n"
      << "motion: " << motion << "\n"
      << "initial: " << initial << "\n"
      << "duration: " << duration << "\n";
    const fs::path p = dir_ / (name + ".yaml");
    write_text(p, s.str());
    return p;
  }

  /// The bundled camera scene (640 x 480, fx = 900 px, 1.2 m over the pivot, 5 deg tilt) with its
  /// hand, motion and initial state replaced.
  fs::path camera_scene(const std::string& name, const std::string& hand,
                        const std::string& initial) const {
    std::string text = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly-camera.yaml");
    const auto replace_section = [&](const std::string& key, const std::string& with) {
      const auto begin = text.find("\n" + key + ":\n");
      EXPECT_NE(begin, std::string::npos) << "the bundled scene has no section " << key;
      if (begin == std::string::npos) return;
      auto end = text.find("\n\n", begin + 1);
      text.replace(begin + 1, end - begin - 1, key + ": " + with);
    };
    replace_section("hand", hand);
    replace_section("motion", "{type: fixed, angle_deg: 0}");
    replace_section("initial", initial);
    const auto duration = text.find("\nduration: 4.0");
    EXPECT_NE(duration, std::string::npos);
    if (duration != std::string::npos) text.replace(duration + 1, 13, "duration: 1.0");
    const fs::path p = dir_ / (name + ".yaml");
    write_text(p, text);
    return p;
  }

  std::map<std::string, std::vector<double>> simulate(const fs::path& scene_file) const {
    const Result r = run("simulate --scene " + quote(scene_file.string()) +
                         " --out run.csv --sample-dt 0.001 --force");
    EXPECT_EQ(r.code, 0) << r.err;
    return read_columns(dir_ / "run.csv");
  }

  /// Bad input: exit 2, one line naming `field`, nothing on stdout, `out` (if any) not written.
  void expect_refused(const std::string& args, const std::string& field,
                      const std::string& out = "") const {
    SCOPED_TRACE(args);
    const Result r = run(args);
    EXPECT_EQ(r.code, 2) << "stderr: " << r.err;
    const auto err = lines_of(r.err);
    ASSERT_EQ(err.size(), 1u) << r.err;
    EXPECT_EQ(err[0].rfind("flatland: error: ", 0), 0u) << err[0];
    EXPECT_NE(err[0].find(field), std::string::npos) << err[0];
    EXPECT_TRUE(r.out.empty()) << r.out;
    if (!out.empty()) {
      EXPECT_FALSE(fs::exists(dir_ / out));
    }
  }
};

// Times at which s crosses zero going down, by linear interpolation between samples.
std::vector<double> downward_zero_crossings(const std::vector<double>& t,
                                            const std::vector<double>& s) {
  std::vector<double> out;
  for (std::size_t i = 1; i < t.size(); ++i)
    if (s[i - 1] > 0 && s[i] <= 0)
      out.push_back(t[i - 1] + s[i - 1] / (s[i - 1] - s[i]) * (t[i] - t[i - 1]));
  return out;
}

// A uniform disk (J = m r^2 / 2) rolling inside a circle of radius R: its centre moves on the
// circle of radius R - r, and energy gives (R - r)(1 + J/(m r^2)) phi'' = -g sin(phi), a pendulum
// of length L = 3 (R - r) / 2, phi = s_h (the contact lies on the ray through the centre). Its
// period is 2 pi sqrt(L / g) for small amplitudes and 4 sqrt(L / g) K(sin(A / 2)) exactly.
TEST_F(CliHandShapes, ADiskInACircularWellSwingsWithThePendulumsPeriod) {
  const double R = 0.2, r = 0.051, tilt_deg = 30, amplitude = 0.01;
  const double g = 9.8 * std::sin(tilt_deg * std::numbers::pi / 180);
  const double length = 1.5 * (R - r);
  // 2 pi sqrt(3 (R - r) / (2 g))
  const double small = 2 * std::numbers::pi * std::sqrt(length / g);
  const double exact = 4 * std::sqrt(length / g) * std::comp_ellint_1(std::sin(amplitude / 2));
  const auto c = simulate(scene("well", tilt_deg, "{shape: circle, radius: 0.2}",
                                "{type: fixed, angle_deg: 0}", "{s_h: 0.01, sdot_h: 0}", 6.0));
  const std::vector<double> down = downward_zero_crossings(c.at("t"), c.at("s_h"));
  ASSERT_GE(down.size(), 4u);
  const double period = (down.back() - down.front()) / static_cast<double>(down.size() - 1);
  // The small-amplitude form leaves out the amplitude's own term, A^2/16 = 6.25e-6 of the
  // period; 1e-5 covers it. The exact (elliptic) period leaves only the integrator's error
  // (rtol 1e-10) and the crossings' interpolation between 1 ms samples, where s_h is nearly
  // straight (its second derivative is 0 at s_h = 0): 1e-7.
  EXPECT_NEAR(period / small, 1.0, 1e-5) << period << " s against " << small << " s";
  EXPECT_NEAR(period / exact, 1.0, 1e-7) << period << " s against " << exact << " s";
  // The amplitude stays A after the first swings: the rolling model is lossless.
  double peak = 0;
  for (std::size_t i = 0; i < c.at("t").size(); ++i)
    if (c.at("t")[i] > 4.0) peak = std::max(peak, std::abs(c.at("s_h")[i]));
  EXPECT_NEAR(peak, amplitude, 1e-6);
}

// On a line at angle alpha (the hand held still), a uniform disk's centre accelerates down the
// slope at (2/3) g_eff sin(alpha): s_h (metres along the line) is a parabola with that second
// derivative, negative (the line rises towards +s_h). The same incline made by the hand's angle
// instead of the line's gives the same motion.
TEST_F(CliHandShapes, ADiskOnAnInclineAcceleratesAtTwoThirdsGSinAlpha) {
  const double tilt_deg = 30, alpha = 12 * std::numbers::pi / 180;
  const double g = 9.8 * std::sin(tilt_deg * std::numbers::pi / 180);
  const double expected = -2.0 / 3.0 * g * std::sin(alpha);
  for (const auto& [hand, motion] :
       {std::pair<std::string, std::string>{"{shape: line, angle_deg: 12}",
                                            "{type: fixed, angle_deg: 0}"},
        {"{shape: line, angle_deg: 7, origin: [0, 0]}", "{type: fixed, angle_deg: 5}"}}) {
    SCOPED_TRACE(hand + " " + motion);
    const auto c =
        simulate(scene("incline", tilt_deg, hand, motion, "{s_h: 0.1, sdot_h: 0.3}", 1.0));
    const std::vector<double>& t = c.at("t");
    const std::vector<double>& s = c.at("s_h");
    ASSERT_GT(t.size(), 100u);
    // Least squares s = s0 + v0 t + a t^2 / 2.
    Eigen::MatrixXd A(t.size(), 3);
    Eigen::VectorXd b(t.size());
    for (std::size_t i = 0; i < t.size(); ++i) {
      A.row(static_cast<Eigen::Index>(i)) << 1.0, t[i], 0.5 * t[i] * t[i];
      b(static_cast<Eigen::Index>(i)) = s[i];
    }
    const Eigen::Vector3d fit = A.colPivHouseholderQr().solve(b);
    // A constant acceleration is integrated exactly (dopri5 is exact on quadratics): the fit's
    // error is the CSV's 17 significant digits and the solve's rounding.
    EXPECT_NEAR(fit(2) / expected, 1.0, 1e-9) << fit(2) << " m/s^2 against " << expected;
    EXPECT_NEAR(fit(1), 0.3, 1e-9);
    EXPECT_NEAR(fit(0), 0.1, 1e-9);
  }
}

TEST_F(CliHandShapes, TheSearchesAndTheClosedLoopRefuseAHandWithoutPalmAndBack) {
  const fs::path line = scene("line", 90, "{shape: line, angle_deg: 5}",
                              "{type: butterfly, period: 1.181, k: -1.1393}", "{s_h: 0}", 1.181);
  const fs::path well = scene("well", 90, "{shape: circle, radius: 0.2}",
                              "{type: butterfly, period: 1.181, k: -1.1393}", "{s_h: 0}", 1.181);
  for (const fs::path& p : {line, well}) {
    const std::string s = " --scene " + quote(p.string());
    expect_refused("solve" + s + " --json", "hand.shape");
    expect_refused("solve" + s + " --out solved", "hand.shape", "solved");
    expect_refused("locus" + s + " --json", "hand.shape");
    expect_refused("surface" + s + " --json --nk 2 --np 2", "hand.shape");
    expect_refused("time-optimal" + s + " --json", "hand.shape");
  }
  // The closed loop plans from the palm to the back.
  const fs::path camera = camera_scene("loop", "{shape: line, angle_deg: 10}", "{s_h: 0}");
  std::string text = read_text(camera);
  text.replace(text.find("motion: {type: fixed, angle_deg: 0}"), 35,
               "motion: {type: butterfly, period: 4.0, k: -1.1393}");
  text.replace(text.find("\ncontact:\n"), 10,
               "\ncontact:\n  mu: 0.5\n");  // the loop's world slides
  write_text(camera, text);
  expect_refused("experiment --scene " + quote(camera.string()) + " --out exp", "hand.shape",
                 "exp");
  expect_refused("montecarlo --scene " + quote(camera.string()) + " --n 2 --out mc", "hand.shape",
                 "mc");
  expect_refused("render --scene " + quote(camera.string()) + " --solve --out frames", "hand.shape",
                 "frames");
  // And simulate takes them.
  EXPECT_EQ(run("simulate --scene " + quote(line.string()) + " --json").code, 0);
  EXPECT_EQ(run("simulate --scene " + quote(well.string()) + " --json").code, 0);
}

TEST_F(CliHandShapes, BadHandKeysAreOneLineNamingTheField) {
  const std::string fixed = "{type: fixed}", rest = "{s_h: 0}";
  const auto refused = [&](const std::string& hand, const std::string& field) {
    const fs::path p = scene("bad", 90, hand, fixed, rest, 1.0);
    expect_refused("simulate --scene " + quote(p.string()) + " --out bad.csv", field, "bad.csv");
  };
  refused("{shape: circle, radius: 0.05}", "hand.radius");  // the disk (0.051 m) does not fit
  refused("{shape: circle, radius: 0.051}", "hand.radius");
  refused("{shape: circle, radius: -0.3}", "hand.radius");
  refused("{shape: circle}", "hand.radius");
  refused("{shape: circle, radius: 0.2, angle_deg: 3}", "hand.angle_deg");
  refused("{shape: circle, radius: 0.2, center: [0, 0, 0]}", "hand.center");
  refused("{shape: line, radius: 0.2}", "hand.radius");
  refused("{shape: line, a: 0.18}", "hand.a");
  refused("{shape: line, angle_deg: .nan}", "hand.angle_deg");
  refused("{shape: line, origin: [0]}", "hand.origin");
  refused("{shape: polynomial, a: 0.18, b: -0.18, c: -0.252, d: 0.216, origin: [0, 0]}",
          "hand.origin");
  refused("{shape: spiral}", "hand.shape");
}

// The plate is drawn where the geometry puts it. The camera looks straight down from 1.2 m over
// the pivot (fx = fy = 900 px, principal point (319.5, 239.5), image v down = table y up), so a
// point (x, y) of the plate's top face (z = 0.012 m) is at u = 319.5 + 900 x / 1.188,
// v = 239.5 - 900 y / 1.188. Pixels well inside the plate are bright aluminium, pixels of the
// table well away from it and from the disk are dark.
class CliHandShapesRender : public CliHandShapes {
 protected:
  static cv::Point2d pixel(double x, double y) {
    const double depth = 1.2 - 0.012;
    return {319.5 + 900 * x / depth, 239.5 - 900 * y / depth};
  }
  /// The mean grey level of a 5 x 5 px patch about `at`.
  static double grey(const cv::Mat& bgr, cv::Point2d at) {
    cv::Mat g;
    cv::cvtColor(bgr(cv::Rect(static_cast<int>(at.x) - 2, static_cast<int>(at.y) - 2, 5, 5)), g,
                 cv::COLOR_BGR2GRAY);
    return cv::mean(g)[0];
  }
  /// The disk's centre in frame `i` (truth.csv) and whether `p` is clear of it by 10 px.
  static bool clear_of_disk(const std::map<std::string, std::vector<double>>& truth, std::size_t i,
                            cv::Point2d p) {
    const double du = p.x - truth.at("disk_u")[i], dv = p.y - truth.at("disk_v")[i];
    return std::hypot(du, dv) > 0.051 * 900 / 1.194 + 10;
  }
};

TEST_F(CliHandShapesRender, ALinesPlateLiesBelowTheLine) {
  // y = tan(10 deg) x - 0.05: the body below it.
  const fs::path p =
      camera_scene("line", "{shape: line, angle_deg: 10, origin: [0.0, -0.05]}", "{s_h: 0.1}");
  const Result r = run("render --scene " + quote(p.string()) + " --out frames --duration 0.2");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto truth = read_columns(dir_ / "frames" / "truth.csv");
  ASSERT_EQ(truth.at("t").size(), 7u);
  const double slope = std::tan(10 * std::numbers::pi / 180);
  for (std::size_t i = 0; i < truth.at("t").size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06zu.png", i);
    const cv::Mat img = cv::imread((dir_ / "frames" / name).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << name;
    int checked = 0;
    for (double x = -0.3; x <= 0.3; x += 0.05) {
      const double y_line = slope * x - 0.05;
      // 15 mm (11 px) either side of the edge: the plate's wall and anti-aliasing are within it.
      const cv::Point2d below = pixel(x, y_line - 0.015), above = pixel(x, y_line + 0.015);
      EXPECT_GT(grey(img, below), 120) << name << " x = " << x << " below the line";
      if (clear_of_disk(truth, i, above)) {
        EXPECT_LT(grey(img, above), 90) << name << " x = " << x << " above the line";
        ++checked;
      }
    }
    EXPECT_GE(checked, 10);
  }
}

TEST_F(CliHandShapesRender, ACircularWellIsARingAroundTheDisk) {
  const double R = 0.2, cy = 0.05;
  const fs::path p =
      camera_scene("well", "{shape: circle, radius: 0.2, center: [0.0, 0.05]}", "{s_h: 0.3}");
  const Result r = run("render --scene " + quote(p.string()) + " --out frames --duration 0.2");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto truth = read_columns(dir_ / "frames" / "truth.csv");
  for (std::size_t i = 0; i < truth.at("t").size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%06zu.png", i);
    const cv::Mat img = cv::imread((dir_ / "frames" / name).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << name;
    for (int k = 0; k < 24; ++k) {
      const double a = 2 * std::numbers::pi * k / 24;
      // The ring: R to 1.25 R (the middle, 1.125 R, 11 px from either edge).
      const cv::Point2d ring = pixel(1.125 * R * std::cos(a), cy + 1.125 * R * std::sin(a));
      if (ring.y > 3 && ring.y < 476) {
        EXPECT_GT(grey(img, ring), 120) << name << " angle " << a;
      }
      // Inside the well and outside the ring: the table, unless the disk is there.
      const cv::Point2d inside = pixel(0.5 * R * std::cos(a), cy + 0.5 * R * std::sin(a));
      if (clear_of_disk(truth, i, inside)) {
        EXPECT_LT(grey(img, inside), 90) << name;
      }
      const cv::Point2d outside = pixel(1.4 * R * std::cos(a), cy + 1.4 * R * std::sin(a));
      if (outside.x > 3 && outside.x < 636 && outside.y > 3 && outside.y < 476) {
        EXPECT_LT(grey(img, outside), 90) << name << " angle " << a;
      }
    }
  }
}

// The tracker's mapping on an open hand: s_h on a line is the disk centre's coordinate along it,
// so a centre error maps one to one into s_h. The tracker's accepted centre error is 0.1 px
// (docs/VISION.md), 0.1 x 1.194 m / 900 px = 0.13 mm on the disk's top face: the tolerance.
TEST_F(CliHandShapesRender, TrackMapsALineHandsFrames) {
  // Moving from the start (1.3 px a frame): a frame identical to the one before is `repeated`,
  // not a measurement.
  const fs::path p = camera_scene("line", "{shape: line, angle_deg: 10, origin: [0.0, -0.05]}",
                                  "{s_h: 0.1, sdot_h: -0.05}");
  ASSERT_EQ(run("render --scene " + quote(p.string()) + " --out frames --duration 0.5").code, 0);
  const Result r = run("track --camera frames/camera.yaml --encoder frames/encoder.csv --scene " +
                       quote(p.string()) + " --images 'frames/frame_*.png' --out track.csv");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto tracked = read_columns(dir_ / "track.csv");
  const auto truth = read_columns(dir_ / "frames" / "truth.csv");
  ASSERT_EQ(tracked.at("s_h").size(), truth.at("s_h").size());
  const double tolerance = 0.1 * 1.194 / 900;
  for (std::size_t i = 0; i < truth.at("s_h").size(); ++i) {
    ASSERT_TRUE(std::isfinite(tracked.at("s_h")[i])) << "frame " << i << " not mapped";
    EXPECT_NEAR(tracked.at("s_h")[i], truth.at("s_h")[i], tolerance) << "frame " << i;
  }
  // The disk rolled down the slope: the mapping followed it over more than a centimetre.
  EXPECT_LT(truth.at("s_h").back(), truth.at("s_h").front() - 0.01);
}

// The paper's hand given as points (issue 26's acceptance, through the CLI): the right half
// sampled at 200 points, from the palm's middle over the tip to the back's middle, in a CSV
// relative to the scene file. `solve` finds the k of the polynomial for 2T = 1.181 s within 1e-5.
TEST_F(CliHandShapes, ThePapersHandAsPointsSolvesToThePolynomialsK) {
  const double a = 0.18, b = -0.18, c = -0.252, d = 0.216, e = -(a + c), f = -(b + 3 * d) / 5;
  fs::create_directories(dir_ / "hands");
  std::ostringstream csv;
  csv << "x,y\n";
  csv.precision(17);
  for (int i = 0; i < 200; ++i) {
    const double u = -1.0 + 2.0 * i / 199;
    const double u2 = u * u;
    csv << a + c * u2 + e * u2 * u2 << ',' << b * u + d * u2 * u + f * u2 * u2 * u << "\n";
  }
  write_text(dir_ / "hands" / "paper.csv", csv.str());
  const std::string motion = "{type: butterfly, period: 1.181, k: -1.1393}";
  const fs::path points = dir_ / "hands" / "points.yaml";
  write_text(points,
             "gravity: {g: 9.8}\nhand: {shape: points, file: paper.csv}\n"
             "object: {type: disk, radius: 0.051}\nmotion: " +
                 motion + "\n");
  const fs::path paper = dir_ / "paper.yaml";
  write_text(paper,
             "gravity: {g: 9.8}\nhand: {shape: polynomial, a: 0.18, b: -0.18, c: -0.252, "
             "d: 0.216}\nobject: {type: disk, radius: 0.051}\nmotion: " +
                 motion + "\n");
  const Result rp = run("solve --scene " + quote(points.string()) + " --json");
  const Result rq = run("solve --scene " + quote(paper.string()) + " --json");
  ASSERT_EQ(rp.code, 0) << rp.err;
  ASSERT_EQ(rq.code, 0) << rq.err;
  const double k_points = nlohmann::json::parse(rp.out).at("k").get<double>();
  const double k_paper = nlohmann::json::parse(rq.out).at("k").get<double>();
  EXPECT_NEAR(k_points, k_paper, 1e-5);
  // A bad row of the file is one line naming the file and its line.
  write_text(dir_ / "hands" / "paper.csv", csv.str() + "0.1,abc\n");
  expect_refused("simulate --scene " + quote(points.string()) + " --out x.csv", "paper.csv:202",
                 "x.csv");
}

TEST_F(CliHandShapesRender, APointsHandIsDrawnWhereItsOutlineIs) {
  // The paper's right half as 60 points (cm): drawn, the plate covers (0.1, 0) and not (0.3, 0)
  // or (0, 0.2) at theta = 0 (the butterfly starts there).
  const double a = 0.18, b = -0.18, c = -0.252, d = 0.216, e = -(a + c), f = -(b + 3 * d) / 5;
  std::ostringstream csv;
  csv.precision(17);
  for (int i = 0; i < 60; ++i) {
    const double u = -1.0 + 2.0 * i / 59, u2 = u * u;
    csv << 100 * (a + c * u2 + e * u2 * u2) << ',' << 100 * (b * u + d * u2 * u + f * u2 * u2 * u)
        << "\n";
  }
  write_text(dir_ / "hand.csv", csv.str());
  const fs::path p =
      camera_scene("points", "{shape: points, file: hand.csv, units: cm}", "{s_h: -1, sdot_h: 0}");
  std::string text = read_text(p);
  text.replace(text.find("motion: {type: fixed, angle_deg: 0}"), 35,
               "motion: {type: butterfly, period: 4.0, k: -1.1393}");
  write_text(p, text);
  const Result r = run("render --scene " + quote(p.string()) + " --out frames --duration 0.1");
  ASSERT_EQ(r.code, 0) << r.err;
  const cv::Mat img = cv::imread((dir_ / "frames" / "frame_000000.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_GT(grey(img, pixel(0.1, 0.0)), 120);
  EXPECT_LT(grey(img, pixel(0.3, 0.0)), 90);
  EXPECT_LT(grey(img, pixel(0.0, 0.2)), 90);
}

// A polar frame r = a - b cos 2 phi (the butterfly frame) with its dips as palm and back:
// simulate rolls the disk from the palm (s_h = -1) and stays in contact for a short while.
TEST_F(CliHandShapes, APolarFrameSimulates) {
  const fs::path p = scene("polar", 90, "{shape: polar, cos: [0.2, 0, -0.05], palm_phi_deg: 0}",
                           "{type: fixed, angle_deg: 0}", "{s_h: -0.95}", 0.2);
  const Result r = run("simulate --scene " + quote(p.string()) + " --json");
  EXPECT_EQ(r.code, 0) << r.err;
  expect_refused(
      "simulate --scene " + quote(scene("bad", 90, "{shape: polar, cos: [0.2], phi_deg: [0, 10]}",
                                        "{type: fixed}", "{s_h: -1}", 0.2)
                                      .string()),
      "hand.");
}

}  // namespace
