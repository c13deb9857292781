// Outputs of every `flatland` command that writes files: an existing output is refused (exit 2,
// one line naming the option and the path, the old output unchanged byte for byte) unless --force,
// which replaces it; an interrupted run (SIGINT, SIGTERM) leaves neither staging directories nor
// partial outputs nor the parent directories it created.
#include "cli_support.hpp"

#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <chrono>
#include <csignal>
#include <map>
#include <thread>

#include <spawn.h>

namespace {

using flatland_test::lines_of;
using flatland_test::quote;
using flatland_test::read_text;
using flatland_test::Result;
using flatland_test::write_text;
namespace fs = std::filesystem;

class CliForce : public flatland_test::CliTestBase {
 protected:
  /// Every regular file under `p` (or `p` itself) with its bytes.
  static std::map<std::string, std::string> snapshot(const fs::path& p) {
    std::map<std::string, std::string> m;
    if (fs::is_regular_file(p)) m[p.string()] = read_text(p);
    if (fs::is_directory(p))
      for (const auto& e : fs::recursive_directory_iterator(p))
        if (e.is_regular_file()) m[e.path().string()] = read_text(e.path());
    return m;
  }

  /// Staging leftovers anywhere in the test directory.
  int temporaries() const {
    int n = 0;
    for (const auto& e : fs::recursive_directory_iterator(dir_)) {
      const std::string name = e.path().filename().string();
      if (name.find(".tmp-") != std::string::npos || name.find(".partial-") != std::string::npos)
        ++n;
    }
    return n;
  }

  /// `out` (relative to the test directory) is a file (or, `directory`, a non-empty directory)
  /// holding an old output. `args` without --force is refused naming `option` and leaves it
  /// byte for byte; with --force it succeeds and replaces it (no old file survives in a
  /// directory output).
  void expect_refused_then_forced(const std::string& args, const std::string& out,
                                  const std::string& option, bool directory) {
    SCOPED_TRACE(args);
    const fs::path p = dir_ / out;
    if (directory) {
      fs::create_directories(p);
      write_text(p / "old-output.txt", "old\n");
    } else {
      if (p.has_parent_path()) fs::create_directories(p.parent_path());
      write_text(p, "old\n");
    }
    const auto before = snapshot(p);
    Result r = run(args);
    EXPECT_EQ(r.code, 2) << r.err;
    const auto err = lines_of(r.err);
    ASSERT_FALSE(err.empty());
    EXPECT_EQ(err.back().rfind("flatland: error: " + option + ": ", 0), 0u) << r.err;
    EXPECT_NE(err.back().find(out), std::string::npos) << r.err;
    EXPECT_NE(err.back().find("--force"), std::string::npos) << r.err;
    EXPECT_EQ(snapshot(p), before) << "the existing output was changed";
    EXPECT_EQ(temporaries(), 0);

    r = run(args + " --force");
    ASSERT_EQ(r.code, 0) << r.err;
    if (directory) {
      EXPECT_TRUE(fs::is_directory(p));
      EXPECT_FALSE(fs::exists(p / "old-output.txt")) << "the directory was not replaced";
      EXPECT_FALSE(fs::is_empty(p));
    } else {
      EXPECT_NE(read_text(p), "old\n") << "the file was not replaced";
    }
    EXPECT_EQ(temporaries(), 0);
  }

  fs::path small_camera_scene() const {
    std::string s = read_text(fs::path(FLATLAND_ASSET_DIR) / "scenes" / "butterfly-camera.yaml");
    for (const auto& [from, to] :
         std::vector<std::pair<std::string, std::string>>{{"width: 640 ", "width: 160 "},
                                                          {"height: 480 ", "height: 120 "},
                                                          {"fx: 900 ", "fx: 225 "},
                                                          {"fy: 900 ", "fy: 225 "},
                                                          {"cx: 319.5 ", "cx: 79.5 "},
                                                          {"cy: 239.5 ", "cy: 59.5 "}}) {
      const auto at = s.find(from);
      EXPECT_NE(at, std::string::npos) << from;
      if (at != std::string::npos) s.replace(at, from.size(), to);
    }
    const fs::path p = dir_ / "small.yaml";
    write_text(p, s);
    return p;
  }

  /// Start `flatland args` in the test directory without waiting; returns its pid.
  pid_t spawn(const std::string& args) const {
    const std::string cmd = "cd " + quote(dir_.string()) + " && exec " + quote(FLATLAND_CLI_PATH) +
                            " " + args + " > stdout.txt 2> stderr.txt";
    std::string a0 = "sh", a1 = "-c", a2 = cmd;
    char* argv[] = {a0.data(), a1.data(), a2.data(), nullptr};
    pid_t pid = 0;
    EXPECT_EQ(::posix_spawn(&pid, "/bin/sh", nullptr, nullptr, argv, environ), 0);
    return pid;
  }

