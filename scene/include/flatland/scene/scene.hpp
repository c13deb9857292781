// Scene files: one YAML description of an experiment, loaded once, immutable afterwards.
// SI units throughout (m, s, kg, rad); keys ending in _deg are degrees. Sections a scene does not
// contain are simply off. Schema: docs/SCENE.md.
#pragma once

#include "flatland/sim/spec.hpp"

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland {

/// Bad scene input. what() is one line: "<origin>: <field>: <reason>".
class SceneError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// Overhead camera (section `camera`). Pinhole + OpenCV distortion (k1, k2, p1, p2, k3); pose in
/// the table frame (x, y in the table plane as in the simulator, origin at the hand pivot, z out
/// of the table towards the camera).
struct CameraSpec {
  int width = 640, height = 480;         ///< px
  double fx = 700, fy = 700;             ///< px
  double cx = 319.5, cy = 239.5;         ///< px (OpenCV convention: pixel centres at integers)
  std::array<double, 5> distortion{};    ///< k1, k2, p1, p2, k3
  std::array<double, 3> position{0.0, 0.0, 1.0};  ///< m, camera centre in the table frame
  std::array<double, 3> look_at{0.0, 0.0, 0.0};   ///< m, point on the optical axis
  std::array<double, 3> up{0.0, 1.0, 0.0};        ///< image "up" direction (table frame)
  double fps = 30.0;                     ///< frames per second
  double exposure = 0.0;                 ///< s, exposure time (blur when > 0 and effects.blur_subframes > 1)
};

/// Image effects (section `effects`); each is off unless the scene asks for it.
struct EffectsSpec {
  int supersample = 1;              ///< anti-aliasing: render s x s samples per pixel
  int blur_subframes = 1;           ///< exposure blur: sub-frames averaged over camera.exposure
  double noise_read_dn = 0.0;       ///< read noise sigma, DN (8-bit digital numbers)
  double noise_shot_gain = 0.0;     ///< shot noise: variance += gain * signal (DN)
  bool quantize = true;             ///< round to 8 bits (off gives a float image)
  double vignetting = 0.0;          ///< relative fall-off at the image corner (cos^4-like), 0..1
  double jitter_s = 0.0;            ///< timing jitter sigma, s
  double drop_probability = 0.0;    ///< probability a frame is dropped
  std::uint64_t seed = 1;           ///< randomness is seeded
};

/// A planar calibration target (section `targets`, list).
struct TargetSpec {
  enum class Kind { kChessboard, kCharuco };
  Kind kind = Kind::kChessboard;
  int cols = 9, rows = 6;          ///< squares
  double square = 0.02;            ///< m
  double marker = 0.015;           ///< m (ChArUco marker side)
  std::string dictionary = "DICT_4X4_50";
  std::array<double, 3> position{0.0, 0.0, 0.0};  ///< m, board origin in the table frame
  std::array<double, 3> rotation{0.0, 0.0, 0.0};  ///< rad, Rodrigues vector board -> table
};

/// How the scene is drawn (section `render`).
struct RenderSpec {
  std::string backend = "osmesa";  ///< osmesa | egl
  std::string view = "overhead";   ///< overhead | side
  double hand_thickness = 0.012;   ///< m, extrusion height of the hand plate
  double disk_thickness = 0.006;   ///< m
  double table_extent = 0.6;       ///< m, half-size of the drawn table
};

struct Scene {
  std::string origin;  ///< file path (or "<string>")
  std::string name;    ///< optional `name:` key
  sim::SimulationSpec sim;
  std::optional<CameraSpec> camera;     ///< absent: nothing is rendered
  EffectsSpec effects;
  RenderSpec render;
  std::vector<TargetSpec> targets;
};

/// Parse and validate a scene (strict: unknown keys, wrong types, NaN/inf, missing required keys,
/// physically invalid values such as negative radius, k = -2 or an unusable hand shape are errors).
Scene parse_scene(const std::string& yaml_text, const std::string& origin = "<string>");
/// Read a file and parse it; an unreadable file is a SceneError too.
Scene load_scene(const std::string& path);
/// The bundled default scene (the paper's butterfly): assets/scenes/butterfly.yaml.
std::string default_scene_path();

}  // namespace flatland
