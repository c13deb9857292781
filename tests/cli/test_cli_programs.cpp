// The CLI is two programs (apps/commands.hpp): `flatland` runs the simulator's commands and
// executes flatland-camera for the commands that need OpenCV, GL or Ceres. A user sees one
// program: every command is listed, runs and exits as before, and the simulator's commands do
// not load the camera stack.
#include "cli_support.hpp"

#include <array>
#include <string>

namespace {

using namespace flatland_test;

class CliPrograms : public CliTestBase {};

constexpr std::array<const char*, 5> kSimulatorCommands = {"simulate", "solve", "locus", "surface",
                                                           "time-optimal"};
constexpr std::array<const char*, 7> kCameraCommands = {
    "render", "render-calibration", "calibrate", "track", "experiment", "montecarlo", "study"};

TEST_F(CliPrograms, HelpListsEveryCommandOfBothPrograms) {
  const Result r = run("--help");
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* name : kSimulatorCommands)
    EXPECT_NE(r.out.find(std::string("\n  ") + name + " "), std::string::npos) << name;
  for (const char* name : kCameraCommands)
    EXPECT_NE(r.out.find(std::string("\n  ") + name + " "), std::string::npos) << name;
}

TEST_F(CliPrograms, TheFrontEndLinksNoCameraLibrary) {
  const std::string cmd =
      "ldd " + quote(FLATLAND_CLI_PATH) + " > " + quote((dir_ / "ldd").string());
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  const std::string libraries = read_text(dir_ / "ldd");
  ASSERT_NE(libraries.find("libc.so"), std::string::npos) << libraries;
  for (const char* heavy : {"opencv", "ceres", "gstreamer", "avcodec", "libGL", "OSMesa", "EGL"})
    EXPECT_EQ(libraries.find(heavy), std::string::npos) << heavy << " in\n" << libraries;
}

TEST_F(CliPrograms, CameraCommandsRunAndExitAsOneProgram) {
  for (const char* name : kCameraCommands) {
    const Result help = run(std::string(name) + " --help");
    EXPECT_EQ(help.code, 0) << name << ": " << help.err;
    EXPECT_NE(help.out.find(std::string("Usage: flatland ") + name), std::string::npos) << name;
  }
  // Bad input keeps its exit code and its one line through the hop.
  const Result bad = run("track --no-such-option");
  EXPECT_EQ(bad.code, 2);
  EXPECT_EQ(lines_of(bad.err).size(), 1u) << bad.err;
  EXPECT_NE(bad.err.find("flatland: error:"), std::string::npos) << bad.err;
}

TEST_F(CliPrograms, MissingCameraProgramIsOneLineAndExitOne) {
  // The front end alone, as a partial install would leave it.
  fs::create_directories(dir_ / "prefix" / "bin");
  const fs::path lone = dir_ / "prefix" / "bin" / "flatland";
  fs::copy_file(FLATLAND_CLI_PATH, lone);
  const std::string cmd = quote(lone.string()) + " render --help > " +
                          quote((dir_ / "out").string()) + " 2> " + quote((dir_ / "err").string());
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  const std::string err = read_text(dir_ / "err");
  EXPECT_EQ(lines_of(err).size(), 1u) << err;
  EXPECT_NE(err.find("flatland-camera"), std::string::npos) << err;
  EXPECT_NE(err.find((dir_ / "prefix" / "libexec" / "flatland").string()), std::string::npos)
      << err;
  // The simulator's commands still work.
  const std::string solve = quote(lone.string()) + " solve --help > /dev/null 2>&1";
  EXPECT_EQ(std::system(solve.c_str()), 0);
}

}  // namespace