  static int wait_exit(pid_t pid) {
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

  /// Wait (up to `seconds`) until `ready` holds; false on timeout.
  template <class F>
  static bool wait_for(F ready, double seconds) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (std::chrono::steady_clock::now() < end) {
      if (ready()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }

  /// Files of a staging directory for `out` (".out.tmp-<pid>" beside it).
  int staged_files(const fs::path& parent) const {
    int n = 0;
    std::error_code ec;
    if (!fs::exists(parent, ec)) return 0;
    for (const auto& e : fs::recursive_directory_iterator(parent, ec))
      if (e.is_regular_file() && e.path().string().find(".tmp-") != std::string::npos) ++n;
    return n;
  }
};

TEST_F(CliForce, HelpOfEveryWritingCommandHasForce) {
  for (const char* c : {"simulate", "solve", "locus", "surface", "time-optimal", "render", "track",
                        "calibrate", "experiment", "montecarlo", "study"}) {
    const Result r = run(std::string(c) + " --help");
    EXPECT_EQ(r.code, 0) << c;
    EXPECT_NE(r.out.find("--force"), std::string::npos) << c << " --help has no --force";
  }
}

TEST_F(CliForce, SimulateSolveLocusSurfaceTimeOptimal) {
  expect_refused_then_forced("simulate --out run.csv", "run.csv", "--out", false);
  expect_refused_then_forced("solve --out sol", "sol", "--out", true);  // with plots
  expect_refused_then_forced("locus --n 2 --no-plot --out loc", "loc", "--out", true);
  expect_refused_then_forced("surface --nk 2 --np 2 --no-plot --out surf", "surf", "--out", true);
  expect_refused_then_forced("time-optimal --no-plot --out fast", "fast", "--out", true);
  // An empty existing directory is not an existing output.
  fs::create_directories(dir_ / "empty");
  EXPECT_EQ(run("locus --n 2 --no-plot --out empty").code, 0);
  EXPECT_TRUE(fs::exists(dir_ / "empty" / "locus.csv"));
  // The wrong kind is refused even with --force: a directory where a file is written.
  fs::create_directories(dir_ / "adir");
  const Result r = run("simulate --out adir --force");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::is_directory(dir_ / "adir"));
}

TEST_F(CliForce, RenderVideoAndFrames) {
  const std::string scene = "--scene " + quote(small_camera_scene().string());
  expect_refused_then_forced("render " + scene + " --duration 0.1 --out frames", "frames", "--out",
                             true);
  expect_refused_then_forced("render " + scene + " --duration 0.1 --out run.mp4", "run.mp4",
                             "--out", false);
  // The truth CSV and the JSON beside the video are outputs too.
  fs::remove(dir_ / "run.mp4");
  const auto before = snapshot(dir_ / "run.truth.csv");
  const Result r = run("render " + scene + " --duration 0.1 --out run.mp4");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("run.truth.csv"), std::string::npos) << r.err;
  EXPECT_EQ(snapshot(dir_ / "run.truth.csv"), before);
  EXPECT_FALSE(fs::exists(dir_ / "run.mp4"));
}

TEST_F(CliForce, Track) {
  const std::string scene = "--scene " + quote(small_camera_scene().string());
  ASSERT_EQ(run("render " + scene + " --duration 0.2 --out frames").code, 0);
  const auto meta = nlohmann::json::parse(read_text(dir_ / "frames/meta.json"));
  const auto& cam = meta["camera"];
  std::ostringstream yaml;
  yaml.precision(17);
  yaml << "image_width: " << cam["width"] << "\nimage_height: " << cam["height"]
       << "\ncamera_name: test\ncamera_matrix: {rows: 3, cols: 3, data: [";
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) yaml << (i + j ? ", " : "") << cam["K"][i][j].get<double>();
  yaml << "]}\ndistortion_model: plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [";
  for (int i = 0; i < 5; ++i) yaml << (i ? ", " : "") << cam["distortion"][i].get<double>();
  yaml << "]}\nflatland:\n  fps: 30\n  table_rvec: [" << cam["rvec"][0].get<double>() << ", "
       << cam["rvec"][1].get<double>() << ", " << cam["rvec"][2].get<double>()
       << "]\n  table_tvec: [" << cam["tvec"][0].get<double>() << ", "
       << cam["tvec"][1].get<double>() << ", " << cam["tvec"][2].get<double>()
       << "]\n  joint_axis: [0, 0]\n  encoder_offset_rad: 0\n";
  write_text(dir_ / "camera.yaml", yaml.str());
  expect_refused_then_forced(
      "track --images 'frames/frame_*.png' --camera camera.yaml " + scene + " --out out/tracks.csv",
      "out/tracks.csv", "--out", false);
}

