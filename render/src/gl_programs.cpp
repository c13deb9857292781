#include "gl_programs.hpp"

namespace flatland::render {

const char* const kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec3 color;
layout(location = 3) in vec2 uv;
uniform mat4 model;
uniform mat4 view;
uniform mat4 projection;
uniform vec3 light_direction;
uniform vec3 eye;
uniform float ambient;
uniform float specular;
out vec3 lit_color;
out vec2 tex_uv;
void main() {
  vec4 wp = model * vec4(position, 1.0);
  vec3 n = normalize(mat3(model) * normal);
  float diffuse = max(dot(n, light_direction), 0.0);
  vec3 h = normalize(light_direction + normalize(eye - wp.xyz));
  float highlight = specular > 0.0 ? specular * pow(max(dot(n, h), 0.0), 24.0) : 0.0;
  lit_color = color * (ambient + (1.0 - ambient) * diffuse) + vec3(highlight);
  tex_uv = uv;
  gl_Position = projection * view * wp;
}
)";

const char* const kPlainFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
out vec4 out_color;
void main() { out_color = vec4(lit_color, 1.0); }
)";

// The disk's top face as one quad: face, O-ring band and marker are exact circles evaluated per
// fragment (the quad's texture coordinates are disk-frame coordinates in units of the radius),
// which costs far less on llvmpipe than the few hundred triangles of a polygonal disk.
const char* const kDiskFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
uniform vec3 face_color;
uniform vec3 ring_color;
uniform vec3 marker_color;
uniform float ring_inner;      // inner radius of the O-ring band, in radii
uniform float hole;            // a ring's hole, in radii (0: a solid face)
uniform vec2 marker_center;    // in radii
uniform float marker_radius;   // in radii
out vec4 out_color;
void main() {
  float d2 = dot(tex_uv, tex_uv);
  if (d2 > 1.0 || d2 < hole * hole) discard;
  vec3 c = d2 > ring_inner * ring_inner ? ring_color : face_color;
  vec2 m = tex_uv - marker_center;
  if (dot(m, m) < marker_radius * marker_radius) c = marker_color;
  out_color = vec4(lit_color * c, 1.0);
}
)";

// Only ChArUco boards (their marker bits) need a texture.
// The segmentation mask: each body one flat id (in red, id / 255), nothing shaded or textured. The
// disk's top quad is cut to its circle (and a ring's hole) as kDiskFragmentShader cuts it.
const char* const kMaskFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
uniform float object_id;   // 0..255
uniform float round_cut;   // 1: the disk's top quad
uniform float hole;        // a ring's hole, in radii
out vec4 out_color;
void main() {
  if (round_cut > 0.5) {
    float d2 = dot(tex_uv, tex_uv);
    if (d2 > 1.0 || d2 < hole * hole) discard;
  }
  out_color = vec4(object_id / 255.0, 0.0, 0.0, 1.0);
}
)";

const char* const kTexturedFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
uniform sampler2D board;
out vec4 out_color;
void main() { out_color = vec4(lit_color * texture(board, tex_uv).rgb, 1.0); }
)";

unsigned compile_shader(const Gl& gl, unsigned type, const char* src) {
  const unsigned sh = gl.glCreateShader(type);
  gl.glShaderSource(sh, 1, &src, nullptr);
  gl.glCompileShader(sh);
  int ok = 0;
  gl.glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048];
    gl.glGetShaderInfoLog(sh, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("render: shader does not compile: ") + log);
  }
  return sh;
}

unsigned link_program(const Gl& gl, const char* fragment_source, const char* vertex_source) {
  const unsigned vs = compile_shader(gl, GL_VERTEX_SHADER, vertex_source);
  const unsigned fs = compile_shader(gl, GL_FRAGMENT_SHADER, fragment_source);
  const unsigned p = gl.glCreateProgram();
  gl.glAttachShader(p, vs);
  gl.glAttachShader(p, fs);
  gl.glLinkProgram(p);
  int ok = 0;
  gl.glGetProgramiv(p, GL_LINK_STATUS, &ok);
  gl.glDeleteShader(vs);
  gl.glDeleteShader(fs);
  if (!ok) throw std::runtime_error("render: shader program does not link");
  return p;
}

}  // namespace flatland::render
