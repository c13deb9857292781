// The compile step: a parsed Scene's sections turned into the typed values the modules run on,
// validated once, here. The first part of flatland::model (the compiled Model): the
// camera and the calibration boards of a scene. Errors are std::invalid_argument
// "SECTION.FIELD: reason" (the CLI prefixes the scene's path).
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/scene/scene.hpp"

namespace flatland::model {

/// The camera of a scene's `camera` section: fx, fy > 0, a size of 1..16384 px, finite
/// distortion, fps > 0, exposure within a frame, the camera above the table and looking down at
/// it, `up` not along the view; its pose from position, look_at and up.
camera::CameraModel compile_camera(const CameraSpec& spec);

/// A scene's `targets` entry: its board (ArUco dictionary checked against OpenCV's) and where it
/// lies on the table.
camera::PlacedBoard compile_target(const TargetSpec& target);

}  // namespace flatland::model
