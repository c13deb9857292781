// The fuzzers' contracts (fuzz/*.cpp) in the normal build: every seed of the fuzz corpora
// (tests/fuzz/<target>/) and every input a fuzzer once crashed on
// (tests/fuzz/regressions/<target>/) either parses or is rejected with the one-line error of its
// reader; no other exception. And the fuzz targets themselves (fuzz/*.cpp, their entry points
// renamed by tests/CMakeLists.txt) over the same inputs: a target aborts on a broken contract.
#include "flatland/camera/camera_file.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

extern "C" int flatland_fuzz_scene(const std::uint8_t* data, std::size_t size);
extern "C" int flatland_fuzz_camera_file(const std::uint8_t* data, std::size_t size);

namespace {

namespace fs = std::filesystem;

std::vector<fs::path> inputs(const std::string& target) {
  std::vector<fs::path> files;
  for (const fs::path& dir :
       {fs::path(FLATLAND_FUZZ_DIR) / target, fs::path(FLATLAND_FUZZ_DIR) / "regressions" / target})
    if (fs::is_directory(dir))
      for (const auto& e : fs::directory_iterator(dir))
        if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

std::string bytes_of(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

/// Runs `parse` on every input of `target`; returns how many parsed.
template <typename Error>
int check_all(const std::string& target, const std::function<void(const std::string&)>& parse) {
  const std::vector<fs::path> files = inputs(target);
  EXPECT_FALSE(files.empty()) << "no inputs under " << FLATLAND_FUZZ_DIR << "/" << target;
  int parsed = 0;
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    try {
      parse(bytes_of(f));
      ++parsed;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      EXPECT_FALSE(what.empty());
    } catch (const std::exception& e) {
      ADD_FAILURE() << "unexpected exception type: " << e.what();
    }
  }
  return parsed;
}

}  // namespace

TEST(FuzzRegressions, SceneInputsParseOrThrowSceneError) {
  const int parsed = check_all<flatland::SceneError>(
      "scene", [](const std::string& s) { (void)flatland::parse_scene(s, "fuzz.yaml"); });
  EXPECT_GE(parsed, 4);  // the bundled scenes among the seeds
}

TEST(FuzzRegressions, CameraFileInputsParseOrThrowInvalidArgument) {
  const int parsed = check_all<std::invalid_argument>("camera_file", [](const std::string& s) {
    (void)flatland::camera::parse_camera_file(s, "fuzz.yaml");
  });
  EXPECT_GE(parsed, 2);  // the minimal ROS file and the full flatland one
}

TEST(FuzzTargets, EachTargetRunsOverItsSeedsAndReproducers) {
  const struct {
    const char* target;
    int (*entry)(const std::uint8_t*, std::size_t);
  } targets[] = {{"scene", flatland_fuzz_scene}, {"camera_file", flatland_fuzz_camera_file}};
  for (const auto& t : targets) {
    const std::vector<fs::path> files = inputs(t.target);
    EXPECT_FALSE(files.empty()) << t.target;
    for (const fs::path& f : files) {
      SCOPED_TRACE(f.string());
      const std::string bytes = bytes_of(f);
      EXPECT_EQ(t.entry(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()), 0);
    }
  }
}
