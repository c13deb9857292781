// Spatial scenes (`space: 3d`): the sections of a ball or an ellipsoid rolling on a surface hand
// in space (docs/SCENE.md, "Spatial scenes"). Internal to scene/.
#pragma once

#include "flatland/sim/spatial_spec.hpp"

#include <yaml-cpp/yaml.h>

#include <initializer_list>
#include <string>

namespace flatland::scene_detail {

/// Whether the document is a spatial scene: `space: 3d` (`2d`, or no `space`, is planar). A
/// SceneError for any other value.
bool is_spatial(const YAML::Node& document, const std::string& origin);

class MapReader;

/// The keys of a spatial scene's document: its own sections, and the camera, effects and render
/// sections it shares with planar scenes (for `flatland render`).
inline constexpr std::initializer_list<const char*> kSpatialSceneKeys = {
    "name",     "space",      "gravity", "hand",   "object",  "motion", "initial",
    "duration", "integrator", "contact", "camera", "effects", "render"};

/// The spatial scene's own sections, checked (key by key here, the physics by
/// sim::build_spatial). `name` receives the optional `name:`.
sim::SpatialSpec read_spatial_scene(const MapReader& root, std::string& name);

}  // namespace flatland::scene_detail
