// A scene as the renderer sees it: compiled, and the part a Renderer takes.
#pragma once

#include "flatland/model/model.hpp"
#include "flatland/render/renderer.hpp"

namespace flatland_test {

inline flatland::render::RenderSetup render_setup(const flatland::Scene& scene) {
  return flatland::model::render_setup(*flatland::model::compile(scene));
}

}  // namespace flatland_test
