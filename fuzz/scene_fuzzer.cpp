// libFuzzer target: the scene parser on arbitrary bytes. A scene either parses or is rejected
// with a SceneError (one line); any other exception, a crash or a sanitizer report is a bug.
#include "flatland/scene/scene.hpp"

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    (void)flatland::parse_scene(text, "fuzz.yaml");
  } catch (const flatland::SceneError& e) {
    // The CLI prints what() as its one error line.
    if (std::string(e.what()).find('\n') != std::string::npos) {
      std::fprintf(stderr, "SceneError message spans lines: %s\n", e.what());
      std::abort();
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "parse_scene threw something other than SceneError: %s\n", e.what());
    std::abort();
  }
  return 0;
}
