#include "lighting.hpp"

#include <cmath>
#include <string>

namespace flatland::render {

namespace {

// Every lit program shares this vertex stage: world position and normal go on to the fragment
// stage, which lights each pixel (the lamp's light varies across a face: a point light's
// distance and angle change along it, and a highlight is smaller than most triangles). `flatten`
// is the identity except in the shadow program, where it is planar_shadow_matrix: its w is not 1
// there, so the position is divided by it. `depth_lift` is 0 except in the shadow program: the
// flattened body lies on the table, where it is drawn, but takes the depth of a point that much
// higher, so that the depth test lets it darken the table and what lies flat on it (a printed
// board) and not a board standing above the table, which hides the table there.
const char* const kLitVertexShader = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec3 color;
layout(location = 3) in vec2 uv;
uniform mat4 model;
uniform mat4 flatten;
uniform float depth_lift;
uniform mat4 view;
uniform mat4 projection;
out vec3 world_position;
out vec3 world_normal;
out vec3 albedo;
out vec2 tex_uv;
out vec2 world_radial;
void main() {
  vec4 wp = flatten * model * vec4(position, 1.0);
  wp /= wp.w;
  world_position = wp.xyz;
  world_normal = mat3(model) * normal;
  albedo = color;
  tex_uv = uv;
  world_radial = (mat3(model) * vec3(uv, 0.0)).xy;  // the disk's top: its radius in the table
  gl_Position = projection * view * wp;
  if (depth_lift != 0.0) {
    vec4 lifted = projection * view * (wp + vec4(0.0, 0.0, depth_lift, 0.0));
    gl_Position.z = lifted.z / lifted.w * gl_Position.w;
  }
}
)";

// The lamp: a point light whose direct light on the table straight under it is `light_radiance`
// (colour x intensity), falling off as the inverse square of the distance (normalised there) and
// the cosine of the incidence; or, without fall-off, a distant light in the lamp's direction from
// the table's origin that lights the table evenly. Diffuse (Lambert) and a Blinn-Phong highlight.
const char* const kShading = R"(
uniform vec3 light_position;
uniform vec3 light_radiance;
uniform vec3 distant_direction;
uniform bool falloff;
uniform float ambient;
uniform vec3 eye;
uniform float specular;
uniform float shininess;
vec3 direct_light(vec3 p, out vec3 l) {
  if (!falloff) {
    l = distant_direction;
    return light_radiance / distant_direction.z;
  }
  vec3 d = light_position - p;
  float d2 = dot(d, d);
  l = d * inversesqrt(d2);
  return light_radiance * (light_position.z * light_position.z / d2);
}
vec3 shade(vec3 albedo, vec3 n, vec3 p, float ks, float exponent) {
  vec3 l;
  vec3 e = direct_light(p, l);
  float ndl = dot(n, l);
  vec3 c = albedo * ambient;
  if (ndl > 0.0) {
    c += albedo * e * ndl;
    if (ks > 0.0) {
      vec3 h = normalize(l + normalize(eye - p));
      c += ks * e * pow(max(dot(n, h), 0.0), exponent);
    }
  }
  return c;
}
)";

const char* const kLitPlainFragment = R"(
in vec3 world_position;
in vec3 world_normal;
in vec3 albedo;
out vec4 out_color;
void main() {
  out_color = vec4(shade(albedo, normalize(world_normal), world_position, specular, shininess), 1.0);
}
)";

const char* const kLitTexturedFragment = R"(
in vec3 world_position;
in vec3 world_normal;
in vec3 albedo;
in vec2 tex_uv;
uniform sampler2D board;
out vec4 out_color;
void main() {
  vec3 a = albedo * texture(board, tex_uv).rgb;
  out_color = vec4(shade(a, normalize(world_normal), world_position, specular, shininess), 1.0);
}
)";

// The disk's top face as the unlit kDiskFragmentShader draws it (same regions, same uniforms),
// lit. The O-ring is a torus: seen from above its round cross-section spans the band, so the
// normal turns from pointing at the disk's centre (inner edge of the band) through up to pointing
// out (outer edge), u = the position across the band in [-1, 1]. Where the normal bisects the
// lamp's and the camera's directions the band shows its highlight, as a real O-ring does; the
// outline stays the exact circle (the torus's height is not drawn).
const char* const kLitDiskTopFragment = R"(
in vec3 world_position;
in vec2 tex_uv;
in vec2 world_radial;
uniform vec3 face_color;
uniform vec3 ring_color;
uniform vec3 marker_color;
uniform float ring_inner;
uniform float hole;
uniform vec2 marker_center;
uniform float marker_radius;
uniform float band_specular;
uniform float band_shininess;
out vec4 out_color;
void main() {
  float d2 = dot(tex_uv, tex_uv);
  if (d2 > 1.0 || d2 < hole * hole) discard;
  vec3 c;
  if (d2 > ring_inner * ring_inner) {
    float u = clamp((sqrt(d2) - 0.5 * (1.0 + ring_inner)) / (0.5 * (1.0 - ring_inner)), -1.0, 1.0);
    vec3 n = vec3(u * normalize(world_radial), sqrt(1.0 - u * u));
    c = shade(ring_color, n, world_position, band_specular, band_shininess);
  } else {
    vec2 m = tex_uv - marker_center;
    vec3 a = dot(m, m) < marker_radius * marker_radius ? marker_color : face_color;
    c = shade(a, vec3(0.0, 0.0, 1.0), world_position, specular, shininess);
  }
  out_color = vec4(c, 1.0);
}
)";

