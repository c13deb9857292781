// libFuzzer target: the camera-file reader on arbitrary bytes. A camera file either parses or is
// rejected with std::invalid_argument (one line); any other exception (cv::Exception included),
// a crash or a sanitizer report is a bug.
#include "flatland/camera/camera_file.hpp"

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <stdexcept>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    (void)flatland::camera::parse_camera_file(text, "fuzz.yaml");
  } catch (const std::invalid_argument& e) {
    if (std::string(e.what()).find('\n') != std::string::npos) {
      std::fprintf(stderr, "camera file error spans lines: %s\n", e.what());
      std::abort();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "parse_camera_file threw something other than invalid_argument: %s\n",
                 e.what());
    std::abort();
  }
  return 0;
}
