// Pieces shared by the image studies (study render, study tracker): both film the scene with its
// camera, so they default to the bundled camera scene rather than the paper's butterfly.
#pragma once

#include "study.hpp"

#include <string>
#include <vector>

namespace flatland::app {

/// assets/scenes/butterfly-camera.yaml, next to the default (paper) scene.
std::string default_camera_scene();

/// The scene of `--scene` (default: default_camera_scene()); a UsageError naming `study` when it
/// has no camera section or its camera is invalid.
Scene load_camera_scene(const StudyOptions& o, const std::string& study);

/// gnuplot: y tics at 1, 2, 5 of every decade from 1e-4 to 1e4 (a log axis spanning less than a
/// decade would otherwise show one label or none).
extern const std::string kLogTics;

/// The camera as JSON (size, intrinsics, distortion, pose summary).
Json camera_summary(const CameraSpec& spec);

}  // namespace flatland::app
