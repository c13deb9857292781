// A lamp over the table (the scene's `lighting` section, docs/SCENE.md): a point light whose
// direct light falls off with the inverse square of the distance and the cosine of the incidence,
// diffuse and Blinn-Phong shading per fragment with each material's highlight, the O-ring band
// shaded as the torus it is, and the hand's and the disk's shadows on the table by exact planar
// projection from the lamp.
#pragma once

#include "flatland/scene/scene.hpp"

#include "gl_programs.hpp"

#include <opencv2/core.hpp>

#include <array>

namespace flatland::render {

/// The homogeneous map (row-major) that sends a point p to where the ray from the lamp at `light`
/// through p meets the plane z = plane_z: M = (P.L) I - L P^T with L = (light, 1) and
/// P = (0, 0, 1, -plane_z). Points below the lamp (z < light.z) keep a positive w.
cv::Matx44d planar_shadow_matrix(const cv::Vec3d& light, double plane_z);

/// The lamp's shader programs, the light's and the camera's uniforms set once (neither moves).
class LitPrograms {
 public:
  enum class Kind {
    kPlain,     ///< the vertex colour as albedo: table, hand, the disk's wall, chessboards
    kTextured,  ///< the albedo from a texture: ChArUco boards
    kDiskTop,   ///< the disk's face, marker and O-ring band, evaluated per fragment
    kShadow,    ///< an occluder flattened onto the table, darkening what lies there
  };
  LitPrograms(const Gl& gl, const LightingSpec& lighting, const cv::Matx44f& view,
              const cv::Matx44f& projection, const cv::Vec3d& eye, const cv::Vec3f& table_albedo);
  ~LitPrograms();
  LitPrograms(const LitPrograms&) = delete;
  LitPrograms& operator=(const LitPrograms&) = delete;

  unsigned program(Kind kind) const { return programs_[static_cast<int>(kind)]; }
  /// Makes `kind`'s program current with the body's model matrix and its material (no highlight
  /// when the scene's lighting.specular is off).
  void use(Kind kind, const cv::Matx44f& model, const MaterialSpec& material) const;

 private:
  const Gl& gl_;
  const LightingSpec lighting_;
  std::array<unsigned, 4> programs_{};
  struct Locations {
    int model = -1, specular = -1, shininess = -1;
  };
  std::array<Locations, 4> locations_{};
};

}  // namespace flatland::render
