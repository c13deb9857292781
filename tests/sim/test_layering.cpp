// The simulator's tests run with no camera stack in the process: `ctest -L sim` needs neither GL
// nor OpenCV nor Ceres (docs/DEVELOPING.md, "Test"). A link added to this program or to
// flatland::sim / flatland::scene that brings one in fails here.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>
#include <string>

TEST(Layering, SimulatorTestsMapNoCameraLibrary) {
  std::ifstream maps("/proc/self/maps");
  ASSERT_TRUE(maps.good());
  std::stringstream text;
  text << maps.rdbuf();
  const std::string mapped = text.str();
  ASSERT_NE(mapped.find("libc.so"), std::string::npos);  // the file lists shared libraries
  for (const char* heavy : {"libopencv", "libceres", "libGL", "libOSMesa", "libEGL", "libgst",
                            "libavcodec", "libyaml-cpp.so.0.6"})
    EXPECT_EQ(mapped.find(heavy), std::string::npos) << heavy << " is mapped";
}
