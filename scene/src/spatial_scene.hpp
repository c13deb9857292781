// Spatial scenes (`space: 3d`): the sections of a ball or an ellipsoid rolling on a surface hand
// in space (docs/SCENE.md, "Spatial scenes"). Internal to scene/.
#pragma once

#include "flatland/sim/spatial_spec.hpp"

#include <yaml-cpp/yaml.h>

#include <string>

namespace flatland::scene_detail {

/// Whether the document is a spatial scene: `space: 3d` (`2d`, or no `space`, is planar). A
/// SceneError for any other value.
bool is_spatial(const YAML::Node& document, const std::string& origin);

/// The spatial scene's sections, checked (key by key here, the physics by sim::build_spatial).
/// `name` receives the optional `name:`.
sim::SpatialSpec read_spatial_scene(const YAML::Node& document, const std::string& origin,
                                    std::string& name);

}  // namespace flatland::scene_detail
