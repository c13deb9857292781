// A scene as the renderer sees it: compiled, and the part a Renderer takes.
#pragma once

#include "flatland/model/model.hpp"
#include "flatland/render/renderer.hpp"
#include "scene_support.hpp"

namespace flatland_test {

inline flatland::render::RenderSetup render_setup(const flatland::Scene& scene) {
  return flatland::model::render_setup(*flatland::model::compile(scene));
}

/// The paper's butterfly hand and disk (radius 0.051 m) under a 640 x 480 camera (f = 900 px)
/// straight down from 1 m over (0.05, 0.08): the disk's face is fronto-parallel. `k1`: radial
/// distortion.
inline flatland::Scene overhead_scene(int supersample, double k1 = 0.0) {
  flatland::Scene s;
  flatland::CameraSpec cam = overhead_camera({0.05, 0.08, 1.0});
  cam.distortion = {k1, 0, 0, 0, 0};
  s.camera = cam;
  s.effects.supersample = supersample;
  return s;
}

}  // namespace flatland_test
