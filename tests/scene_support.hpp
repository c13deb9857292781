// The FLATLAND experiment used by the rendering-based tests: the butterfly at 5 deg tilt with
// 2T = 4 s (k solves it), seen by the 640 x 480 overhead camera at 1.2 m, 30 Hz.
#pragma once

#include "flatland/scene/scene.hpp"

#include <array>
#include <cstdint>
#include <numbers>

namespace flatland_test {

/// A 640 x 480 camera (f = 900 px, principal point at the centre) at `position`, looking
/// straight down at the table point below it: the table and the disk's face are fronto-parallel.
inline flatland::CameraSpec overhead_camera(const std::array<double, 3>& position) {
  flatland::CameraSpec cam;
  cam.width = 640;
  cam.height = 480;
  cam.fx = cam.fy = 900;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.position = position;
  cam.look_at = {position[0], position[1], 0.0};
  return cam;
}

/// `blur`: a full-frame exposure averaged over 8 sub-frames; `noise_dn`: read noise sigma.
inline flatland::Scene air_table_experiment(double noise_dn, bool blur, std::uint64_t seed) {
  flatland::Scene s;
  s.sim.tilt = 5.0 * std::numbers::pi / 180.0;
  s.sim.motion.period = 4.0;
  s.sim.motion.k = -1.1395840;
  s.sim.duration = 4.0;
  flatland::CameraSpec cam = overhead_camera({0.0, 0.0, 1.2});
  cam.fps = 30;
  cam.exposure = blur ? 1.0 / 30.0 : 0.0;
  s.camera = cam;
  s.effects.supersample = 2;
  s.effects.blur_subframes = blur ? 8 : 1;
  s.effects.noise_read_dn = noise_dn;
  s.effects.seed = seed;
  return s;
}

}  // namespace flatland_test
