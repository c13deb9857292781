// The fitted world as a scene file (docs/IDENTIFY.md, "The fitted scene"): the scene identify
// started from, with the values it determined put in place and a comment block saying where they
// came from, ready for `experiment`, `montecarlo` and `render`.
#pragma once

#include "flatland/identify/identify.hpp"

#include <optional>
#include <string>
#include <vector>

namespace flatland::identify {

/// Where a parameter goes in a scene file: its section and key, and the factor from the
/// parameter's SI value to the key's unit (tilt: rad -> tilt_deg). Parameters that are not the
/// world's (angle_offset, time_offset: the joint's and the camera's) have none.
struct SceneKey {
  std::string section, key;
  double scale = 1.0;
};
std::optional<SceneKey> scene_key(const std::string& parameter);

/// What the comment block says of the fit's inputs.
struct FitProvenance {
  std::string scene_path;    ///< the scene the fit started from
  std::string command_line;  ///< as the user typed it (no dates: the file is reproducible)
  std::vector<std::string> recordings;  ///< one line each, e.g. "run1/ (412 samples)"
};

/// The scene text `scene_text` with every determined world parameter of `result` in place, each
/// replaced value's line commented "identified: VALUE +- SIGMA (was OLD)", `contact.model: hybrid`
/// (the model identify fits in), and a comment block at the top: the provenance, chi^2 against
/// its degrees of freedom, and every parameter with its sigma or why it was not determined (such a
/// parameter keeps the scene's value: the file claims no more than the data gave). Values are
/// edited in the text where they stand, so the scene's own comments survive; a layout the edit
/// cannot follow (a flow-style section) is written anew from the parsed document instead, without
/// the scene's comments. std::invalid_argument if `scene_text` is not a YAML mapping.
std::string fitted_scene(const std::string& scene_text, const IdentifyResult& result,
                         const FitProvenance& provenance);

}  // namespace flatland::identify
