// The compile step's pieces that stand alone: a scene's camera and its calibration boards, for a
// program that builds a camera without a whole scene (model::compile, model.hpp, uses them).
// Errors are std::invalid_argument "SECTION.FIELD: reason".
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/scene/scene.hpp"

namespace flatland::model {

/// The camera of a scene's `camera` section, checked by the camera's rules (camera_problem,
/// scene.hpp); its pose from position, look_at and up.
camera::CameraModel compile_camera(const CameraSpec& spec);

/// A scene's `targets` entry: its board (ArUco dictionary checked against OpenCV's) and where it
/// lies on the table.
camera::PlacedBoard compile_target(const TargetSpec& target);

}  // namespace flatland::model