TEST_F(CliForce, Calibrate) {
  // The refusal comes before the images are read; with --force the run gets past it (and fails
  // later here, having no board images: the old file stays, nothing is staged).
  write_text(dir_ / "camera.yaml", "old\n");
  fs::create_directories(dir_ / "imgs");
  write_text(dir_ / "imgs" / "x.png", "not a png");
  Result r = run("calibrate --images 'imgs/*.png' --board chessboard:9x7:0.025 --out camera.yaml");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.err.rfind("flatland: error: --out: camera.yaml already exists", 0), 0u) << r.err;
  r =
      run("calibrate --images 'imgs/*.png' --board chessboard:9x7:0.025 --out camera.yaml "
          "--force");
  EXPECT_EQ(r.err.find("already exists"), std::string::npos) << r.err;
  EXPECT_EQ(read_text(dir_ / "camera.yaml"), "old\n");
  EXPECT_EQ(temporaries(), 0);
}

TEST_F(CliForce, ExperimentOutAndRecordAndMontecarlo) {
  expect_refused_then_forced("experiment --controller open-loop --no-plot --out run", "run",
                             "--out", true);
  expect_refused_then_forced("experiment --controller open-loop --no-plot --out run2 --record rec",
                             "rec", "--record", true);
  EXPECT_TRUE(fs::exists(dir_ / "rec" / "recording.json"));
  // Replacing the recording that is being replayed is refused even with --force.
  const Result r =
      run("experiment --controller open-loop --no-plot --camera video:rec --joint log:rec --out b "
          "--record rec --force");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--record"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::exists(dir_ / "rec" / "recording.json"));
  expect_refused_then_forced("montecarlo --n 1 --out mc", "mc", "--out", true);
}

TEST_F(CliForce, StudyRefusesAnExistingOutput) {
  fs::create_directories(dir_ / "st");
  write_text(dir_ / "st" / "sim.csv", "old\n");
  const Result r = run("study sim --no-plot --out st");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("--out: st"), std::string::npos) << r.err;
  EXPECT_EQ(read_text(dir_ / "st" / "sim.csv"), "old\n");
}

// SIGINT while frames are being written into the staging directory: exit 130, and neither the
// output, nor its staging directory, nor the parents the run created remain.
TEST_F(CliForce, InterruptedRenderLeavesNothing) {
  const std::string scene = "--scene " + quote(small_camera_scene().string());
  const pid_t pid = spawn("render " + scene + " --duration 30 --out a/b/frames");
  const bool staged = wait_for([&] { return staged_files(dir_ / "a" / "b") >= 2; }, 120);
  ASSERT_EQ(::kill(pid, SIGINT), 0);
  const int code = wait_exit(pid);
  EXPECT_TRUE(staged) << "no frame was staged before the timeout";
  EXPECT_EQ(code, 130) << read_text(dir_ / "stderr.txt");
  EXPECT_NE(read_text(dir_ / "stderr.txt").find("interrupted by SIGINT"), std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ / "a")) << "left a/ behind";
  EXPECT_EQ(temporaries(), 0);
}

// SIGTERM during a long surface with an existing output and --force: the old output survives
// byte for byte, no staging is left.
TEST_F(CliForce, InterruptedSurfaceKeepsTheOldOutput) {
  fs::create_directories(dir_ / "surf");
  write_text(dir_ / "surf" / "surface.csv", "old\n");
  const pid_t pid = spawn("surface --nk 200 --np 200 --threads 1 --no-plot --out surf --force");
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  ASSERT_EQ(::kill(pid, SIGTERM), 0);
  EXPECT_EQ(wait_exit(pid), 143) << read_text(dir_ / "stderr.txt");
  EXPECT_EQ(read_text(dir_ / "surf" / "surface.csv"), "old\n");
  EXPECT_EQ(temporaries(), 0);
}

// SIGINT while the recorder writes frames (inside the staging root of --record) and the video
// is being encoded: neither output nor any partial directory remains.
TEST_F(CliForce, InterruptedExperimentWithRecordingLeavesNothing) {
  const pid_t pid = spawn("experiment --controller open-loop --out run --record rec --video");
  const bool staged = wait_for(
      [&] {
        int n = 0;
        std::error_code ec;
        for (const auto& e : fs::recursive_directory_iterator(dir_, ec))
          if (e.path().string().find(".rec.tmp-") != std::string::npos && e.is_regular_file()) ++n;
        return n >= 3;
      },
      120);
  ASSERT_EQ(::kill(pid, SIGINT), 0);
  EXPECT_EQ(wait_exit(pid), 130) << read_text(dir_ / "stderr.txt");
  EXPECT_TRUE(staged);
  EXPECT_FALSE(fs::exists(dir_ / "run"));
  EXPECT_FALSE(fs::exists(dir_ / "rec"));
  EXPECT_EQ(temporaries(), 0);
}

}  // namespace
