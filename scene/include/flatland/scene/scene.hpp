// Scene files: one YAML description of an experiment, loaded once, immutable afterwards.
// SI units throughout (m, s, kg, rad); keys ending in _deg are degrees. Sections a scene does not
// contain are simply off. Schema: docs/SCENE.md.
#pragma once

#include "flatland/sim/spec.hpp"

#include <stdexcept>
#include <string>

namespace flatland {

/// Bad scene input. what() is one line: "<origin>: <field>: <reason>".
class SceneError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct Scene {
  std::string origin;  ///< file path (or "<string>")
  std::string name;    ///< optional `name:` key
  sim::SimulationSpec sim;
};

/// Parse and validate a scene (strict: unknown keys, wrong types, NaN/inf, missing required keys,
/// physically invalid values such as negative radius, k = -2 or an unusable hand shape are errors).
Scene parse_scene(const std::string& yaml_text, const std::string& origin = "<string>");
/// Read a file and parse it; an unreadable file is a SceneError too.
Scene load_scene(const std::string& path);
/// The bundled default scene (the paper's butterfly): assets/scenes/butterfly.yaml.
std::string default_scene_path();

}  // namespace flatland