// An occluder flattened onto the table: each pixel it covers loses the lamp's direct light. The
// table (and a board lying on it) was drawn lit, albedo (ambient + direct) + highlight; blending
// multiplies it by this colour, which leaves albedo x ambient. Exact for the table's albedo, and
// for any albedo when the table's material has no highlight (the default: matte). The stencil
// lets each pixel be darkened once, however many flattened triangles cover it.
const char* const kShadowFragment = R"(
in vec3 world_position;
uniform vec3 table_albedo;
out vec4 out_color;
void main() {
  vec3 lit = shade(table_albedo, vec3(0.0, 0.0, 1.0), world_position, specular, shininess);
  out_color = vec4(table_albedo * ambient / max(lit, vec3(1e-6)), 1.0);
}
)";

std::string fragment_source(const char* body) {
  return std::string("#version 330 core\n") + kShading + body;
}

// m: above a printed board lying on the table (render-calibration's are 0.5 mm thick), below a
// board held above it.
constexpr double kShadowDepthLift = 0.002;

}  // namespace

cv::Matx44d planar_shadow_matrix(const cv::Vec3d& light, double plane_z) {
  const cv::Vec4d L(light[0], light[1], light[2], 1.0);
  const cv::Vec4d P(0, 0, 1, -plane_z);
  const double dot = L.dot(P);
  cv::Matx44d M;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) M(i, j) = (i == j ? dot : 0.0) - L[i] * P[j];
  return M;
}

LitPrograms::LitPrograms(const Gl& gl, const LightingSpec& lighting, const cv::Matx44f& view,
                         const cv::Matx44f& projection, const cv::Vec3d& eye,
                         const cv::Vec3f& table_albedo)
    : gl_(gl), lighting_(lighting) {
  const char* bodies[4] = {kLitPlainFragment, kLitTexturedFragment, kLitDiskTopFragment,
                           kShadowFragment};
  const cv::Vec3d lamp(lighting.position[0], lighting.position[1], lighting.position[2]);
  const cv::Vec3d distant = cv::normalize(lamp);
  const cv::Matx44f identity = cv::Matx44f::eye();
  // GL reads matrices column-major: the transpose of a row-major matrix has that memory layout.
  const cv::Matx44f flatten = cv::Matx44f(planar_shadow_matrix(lamp, 0.0).t());
  for (int k = 0; k < 4; ++k) {
    const std::string fragment = fragment_source(bodies[k]);
    const unsigned p = link_program(gl, fragment.c_str(), kLitVertexShader);
    programs_[k] = p;
    gl.glUseProgram(p);
    auto at = [&](const char* name) { return gl.glGetUniformLocation(p, name); };
    gl.glUniformMatrix4fv(at("view"), 1, GL_FALSE, view.val);
    gl.glUniformMatrix4fv(at("projection"), 1, GL_FALSE, projection.val);
    const bool shadow = static_cast<Kind>(k) == Kind::kShadow;
    gl.glUniformMatrix4fv(at("flatten"), 1, GL_FALSE, (shadow ? flatten : identity).val);
    gl.glUniform1f(at("depth_lift"), shadow ? float(kShadowDepthLift) : 0.0f);
    gl.glUniform3f(at("light_position"), float(lamp[0]), float(lamp[1]), float(lamp[2]));
    gl.glUniform3f(at("light_radiance"), float(lighting.intensity * lighting.color[0]),
                   float(lighting.intensity * lighting.color[1]),
                   float(lighting.intensity * lighting.color[2]));
    gl.glUniform3f(at("distant_direction"), float(distant[0]), float(distant[1]),
                   float(distant[2]));
    gl.glUniform1i(at("falloff"), lighting.falloff ? 1 : 0);
    gl.glUniform1f(at("ambient"), float(lighting.ambient));
    gl.glUniform3f(at("eye"), float(eye[0]), float(eye[1]), float(eye[2]));
    gl.glUniform3f(at("table_albedo"), table_albedo[0], table_albedo[1], table_albedo[2]);
    const bool highlights = lighting.specular;
    gl.glUniform1f(at("band_specular"), float(highlights ? lighting.band.specular : 0.0));
    gl.glUniform1f(at("band_shininess"), float(lighting.band.shininess));
    locations_[k] = {at("model"), at("specular"), at("shininess")};
  }
}

LitPrograms::~LitPrograms() {
  for (unsigned p : programs_) gl_.glDeleteProgram(p);
}

void LitPrograms::use(Kind kind, const cv::Matx44f& model, const MaterialSpec& material) const {
  const int k = static_cast<int>(kind);
  gl_.glUseProgram(programs_[k]);
  gl_.glUniformMatrix4fv(locations_[k].model, 1, GL_FALSE, model.val);
  gl_.glUniform1f(locations_[k].specular, float(lighting_.specular ? material.specular : 0.0));
  gl_.glUniform1f(locations_[k].shininess, float(material.shininess));
}

}  // namespace flatland::render
