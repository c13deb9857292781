// The minimum a scene must say, for the loader's tests of one section appended to it.
#pragma once

#include "flatland/scene/scene.hpp"

#include <string>

namespace flatland_test {

// The minimum a scene must say.
inline const std::string kMinimal = R"(gravity:
  g: 9.8
hand:
  shape: polynomial
  a: 0.18
  b: -0.18
  c: -0.252
  d: 0.216
object:
  type: disk
  radius: 0.051
motion:
  type: butterfly
  period: 1.181
  k: -1.1393
)";

/// The loader's error for kMinimal with `section` appended ("t.yaml"); "NO ERROR" if it loads.
inline std::string error_with_section(const std::string& section) {
  try {
    flatland::parse_scene(kMinimal + section, "t.yaml");
  } catch (const flatland::SceneError& e) {
    return e.what();
  }
  return "NO ERROR";
}

}  // namespace flatland_test
