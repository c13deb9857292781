#include "flatland/render/renderer.hpp"

#include "flatland/camera/board.hpp"
#include "flatland/render/distortion_maps.hpp"
#include "flatland/sim/curve.hpp"

// Prototypes only, for decltype: every function is fetched from the context at run time.
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland::render {

namespace {

// ---------------------------------------------------------------------------------------------
// The GL 3.3 core functions the renderer uses, fetched through the context (no libGL linked).
#define FLATLAND_GL_FUNCTIONS(X) \
  X(glClear)                     \
  X(glClearColor)                \
  X(glEnable)                    \
  X(glDisable)                   \
  X(glFrontFace)                 \
  X(glPolygonOffset)             \
  X(glViewport)                  \
  X(glReadPixels)                \
  X(glPixelStorei)               \
  X(glGetError)                  \
  X(glFinish)                    \
  X(glDrawArrays)                \
  X(glGenTextures)               \
  X(glBindTexture)               \
  X(glTexImage2D)                \
  X(glTexParameteri)             \
  X(glDeleteTextures)            \
  X(glActiveTexture)             \
  X(glGenerateMipmap)            \
  X(glGenFramebuffers)           \
  X(glBindFramebuffer)           \
  X(glFramebufferRenderbuffer)   \
  X(glCheckFramebufferStatus)    \
  X(glDeleteFramebuffers)        \
  X(glGenRenderbuffers)          \
  X(glBindRenderbuffer)          \
  X(glRenderbufferStorage)       \
  X(glDeleteRenderbuffers)       \
  X(glGenBuffers)                \
  X(glBindBuffer)                \
  X(glBufferData)                \
  X(glDeleteBuffers)             \
  X(glGenVertexArrays)           \
  X(glBindVertexArray)           \
  X(glDeleteVertexArrays)        \
  X(glEnableVertexAttribArray)   \
  X(glVertexAttribPointer)       \
  X(glCreateShader)              \
  X(glShaderSource)              \
  X(glCompileShader)             \
  X(glGetShaderiv)               \
  X(glGetShaderInfoLog)          \
  X(glDeleteShader)              \
  X(glCreateProgram)             \
  X(glAttachShader)              \
  X(glLinkProgram)               \
  X(glGetProgramiv)              \
  X(glGetProgramInfoLog)         \
  X(glUseProgram)                \
  X(glDeleteProgram)             \
  X(glGetUniformLocation)        \
  X(glUniformMatrix4fv)          \
  X(glUniform3f)                 \
  X(glUniform1f)                 \
  X(glUniform2f)                 \
  X(glUniform1i)

struct Gl {
#define FLATLAND_GL_MEMBER(name) decltype(&::name) name = nullptr;
  FLATLAND_GL_FUNCTIONS(FLATLAND_GL_MEMBER)
#undef FLATLAND_GL_MEMBER
  explicit Gl(const GlContext& c) {
#define FLATLAND_GL_LOAD(name)                                        \
  name = reinterpret_cast<decltype(&::name)>(c.proc_address(#name));  \
  if (!name)                                                          \
    throw std::runtime_error("GL backend " + to_string(c.backend()) + \
                             ": no " #name " (OpenGL 3.3 core required)");
    FLATLAND_GL_FUNCTIONS(FLATLAND_GL_LOAD)
#undef FLATLAND_GL_LOAD
  }
};

// ---------------------------------------------------------------------------------------------
// Shading: Lambert plus an optional Blinn-Phong highlight (the brushed aluminium hand) under one
// directional light, evaluated per vertex. Every face is planar, so Lambert shading is exact per
// vertex, and the fragment stage only passes the colour on: llvmpipe runs a fragment shader for
// every pixel, and a lit or textured one there costs several times the whole frame budget.
const char* kVertexShader = R"(#version 330 core
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

const char* kPlainFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
out vec4 out_color;
void main() { out_color = vec4(lit_color, 1.0); }
)";

// The disk's top face as one quad: face, O-ring band and marker are exact circles evaluated per
// fragment (the quad's texture coordinates are disk-frame coordinates in units of the radius),
// which costs far less on llvmpipe than the few hundred triangles of a polygonal disk.
const char* kDiskFragmentShader = R"(#version 330 core
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
const char* kTexturedFragmentShader = R"(#version 330 core
in vec3 lit_color;
in vec2 tex_uv;
uniform sampler2D board;
out vec4 out_color;
void main() { out_color = vec4(lit_color * texture(board, tex_uv).rgb, 1.0); }
)";

// Interleaved vertex: position, normal, colour, texture coordinate.
struct Vertex {
  float p[3], n[3], c[3], uv[2];
};
using Mesh = std::vector<Vertex>;

void add_triangle(Mesh& m, const cv::Vec3d& a, const cv::Vec3d& b, const cv::Vec3d& c,
                  const cv::Vec3d& normal, const cv::Vec3f& color,
                  std::array<cv::Vec2f, 3> uv = {}) {
  // Wind every triangle counter-clockwise seen from its outward normal, so that back faces can
  // be culled (walls facing away from the camera cost nothing).
  const bool flip = (b - a).cross(c - a).dot(normal) < 0;
  const cv::Vec3d* pts[3] = {&a, flip ? &c : &b, flip ? &b : &c};
  if (flip) std::swap(uv[1], uv[2]);
  for (int i = 0; i < 3; ++i) {
    Vertex v{};
    for (int k = 0; k < 3; ++k) {
      v.p[k] = static_cast<float>((*pts[i])[k]);
      v.n[k] = static_cast<float>(normal[k]);
      v.c[k] = color[k];
    }
    v.uv[0] = uv[i][0];
    v.uv[1] = uv[i][1];
    m.push_back(v);
  }
}

void add_quad(Mesh& m, const cv::Vec3d& a, const cv::Vec3d& b, const cv::Vec3d& c,
              const cv::Vec3d& d, const cv::Vec3d& normal, const cv::Vec3f& color) {
  add_triangle(m, a, b, c, normal, color);
  add_triangle(m, a, c, d, normal, color);
}

// Ear clipping of a simple polygon (counter-clockwise). Of the ears that can be cut, the best
// shaped one (largest smallest angle) goes first: clipping ears in order would fan long slivers
// from one vertex, and llvmpipe pays for a sliver by its length (see banded_triangulation).
std::vector<std::array<int, 3>> triangulate(const std::vector<cv::Point2d>& poly) {
  std::vector<int> idx(poly.size());
  for (std::size_t i = 0; i < poly.size(); ++i) idx[i] = static_cast<int>(i);
  std::vector<std::array<int, 3>> tris;
  auto cross = [](const cv::Point2d& o, const cv::Point2d& a, const cv::Point2d& b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
  };
  auto smallest_angle = [](const cv::Point2d& a, const cv::Point2d& b, const cv::Point2d& c) {
    const double ab = cv::norm(b - a), bc = cv::norm(c - b), ca = cv::norm(a - c);
    auto angle = [](double opposite, double s1, double s2) {
      return std::acos(
          std::clamp((s1 * s1 + s2 * s2 - opposite * opposite) / (2 * s1 * s2), -1.0, 1.0));
    };
    return std::min({angle(bc, ab, ca), angle(ca, ab, bc), angle(ab, bc, ca)});
  };
  while (idx.size() > 3) {
    std::size_t best = idx.size();
    double best_quality = -1;
    for (std::size_t i = 0; i < idx.size(); ++i) {
      const int a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i],
                c = idx[(i + 1) % idx.size()];
      if (cross(poly[a], poly[b], poly[c]) <= 0) continue;  // reflex corner
      bool empty = true;
      for (int j : idx) {
        if (j == a || j == b || j == c) continue;
        if (cross(poly[a], poly[b], poly[j]) >= 0 && cross(poly[b], poly[c], poly[j]) >= 0 &&
            cross(poly[c], poly[a], poly[j]) >= 0) {
          empty = false;
          break;
        }
      }
      if (!empty) continue;
      const double quality = smallest_angle(poly[a], poly[b], poly[c]);
      if (quality > best_quality) {
        best_quality = quality;
        best = i;
      }
    }
    if (best == idx.size()) throw std::runtime_error("render: cannot triangulate the hand outline");
    tris.push_back(
        {idx[(best + idx.size() - 1) % idx.size()], idx[best], idx[(best + 1) % idx.size()]});
    idx.erase(idx.begin() + static_cast<long>(best));
  }
  tris.push_back({idx[0], idx[1], idx[2]});
  return tris;
}

// Colours (linear RGB stored as BGR-free RGB; the shader output is read back as BGRA).
const cv::Vec3f kTable(0.20f, 0.22f, 0.25f);
const cv::Vec3f kAluminium(0.60f, 0.61f, 0.63f);
const cv::Vec3f kPivot(0.30f, 0.30f, 0.32f);
const cv::Vec3f kDiskFace(0.92f, 0.92f, 0.90f);
const cv::Vec3f kRubber(0.05f, 0.05f, 0.05f);
const cv::Vec3f kMarker(0.10f, 0.12f, 0.55f);

constexpr double kAmbient = 0.35;
const cv::Vec3d kLight =
    cv::normalize(cv::Vec3d(0.25, 0.35, 1.0));  // table frame, towards the light

constexpr double kRingWidth = 0.08;    // O-ring seen from above, fraction of the radius
constexpr double kMarkerOffset = 0.5;  // marker centre from the disk centre, fraction of radius
constexpr double kMarkerRadius = 0.12;

// Parameters along [s0, s1] of one piece, spaced so that the chord's sagitta stays below
// `tolerance` (m): fine at the tip, coarse along flat stretches.
std::vector<double> adaptive_samples(const sim::Curve& curve, int piece, double s0, double s1,
                                     double tolerance) {
  std::vector<double> out{s0};
  double s = s0;
  const double dir = s1 > s0 ? 1.0 : -1.0;
  while (dir * (s1 - s) > 1e-12) {
    const sim::CurveGeometry g = curve.geometry(s, piece);
    const double kappa = std::max(std::abs(g.curvature), 1e-6);
    const double step_len = std::min(std::sqrt(8.0 * tolerance / kappa), 0.01);  // m
    s += dir * std::max(step_len / g.speed, 1e-4);
    if (dir * (s1 - s) < 0.25 * step_len / g.speed) s = s1;  // no sliver at the end
    out.push_back(s);
  }
  return out;
}

constexpr double kOutlineTolerance = 2e-5;  // m: 0.02 px at 1 px/mm

// The hand's top face in well-shaped triangles. llvmpipe pays for a triangle by the 4x4 pixel
// blocks it touches, besides a fixed cost per triangle, so long slivers (slabs across the hand,
// fans from one vertex) cost several times the face's own area. Here the face is a coarse inner
// polygon through points `depth` inside the outline at key vertices about `spacing` apart (ear
// clipped, best ears first: large triangles), and a band between that polygon and the outline,
// fanned to every outline vertex (short triangles). The outline polygon is covered exactly.
// Returns nothing when the band folds over itself (depth too large for the outline's curvature).
struct PolygonMesh {
  std::vector<cv::Point2d> points;
  std::vector<std::array<int, 3>> triangles;
};

std::optional<PolygonMesh> banded_triangulation(const std::vector<cv::Point2d>& outline,
                                                double depth, double spacing) {
  const int n = static_cast<int>(outline.size());
  std::vector<int> keys{0};
  double run = 0;
  for (int i = 1; i < n; ++i) {
    run += cv::norm(outline[i] - outline[i - 1]);
    if (run >= spacing && n - i > 1) {
      keys.push_back(i);
      run = 0;
    }
  }
  const int K = static_cast<int>(keys.size());
  if (K < 3) return std::nullopt;
  PolygonMesh out;
  out.points = outline;  // then the K inner points
  std::vector<cv::Point2d> inner;
  for (int k : keys) {
    const cv::Point2d t = outline[(k + 1) % n] - outline[(k + n - 1) % n];
    inner.push_back(outline[k] + depth / cv::norm(t) * cv::Point2d(-t.y, t.x));  // inward (left)
  }
  out.points.insert(out.points.end(), inner.begin(), inner.end());
  for (int j = 0; j < K; ++j) {
    const int a = keys[j], b = j + 1 < K ? keys[j + 1] : n, mid = a + (b - a) / 2;
    const int ia = n + j, ib = n + (j + 1) % K;
    for (int i = a; i < mid; ++i) out.triangles.push_back({i, (i + 1) % n, ia});
    out.triangles.push_back({mid % n, ib, ia});
    for (int i = mid; i < b; ++i) out.triangles.push_back({i, (i + 1) % n, ib});
  }
  for (const auto& t : triangulate(inner)) out.triangles.push_back({n + t[0], n + t[1], n + t[2]});
  // Every triangle counter-clockwise and the boundary the (simple) outline: then the triangles
  // cover the polygon exactly once (the degree of the map is the winding number, 1 or 0).
  for (const auto& t : out.triangles) {
    const cv::Point2d u = out.points[t[1]] - out.points[t[0]];
    const cv::Point2d v = out.points[t[2]] - out.points[t[0]];
    if (!(u.x * v.y - u.y * v.x > 1e-6 * depth * depth)) return std::nullopt;
  }
  return out;
}

// The paper's polynomial hand's outline, counter-clockwise: the right half sampled from the tip
// (u = 0) to the middle of the palm/back (u = 1) and mirrored; the shape is symmetric about the x
// axis within a half (x even, y odd in u) and the halves mirror x -> -x, so the drawn outline is
// exactly symmetric too.
std::vector<cv::Point2d> polynomial_outline(const sim::PolynomialHand& hand) {
  const std::vector<double> u = adaptive_samples(hand, 0, 0.0, 1.0, kOutlineTolerance);
  std::vector<cv::Point2d> half;  // (x(u), |y(u)|)
  for (std::size_t i = 0; i < u.size(); ++i) {
    const sim::Vec2 p = hand.geometry(u[i], 0).point;
    half.emplace_back(p.x(), std::abs(p.y()));
  }
  // Closed outline, counter-clockwise: up the right half from the back's middle (bottom) over the
  // tip to the palm's middle (top), then down the mirrored half. Junction points appear once.
  const std::size_t last = half.size() - 1;
  std::vector<cv::Point2d> outline;
  for (std::size_t i = last + 1; i-- > 0;) outline.emplace_back(half[i].x, -half[i].y);
  for (std::size_t i = 1; i <= last; ++i) outline.emplace_back(half[i].x, half[i].y);
  for (std::size_t i = last; i-- > 0;) outline.emplace_back(-half[i].x, half[i].y);
  for (std::size_t i = 1; i < last; ++i) outline.emplace_back(-half[i].x, -half[i].y);
  return outline;
}

double signed_area(const std::vector<cv::Point2d>& polygon) {
  double area = 0;
  for (std::size_t i = 0; i < polygon.size(); ++i)
    area += polygon[i].cross(polygon[(i + 1) % polygon.size()]) / 2;
  return area;
}

// Any other closed hand's outline over one period from s = -1 (the palm's middle), each piece
// sampled by its own formula, counter-clockwise (hands are traversed clockwise, so reversed).
std::vector<cv::Point2d> closed_outline(const sim::HandCurve& hand) {
  const double s_begin = -1.0, s_end = s_begin + hand.period();
  std::vector<cv::Point2d> outline;
  for (double s = s_begin; s < s_end;) {
    const int piece = hand.piece_at(s, +1);
    const double end = std::min(hand.piece_interval(piece).hi, s_end);
    if (!(end > s)) throw std::logic_error("render: a hand piece that does not advance s");
    const std::vector<double> u = adaptive_samples(hand, piece, s, end, kOutlineTolerance);
    for (std::size_t i = 0; i + 1 < u.size(); ++i) {  // the end is the next piece's start
      const sim::Vec2 p = hand.geometry(u[i], piece).point;
      outline.emplace_back(p.x(), p.y());
    }
    s = end;
  }
  if (signed_area(outline) < 0) std::reverse(outline.begin(), outline.end());
  return outline;
}

// Where an open hand leaves the disk of radius `reach` about the pivot, walking from s in
// `direction` (+1/-1) in steps of 1 cm along it; or where the curve ends.
double open_hand_end(const sim::HandCurve& hand, double s, int direction, double reach) {
  for (int i = 0; i < 1000000; ++i) {
    const int piece = hand.piece_at(s, direction);
    const sim::PieceInterval iv = hand.piece_interval(piece);
    const sim::CurveGeometry g = hand.geometry(s, piece);
    if (g.point.norm() >= reach) return s;
    const double end = direction > 0 ? iv.hi : iv.lo;
    double next = s + direction * 0.01 / g.speed;
    if (direction * (next - end) >= 0) {
      if (hand.piece_at(end, direction) == piece) return end;  // the curve's own end
      next = end;
    }
    s = next;
  }
  return s;
}

// The distance from the pivot an open hand is drawn out to: the table's corners (at
// sqrt(2) table_extent) lie well inside it whatever the hand's angle.
double open_hand_reach(double table_extent) { return 2 * table_extent; }

// An open hand (a line): its curve from where it enters to where it leaves the disk of radius
// 2 table_extent about the pivot, closed by a back edge 4 table_extent deep in the body (along the
// inward normal at each end), counter-clockwise.
std::vector<cv::Point2d> open_outline(const sim::HandCurve& hand, double table_extent) {
  const double reach = open_hand_reach(table_extent);
  const double middle = hand.nearest(sim::Vec2::Zero());
  const double lo = open_hand_end(hand, middle, -1, reach);
  const double hi = open_hand_end(hand, middle, +1, reach);
  std::vector<cv::Point2d> edge;
  for (double s = lo; s < hi;) {
    const int piece = hand.piece_at(s, +1);
    const double end = std::min(hand.piece_interval(piece).hi, hi);
    if (!(end > s)) throw std::logic_error("render: a hand piece that does not advance s");
    const std::vector<double> u = adaptive_samples(hand, piece, s, end, kOutlineTolerance);
    for (std::size_t i = 0; i + 1 < u.size() || (end == hi && i < u.size()); ++i) {
      const sim::Vec2 p = hand.geometry(u[i], piece).point;
      edge.emplace_back(p.x(), p.y());
    }
    s = end;
  }
  const double depth = 2 * reach;
  for (double s : {hi, lo}) {
    const sim::CurveGeometry g = hand.geometry(s, hand.piece_at(s, s == hi ? -1 : +1));
    const sim::Vec2 back = g.point - depth * g.normal;
    edge.emplace_back(back.x(), back.y());
  }
  if (signed_area(edge) < 0) std::reverse(edge.begin(), edge.end());
  return edge;
}

// How far a circular well's drawn ring reaches beyond the well: its outer radius is this times
// the well's radius.
constexpr double kWellRingOuter = 1.25;

// A circle of `radius` about `center` in as many segments as keep the chord within the outline
// tolerance of the circle, counter-clockwise.
std::vector<cv::Point2d> circle_points(const sim::Vec2& center, double radius, int segments) {
  std::vector<cv::Point2d> out;
  for (int i = 0; i < segments; ++i) {
    const double a = 2 * std::numbers::pi * i / segments;
    out.emplace_back(center.x() + radius * std::cos(a), center.y() + radius * std::sin(a));
  }
  return out;
}
int circle_segments(double radius) {
  const double step = 2 * std::acos(std::max(0.0, 1 - kOutlineTolerance / radius));
  return std::clamp(static_cast<int>(std::ceil(2 * std::numbers::pi / step)), 32, 4096);
}

// The hand plate's pivot: a short cylinder on top of the plate at the origin.
void add_pivot(Mesh& m, double thickness) {
  constexpr int kSeg = 32;
  const double pr = 0.012, pz = thickness + 0.004;
  for (int i = 0; i < kSeg; ++i) {
    const double a0 = 2 * std::numbers::pi * i / kSeg, a1 = 2 * std::numbers::pi * (i + 1) / kSeg;
    add_triangle(m, {0, 0, pz}, {pr * std::cos(a0), pr * std::sin(a0), pz},
                 {pr * std::cos(a1), pr * std::sin(a1), pz}, {0, 0, 1}, kPivot);
  }
}

// A plate of `thickness` whose top face is the simple polygon `outline` (counter-clockwise), with
// its side walls and, where the pivot is on the plate, the pivot (a line's plate may pass beside
// it).
Mesh plate_mesh(const std::vector<cv::Point2d>& outline, double thickness) {
  Mesh m;
  const double z0 = 0.0005, z1 = thickness;
  // The top face. Band depth and key spacing scale with the hand (about 8 mm and 33 mm for the
  // paper's hand: band triangles a few pixels long, inner ones tens of pixels); the depth is
  // halved until the band fits the outline's curvature, and plain ear clipping is the fallback.
  const double area = signed_area(outline);
  std::optional<PolygonMesh> top;
  for (double depth = 0.04 * std::sqrt(area); !top && depth > 1e-4; depth /= 2)
    top = banded_triangulation(outline, depth, 4 * depth);
  if (!top) top = PolygonMesh{outline, triangulate(outline)};
  for (const auto& t : top->triangles) {
    auto P = [&](int i) { return cv::Vec3d(top->points[i].x, top->points[i].y, z1); };
    add_triangle(m, P(t[0]), P(t[1]), P(t[2]), {0, 0, 1}, kAluminium);
  }
  const std::size_t n = outline.size();
  for (std::size_t i = 0; i < n; ++i) {
    const cv::Point2d a = outline[i], b = outline[(i + 1) % n];
    const cv::Point2d d = b - a;
    const double len = std::hypot(d.x, d.y);
    if (len < 1e-12) continue;
    const cv::Vec3d normal(d.y / len, -d.x / len, 0);  // outward for a counter-clockwise outline
    add_quad(m, {a.x, a.y, z0}, {b.x, b.y, z0}, {b.x, b.y, z1}, {a.x, a.y, z1}, normal, kAluminium);
  }
  std::vector<cv::Point2f> polygon(outline.begin(), outline.end());
  if (cv::pointPolygonTest(polygon, cv::Point2f(0, 0), false) >= 0) add_pivot(m, thickness);
  return m;
}

// A circular well drawn as a ring: the plate between the well's circle and kWellRingOuter times
// it, walls inside and out. No pivot cap: it would stand in the well, over the object.
Mesh well_ring_mesh(const sim::CircleWellHand& well, double thickness) {
  Mesh m;
  const double z0 = 0.0005, z1 = thickness;
  const double r_in = well.radius(), r_out = kWellRingOuter * r_in;
  const int n = circle_segments(r_out);
  const std::vector<cv::Point2d> in = circle_points(well.center(), r_in, n);
  const std::vector<cv::Point2d> out = circle_points(well.center(), r_out, n);
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    add_quad(m, {in[i].x, in[i].y, z1}, {out[i].x, out[i].y, z1}, {out[j].x, out[j].y, z1},
             {in[j].x, in[j].y, z1}, {0, 0, 1}, kAluminium);
    const double a = 2 * std::numbers::pi * (i + 0.5) / n;
    const cv::Vec3d radial(std::cos(a), std::sin(a), 0);
    add_quad(m, {out[i].x, out[i].y, z0}, {out[j].x, out[j].y, z0}, {out[j].x, out[j].y, z1},
             {out[i].x, out[i].y, z1}, radial, kAluminium);
    add_quad(m, {in[i].x, in[i].y, z0}, {in[j].x, in[j].y, z0}, {in[j].x, in[j].y, z1},
             {in[i].x, in[i].y, z1}, -radial, kAluminium);
  }
  return m;
}

Mesh hand_mesh(const sim::HandCurve& hand, double thickness, double table_extent) {
  if (const auto* well = dynamic_cast<const sim::CircleWellHand*>(&hand))
    return well_ring_mesh(*well, thickness);
  return plate_mesh(hand_plate_outline(hand, table_extent), thickness);
}

// The disk's rubber side wall (its top is drawn by kDiskFragmentShader on disk_top_quad), and a
// ring's inner wall around its hole (radius `hole` > 0, facing the centre).
Mesh disk_side_mesh(double r, double thickness, double hole = 0) {
  constexpr int kSeg = 64;
  Mesh m;
  for (int i = 0; i < kSeg; ++i) {
    const double a0 = 2 * std::numbers::pi * i / kSeg, a1 = 2 * std::numbers::pi * (i + 1) / kSeg;
    const cv::Vec3d u0(std::cos(a0), std::sin(a0), 0), u1(std::cos(a1), std::sin(a1), 0);
    const cv::Vec3d up(0, 0, thickness);
    add_quad(m, r * u0, r * u1, r * u1 + up, r * u0 + up, 0.5 * (u0 + u1), kRubber);
    if (hole > 0)
      add_quad(m, hole * u0, hole * u1, hole * u1 + up, hole * u0 + up, -0.5 * (u0 + u1), kRubber);
  }
  return m;
}

Mesh disk_top_quad(double r, double thickness) {
  Mesh m;
  const cv::Vec3f white(1, 1, 1);
  const double z = thickness;
  add_triangle(m, {-r, -r, z}, {r, -r, z}, {r, r, z}, {0, 0, 1}, white,
               {cv::Vec2f(-1, -1), cv::Vec2f(1, -1), cv::Vec2f(1, 1)});
  add_triangle(m, {-r, -r, z}, {r, r, z}, {-r, r, z}, {0, 0, 1}, white,
               {cv::Vec2f(-1, -1), cv::Vec2f(1, 1), cv::Vec2f(-1, 1)});
  return m;
}

// ---- spatial bodies ----

const cv::Vec3f kBall(0.92f, 0.92f, 0.90f);
const cv::Vec3f kBallCell(0.10f, 0.12f, 0.55f);
const cv::Vec3f kBackground(0.08f, 0.08f, 0.09f);

/// A surface's chart tessellated over [lo, hi] (nu x nv quads, flat-shaded by each facet's
/// normal). `cells` > 0 colours the quads in a checkerboard of that many cells along u (and half
/// as many along v) in `color` and `cell_color`, so that the body's motion shows.
Mesh surface_mesh(const sim::Surface& surface, const sim::SurfacePatch& range, int nu, int nv,
                  const cv::Vec3f& color, int cells, const cv::Vec3f& cell_color) {
  Mesh m;
  const auto point = [&](double u, double v) {
    const sim::Vec3 c = surface.jet(sim::SurfaceParam(u, v)).c;
    return cv::Vec3d(c.x(), c.y(), c.z());
  };
  const double du = (range.hi.x() - range.lo.x()) / nu, dv = (range.hi.y() - range.lo.y()) / nv;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u0 = range.lo.x() + i * du, v0 = range.lo.y() + j * dv;
      const cv::Vec3d a = point(u0, v0), b = point(u0 + du, v0), c = point(u0 + du, v0 + dv),
                      d = point(u0, v0 + dv);
      // The facet's normal, turned outwards by the surface's orientation (also at a pole, where
      // the chart is singular and the quad a triangle).
      cv::Vec3d normal = (c - a).cross(d - b);
      if (cv::norm(normal) == 0) continue;
      normal *= surface.normal_sign() / cv::norm(normal);
      cv::Vec3f col = color;
      if (cells > 0) {
        const int cu = static_cast<int>(std::floor((i + 0.5) * cells / nu));
        const int cv_ = static_cast<int>(std::floor((j + 0.5) * std::max(1, cells / 2) / nv));
        if ((cu + cv_) % 2 == 1) col = cell_color;
      }
      if (cv::norm(b - a) > 0) add_triangle(m, a, b, c, normal, col);
      if (cv::norm(d - c) > 0) add_triangle(m, a, c, d, normal, col);
    }
  return m;
}

/// The part of the hand's chart drawn: the extent asked for, its unbounded sides cut at the
/// patch. (A finite extent may go past the patch: a bowl is drawn to its poles, where the chart's
/// formula still holds but the run cannot follow the contact.)
sim::SurfacePatch drawn_range(const sim::Surface& s, const sim::SurfacePatch& extent) {
  const sim::SurfacePatch p = s.patch();
  sim::SurfacePatch r = extent;
  for (int i = 0; i < 2; ++i) {
    if (!std::isfinite(r.lo[i])) r.lo[i] = p.lo[i];
    if (!std::isfinite(r.hi[i])) r.hi[i] = p.hi[i];
  }
  if (!(r.lo.array() < r.hi.array()).all() || !r.lo.allFinite() || !r.hi.allFinite())
    throw std::invalid_argument("render: the hand's drawn extent is empty or unbounded");
  return r;
}

Mesh table_mesh(double extent) {
  Mesh m;
  add_quad(m, {-extent, -extent, 0}, {extent, -extent, 0}, {extent, extent, 0},
           {-extent, extent, 0}, {0, 0, 1}, kTable);
  return m;
}

// A chessboard as exact geometry: a white board (one square of margin) and black squares, all in
// the board plane z = 0 (the board is drawn with a polygon offset behind the squares). Board
// frame: origin at the outer corner of the first square, x along columns, y along rows.
Mesh chessboard_background(const camera::Board& t) {
  Mesh m;
  const double s = t.square;
  add_quad(m, {-s, -s, 0}, {(t.squares_x + 1) * s, -s, 0},
           {(t.squares_x + 1) * s, (t.squares_y + 1) * s, 0}, {-s, (t.squares_y + 1) * s, 0},
           {0, 0, 1}, cv::Vec3f(0.95f, 0.95f, 0.95f));
  return m;
}

Mesh chessboard_squares(const camera::Board& t) {
  Mesh m;
  const double s = t.square;
  for (int r = 0; r < t.squares_y; ++r)
    for (int c = 0; c < t.squares_x; ++c)
      if ((r + c) % 2 == 0)
        add_quad(m, {c * s, r * s, 0}, {(c + 1) * s, r * s, 0}, {(c + 1) * s, (r + 1) * s, 0},
                 {c * s, (r + 1) * s, 0}, {0, 0, 1}, cv::Vec3f(0.04f, 0.04f, 0.04f));
  return m;
}

// A ChArUco board as a textured quad: OpenCV draws the board image (the markers' bits need a
// texture); 40 texels per square keep the marker bits sharp.
Mesh textured_quad(double w, double h) {
  Mesh m;
  const cv::Vec3f white(1, 1, 1);
  add_triangle(m, {0, 0, 0}, {w, 0, 0}, {w, h, 0}, {0, 0, 1}, white,
               {cv::Vec2f(0, 1), cv::Vec2f(1, 1), cv::Vec2f(1, 0)});
  add_triangle(m, {0, 0, 0}, {w, h, 0}, {0, h, 0}, {0, 0, 1}, white,
               {cv::Vec2f(0, 1), cv::Vec2f(1, 0), cv::Vec2f(0, 0)});
  return m;
}

cv::Matx44f to_gl(const cv::Matx44d& m) {
  // GL expects column-major; transposing a row-major matrix gives that memory layout.
  cv::Matx44f out;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out(c, r) = static_cast<float>(m(r, c));
  return out;
}

cv::Matx44d rigid(const cv::Matx33d& R, const cv::Vec3d& t) {
  return {R(0, 0), R(0, 1), R(0, 2), t[0], R(1, 0), R(1, 1), R(1, 2), t[1],
          R(2, 0), R(2, 1), R(2, 2), t[2], 0,       0,       0,       1};
}

cv::Matx33d rot_z(double a) {
  const double c = std::cos(a), s = std::sin(a);
  return {c, -s, 0, s, c, 0, 0, 0, 1};
}

}  // namespace

std::vector<cv::Point2d> hand_plate_outline(const sim::HandCurve& hand, double table_extent) {
  if (const auto* polynomial = dynamic_cast<const sim::PolynomialHand*>(&hand))
    return polynomial_outline(*polynomial);
  if (const auto* well = dynamic_cast<const sim::CircleWellHand*>(&hand))
    return circle_points(well->center(), kWellRingOuter * well->radius(),
                         circle_segments(kWellRingOuter * well->radius()));
  if (!std::isfinite(hand.period())) {
    if (!(table_extent > 0) || !std::isfinite(table_extent))
      throw std::invalid_argument("render.table_extent: must be positive and finite");
    return open_outline(hand, table_extent);
  }
  return closed_outline(hand);
}

SceneState SceneState::from_spatial_sample(const sim::SpatialSample& s,
                                           const sim::HandPose3& hand) {
  SceneState st;
  st.t = s.t;
  SpatialPose pose;
  const Eigen::Matrix3d Ro = s.state.orientation.normalized().toRotationMatrix();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      pose.hand_rotation(r, c) = hand.rotation(r, c);
      pose.object_rotation(r, c) = Ro(r, c);
    }
    pose.hand_position[r] = hand.position[r];
    pose.object_position[r] = s.state.position[r];
  }
  st.spatial = pose;
  return st;
}

SceneState SceneState::from_sample(const sim::Sample& s) {
  SceneState st;
  st.t = s.t;
  st.hand_angle = s.theta;
  st.disk_center = {s.object_position.x(), s.object_position.y()};
  st.disk_angle = s.object_angle;
  st.s_h = s.s_h;
  st.force_normal_ratio = s.fn_ratio;
  st.force_tangential_ratio = s.ft_ratio;
  st.mode = s.mode;
  return st;
}

// ---------------------------------------------------------------------------------------------
struct Renderer::Impl {
  struct Drawable {
    unsigned vao = 0, vbo = 0, texture = 0;
    int count = 0;
    cv::Matx44d model = cv::Matx44d::eye();
    bool behind = false;  // drawn with a polygon offset: coplanar geometry drawn later wins
  };

  RenderSetup setup;
  camera::CameraModel& camera = setup.camera;
  DistortionMaps maps;
  int supersample = 1;
  double disk_radius = 0;    // m, the object's outline as the camera sees it (a ball's R)
  double hole_radius = 0;    // m, a ring's hole
  double marker_offset = 0;  // marker centre from the object's centre, fraction of its radius
  std::unique_ptr<GlContext> context;
  std::unique_ptr<Gl> gl;
  unsigned program = 0, textured_program = 0, disk_program = 0, fbo = 0, color_rb = 0, depth_rb = 0;
  int fbo_width = 0, fbo_height = 0;
  Drawable table, hand, disk, disk_top;
  Drawable spatial_hand, spatial_object;  // a spatial scene's bodies
  std::vector<Drawable> targets;
  bool textured_targets = false;
  bool table_fills_view = false;
  struct Locations {
    int model, specular;
  };
  std::map<unsigned, Locations> locations;  // per program
  cv::Vec3f table_color;
  EffectsRng rng;
  cv::Mat readback;  // CV_8UC4 (RGBA), reused
  // render_linear's intermediates at the supersampled size, capture's sub-frame and its float
  // image before quantisation: reused.
  cv::Mat ideal_bgr, ideal_f32, distorted_f32, subframe, linear_scratch;
  cv::Mat downsampled_rgba;  // render_8u's supersampled readback averaged down, reused

  Impl(const RenderSetup& given, GlBackend backend) : setup(given), rng(given.effects.seed) {
    const RenderSetup& s = setup;
    supersample = s.effects.supersample;
    if (supersample < 1 || supersample > 8)
      throw std::invalid_argument("effects.supersample: must be between 1 and 8");
    if (!s.spatial && !s.object.round())
      throw std::invalid_argument(
          "object.type: ellipse: the renderer draws disks, rings and balls");
    if (!s.spatial) {
      // A ball is drawn as its equatorial disk seen from above (radius R, the face's texture),
      // not a shaded sphere; a ring as the annulus of its face.
      disk_radius = s.object.seen_radius();
      if (s.object.kind == sim::ObjectSpec::Kind::kRing) hole_radius = s.object.inner_radius;
      // The marker on the face between the hole and the O-ring band.
      marker_offset = std::max(kMarkerOffset, 0.5 * (hole_radius / disk_radius + 1.0 - kRingWidth));
    }
    maps = make_distortion_maps(camera, supersample);
    fbo_width = maps.ideal_width;
    fbo_height = maps.ideal_height;
    context = create_context(backend);
    gl = std::make_unique<Gl>(*context);
    build_program();
    build_framebuffer();
    if (s.spatial) {
      if (!s.spatial->hand || !s.spatial->object)
        throw std::invalid_argument("render: a spatial scene needs its hand and object surfaces");
      constexpr int kHandQuads = 96, kBodyQuads = 48;
      spatial_hand = upload(
          surface_mesh(*s.spatial->hand, drawn_range(*s.spatial->hand, s.spatial->hand_extent),
                       kHandQuads, kHandQuads, kAluminium, 12, kAluminium * 0.8f));
      // The whole object: every longitude, the latitudes up to its poles.
      const double half_pi = std::numbers::pi / 2;
      spatial_object = upload(surface_mesh(
          *s.spatial->object, {{-std::numbers::pi, -half_pi}, {std::numbers::pi, half_pi}},
          kBodyQuads, kBodyQuads / 2, kBall, 8, kBallCell));
    }
    table = upload(table_mesh(s.render.table_extent));
    if (s.hand) hand = upload(hand_mesh(*s.hand, s.render.hand_thickness, s.render.table_extent));
    disk = upload(disk_side_mesh(disk_radius, s.render.disk_thickness, hole_radius));
    disk_top = upload(disk_top_quad(disk_radius, s.render.disk_thickness));
    for (const camera::PlacedBoard& b : s.boards) targets.push_back(make_target(b));
    for (const Drawable& t : targets) textured_targets = textured_targets || t.texture != 0;
    readback.create(fbo_height, fbo_width, CV_8UC4);
    const float shade = static_cast<float>(kAmbient + (1.0 - kAmbient) * std::max(kLight[2], 0.0));
    table_color = kTable * shade;
    table_fills_view = view_inside_table(s.render.table_extent);
    // The camera and the light never change: their uniforms are set once, and each frame only
    // uploads the moving parts' model matrices (llvmpipe re-validates state on every change).
    for (unsigned p : {program, textured_program, disk_program}) set_frame_uniforms(p);
    for (unsigned p : {program, textured_program, disk_program})
      locations[p] = {gl->glGetUniformLocation(p, "model"),
                      gl->glGetUniformLocation(p, "specular")};
  }

  // Whether every ray through the ideal image's corners meets the table plane inside the table.
  bool view_inside_table(double extent) const {
    const cv::Vec3d c = camera.position_in_table();
    const cv::Matx33d Kinv = maps.ideal_K.inv();
    for (double u : {-0.5, fbo_width - 0.5})
      for (double v : {-0.5, fbo_height - 0.5}) {
        const cv::Vec3d d = camera.R.t() * (Kinv * cv::Vec3d(u, v, 1));
        if (!(d[2] < 0)) return false;
        const double lambda = -c[2] / d[2];
        const cv::Vec3d p = c + lambda * d;
        if (std::abs(p[0]) > extent || std::abs(p[1]) > extent) return false;
      }
    return true;
  }

  ~Impl() {
    if (!gl) return;
    context->make_current();
    for (Drawable* d : {&table, &hand, &disk, &disk_top, &spatial_hand, &spatial_object})
      release(*d);
    for (Drawable& d : targets) release(d);
    gl->glDeleteFramebuffers(1, &fbo);
    gl->glDeleteRenderbuffers(1, &color_rb);
    gl->glDeleteRenderbuffers(1, &depth_rb);
    gl->glDeleteProgram(program);
    gl->glDeleteProgram(textured_program);
    gl->glDeleteProgram(disk_program);
  }

  void release(Drawable& d) {
    gl->glDeleteBuffers(1, &d.vbo);
    gl->glDeleteVertexArrays(1, &d.vao);
    if (d.texture) gl->glDeleteTextures(1, &d.texture);
  }

  unsigned compile(unsigned type, const char* src) {
    const unsigned sh = gl->glCreateShader(type);
    gl->glShaderSource(sh, 1, &src, nullptr);
    gl->glCompileShader(sh);
    int ok = 0;
    gl->glGetShaderiv(sh, GL_COMPILE_STATUS, &ok);
    if (!ok) {
      char log[2048];
      gl->glGetShaderInfoLog(sh, sizeof log, nullptr, log);
      throw std::runtime_error(std::string("render: shader does not compile: ") + log);
    }
    return sh;
  }

  unsigned link(const char* fragment_source) {
    const unsigned vs = compile(GL_VERTEX_SHADER, kVertexShader);
    const unsigned fs = compile(GL_FRAGMENT_SHADER, fragment_source);
    const unsigned p = gl->glCreateProgram();
    gl->glAttachShader(p, vs);
    gl->glAttachShader(p, fs);
    gl->glLinkProgram(p);
    int ok = 0;
    gl->glGetProgramiv(p, GL_LINK_STATUS, &ok);
    gl->glDeleteShader(vs);
    gl->glDeleteShader(fs);
    if (!ok) throw std::runtime_error("render: shader program does not link");
    return p;
  }

  void build_program() {
    program = link(kPlainFragmentShader);
    textured_program = link(kTexturedFragmentShader);
    disk_program = link(kDiskFragmentShader);
    gl->glUseProgram(disk_program);
    auto set3 = [&](const char* name, const cv::Vec3f& c) {
      gl->glUniform3f(gl->glGetUniformLocation(disk_program, name), c[0], c[1], c[2]);
    };
    set3("face_color", kDiskFace);
    set3("ring_color", kRubber);
    set3("marker_color", kMarker);
    gl->glUniform1f(gl->glGetUniformLocation(disk_program, "ring_inner"), float(1.0 - kRingWidth));
    gl->glUniform1f(gl->glGetUniformLocation(disk_program, "marker_radius"), float(kMarkerRadius));
    gl->glUniform2f(gl->glGetUniformLocation(disk_program, "marker_center"), float(marker_offset),
                    0.0f);
    gl->glUniform1f(gl->glGetUniformLocation(disk_program, "hole"),
                    float(disk_radius > 0 ? hole_radius / disk_radius : 0.0));
  }

  void build_framebuffer() {
    gl->glGenFramebuffers(1, &fbo);
    gl->glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl->glGenRenderbuffers(1, &color_rb);
    gl->glBindRenderbuffer(GL_RENDERBUFFER, color_rb);
    gl->glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, fbo_width, fbo_height);
    gl->glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb);
    gl->glGenRenderbuffers(1, &depth_rb);
    gl->glBindRenderbuffer(GL_RENDERBUFFER, depth_rb);
    gl->glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, fbo_width, fbo_height);
    gl->glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb);
    if (gl->glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
      throw std::runtime_error("render: framebuffer " + std::to_string(fbo_width) + "x" +
                               std::to_string(fbo_height) + " is incomplete (too large?)");
  }

  Drawable upload(const Mesh& mesh) {
    Drawable d;
    gl->glGenVertexArrays(1, &d.vao);
    gl->glBindVertexArray(d.vao);
    gl->glGenBuffers(1, &d.vbo);
    gl->glBindBuffer(GL_ARRAY_BUFFER, d.vbo);
    gl->glBufferData(GL_ARRAY_BUFFER, static_cast<long>(mesh.size() * sizeof(Vertex)), mesh.data(),
                     GL_STATIC_DRAW);
    const int stride = sizeof(Vertex);
    gl->glEnableVertexAttribArray(0);
    gl->glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, p)));
    gl->glEnableVertexAttribArray(1);
    gl->glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, n)));
    gl->glEnableVertexAttribArray(2);
    gl->glVertexAttribPointer(2, 3, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, c)));
    gl->glEnableVertexAttribArray(3);
    gl->glVertexAttribPointer(3, 2, GL_FLOAT, GL_FALSE, stride,
                              reinterpret_cast<void*>(offsetof(Vertex, uv)));
    d.count = static_cast<int>(mesh.size());
    return d;
  }

  Drawable make_target(const camera::PlacedBoard& placed) {
    cv::Matx33d R;
    cv::Rodrigues(placed.rotation, R);
    const cv::Vec3d p = placed.position;
    const camera::Board& t = placed.board;
    if (t.kind == camera::Board::Kind::kChessboard) {
      Drawable back = upload(chessboard_background(t));
      back.model = rigid(R, p);
      back.behind = true;
      targets.push_back(back);
      Drawable squares = upload(chessboard_squares(t));
      squares.model = rigid(R, p);
      return squares;
    }
    // ChArUco: OpenCV draws the board (white margin of one square drawn by us as the quad's own
    // border is not needed: the board image covers exactly cols x rows squares).
    const int px_per_square = 40;
    const auto dict = cv::aruco::getPredefinedDictionary(
        cv::aruco::PREDEFINED_DICTIONARY_NAME(*camera::aruco_dictionary_id(t.dictionary)));
    const auto board = cv::aruco::CharucoBoard::create(
        t.squares_x, t.squares_y, static_cast<float>(t.square), static_cast<float>(t.marker), dict);
    cv::Mat image;
    board->draw(cv::Size(t.squares_x * px_per_square, t.squares_y * px_per_square), image, 0, 1);
    cv::Mat rgba;
    cv::cvtColor(image, rgba, cv::COLOR_GRAY2RGBA);
    Drawable d = upload(textured_quad(t.squares_x * t.square, t.squares_y * t.square));
    gl->glGenTextures(1, &d.texture);
    gl->glBindTexture(GL_TEXTURE_2D, d.texture);
    gl->glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    gl->glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, rgba.cols, rgba.rows, 0, GL_RGBA, GL_UNSIGNED_BYTE,
                     rgba.data);
    gl->glGenerateMipmap(GL_TEXTURE_2D);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    gl->glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    d.model = rigid(R, p);
    return d;
  }

  // Projection of the ideal pinhole camera, OpenCV pixel convention (centres at integers), with
  // image row v mapped to window row v so that glReadPixels returns rows top-down.
  cv::Matx44d projection() const {
    const double W = fbo_width, H = fbo_height, n = 0.01, f = 50.0;
    const cv::Matx33d& K = maps.ideal_K;
    return {2 * K(0, 0) / W,
            0,
            (2 * K(0, 2) + 1) / W - 1,
            0,
            0,
            2 * K(1, 1) / H,
            (2 * K(1, 2) + 1) / H - 1,
            0,
            0,
            0,
            (f + n) / (f - n),
            -2 * f * n / (f - n),
            0,
            0,
            1,
            0};
  }

  // Uniforms fixed for the renderer's life (camera, light), set on each program.
  void set_frame_uniforms(unsigned p) {
    gl->glUseProgram(p);
    const cv::Matx44f view = to_gl(rigid(camera.R, camera.t));
    const cv::Matx44f proj = to_gl(projection());
    gl->glUniformMatrix4fv(gl->glGetUniformLocation(p, "view"), 1, GL_FALSE, view.val);
    gl->glUniformMatrix4fv(gl->glGetUniformLocation(p, "projection"), 1, GL_FALSE, proj.val);
    gl->glUniform3f(gl->glGetUniformLocation(p, "light_direction"), float(kLight[0]),
                    float(kLight[1]), float(kLight[2]));
    const cv::Vec3d eye = camera.position_in_table();
    gl->glUniform3f(gl->glGetUniformLocation(p, "eye"), float(eye[0]), float(eye[1]),
                    float(eye[2]));
    gl->glUniform1f(gl->glGetUniformLocation(p, "ambient"), float(kAmbient));
  }

  void draw(const Drawable& d, float specular = 0.0f, unsigned use_program = 0) {
    const unsigned p = use_program ? use_program : d.texture ? textured_program : program;
    gl->glUseProgram(p);
    const Locations& loc = locations.at(p);
    const cv::Matx44f m = to_gl(d.model);
    gl->glUniformMatrix4fv(loc.model, 1, GL_FALSE, m.val);
    gl->glUniform1f(loc.specular, specular);
    if (d.texture) {
      gl->glUniform1i(gl->glGetUniformLocation(p, "board"), 0);
      gl->glActiveTexture(GL_TEXTURE0);
      gl->glBindTexture(GL_TEXTURE_2D, d.texture);
    }
    if (d.behind) {
      gl->glEnable(GL_POLYGON_OFFSET_FILL);
      gl->glPolygonOffset(1.0f, 4.0f);
    }
    gl->glBindVertexArray(d.vao);
    gl->glDrawArrays(GL_TRIANGLES, 0, d.count);
    if (d.behind) gl->glDisable(GL_POLYGON_OFFSET_FILL);
  }

  // Render the ideal (undistorted, supersampled) image into `readback` (BGRA, top row first).
  void render_ideal(const SceneState& st) {
    context->make_current();
    gl->glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    gl->glViewport(0, 0, fbo_width, fbo_height);
    gl->glEnable(GL_DEPTH_TEST);
    // The projection maps image rows top-down, which mirrors the window: counter-clockwise
    // triangles arrive clockwise.
    gl->glEnable(GL_CULL_FACE);
    gl->glFrontFace(GL_CW);
    // Where the table fills the whole view it is a uniformly lit plane: clearing to its colour
    // gives the same pixels as drawing it, without a full-screen fill.
    if (table_fills_view)
      gl->glClearColor(table_color[0], table_color[1], table_color[2], 1);
    else
      gl->glClearColor(0, 0, 0, 1);
    if (setup.spatial) {
      draw_spatial(st);
    } else {
      draw_table_scene(st);
    }
    gl->glPixelStorei(GL_PACK_ALIGNMENT, 4);
    // RGBA is llvmpipe's fastest read format (BGRA and BGR go through slower paths).
    gl->glReadPixels(0, 0, fbo_width, fbo_height, GL_RGBA, GL_UNSIGNED_BYTE, readback.data);
  }

  // A spatial scene: the hand's surface and the object at their poses, on a dark background.
  void draw_spatial(const SceneState& st) {
    if (!st.spatial) throw std::invalid_argument("render: a spatial scene's frame needs its poses");
    gl->glClearColor(kBackground[0], kBackground[1], kBackground[2], 1);
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    spatial_hand.model = rigid(st.spatial->hand_rotation, st.spatial->hand_position);
    draw(spatial_hand, 0.25f);
    spatial_object.model = rigid(st.spatial->object_rotation, st.spatial->object_position);
    draw(spatial_object, 0.3f);
  }

  void draw_table_scene(const SceneState& st) {
    gl->glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (!table_fills_view) draw(table);
    for (const Drawable& t : targets) draw(t);
    disk.model = rigid(rot_z(st.disk_angle), {st.disk_center.x, st.disk_center.y, 0});
    draw(disk);
    disk_top.model = disk.model;
    draw(disk_top, 0.0f, disk_program);
    hand.model = rigid(rot_z(st.hand_angle), {0, 0, 0});
    draw(hand, 0.25f);  // brushed aluminium: a soft highlight
  }

  // The geometric image: supersampled ideal render -> distortion remap -> area downsample.
  // The geometric image into `out`, reusing its memory when its size and type fit. The
  // supersampled intermediates are members and keep theirs too: fresh multi-megabyte buffers every
  // frame cost page faults (every allocation under AddressSanitizer, whose allocator maps each
  // large block anew, and any that glibc hands back to the system).
  void render_linear(const SceneState& st, cv::Mat& out) {
    render_ideal(st);
    cv::cvtColor(readback, ideal_bgr, cv::COLOR_RGBA2BGR);
    const bool distorted = camera.distorted();
    if (!distorted && supersample == 1) {
      ideal_bgr.convertTo(out, CV_32FC3);
      return;
    }
    ideal_bgr.convertTo(ideal_f32, CV_32FC3);
    if (!distorted) {
      downsample(ideal_f32, supersample, out);
      return;
    }
    cv::Mat& remapped = supersample == 1 ? out : distorted_f32;
    cv::remap(ideal_f32, remapped, maps.map_x, maps.map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    if (supersample > 1) downsample(distorted_f32, supersample, out);
  }

  cv::Mat render_linear(const SceneState& st) {
    cv::Mat out;
    render_linear(st, out);
    return out;
  }

  // Fast path for 8-bit frames without effects: no float conversion when nothing resamples.
  cv::Mat render_8u(const SceneState& st) {
    if (!camera.distorted()) {
      // Anti-aliasing by area averaging works as well on 8-bit samples (rounded once), and avoids
      // converting the supersampled image to float.
      // Only the returned frame is a new buffer: a process whose malloc hands large blocks back to
      // the system every time (the Python module's, measured: 0.8 ms more per 640 x 480 frame)
      // pays page faults for each one.
      render_ideal(st);
      const cv::Mat* small = &readback;
      if (supersample > 1) {
        cv::resize(readback, downsampled_rgba,
                   cv::Size(fbo_width / supersample, fbo_height / supersample), 0, 0,
                   cv::INTER_AREA);
        small = &downsampled_rgba;
      }
      cv::Mat bgr;
      cv::cvtColor(*small, bgr, cv::COLOR_RGBA2BGR);
      return bgr;
    }
    return quantize(render_linear(st));
  }

  FrameTruth truth(const SceneState& st) const {
    FrameTruth tr;
    tr.t = st.t;
    tr.theta = st.hand_angle;
    tr.s_h = st.s_h;
    if (st.spatial) {  // the object's centre (no marker: both are the centre)
      const cv::Vec3d c = st.spatial->object_position;
      tr.disk_center_table = tr.marker_table = {c[0], c[1], c[2]};
      tr.disk_center_px = tr.marker_px = camera.project(tr.disk_center_table);
      return tr;
    }
    const double z = setup.render.disk_thickness;
    tr.disk_center_table = {st.disk_center.x, st.disk_center.y, z};
    tr.marker_table = {st.disk_center.x + marker_offset * disk_radius * std::cos(st.disk_angle),
                       st.disk_center.y + marker_offset * disk_radius * std::sin(st.disk_angle), z};
    const auto px = camera.project(std::vector<cv::Point3d>{tr.disk_center_table, tr.marker_table});
    tr.disk_center_px = px[0];
    tr.marker_px = px[1];
    return tr;
  }
};

Renderer::Renderer(const RenderSetup& setup, std::optional<GlBackend> backend) {
  if (!setup.hand && !setup.spatial) throw std::invalid_argument("render: no hand to draw");
  const GlBackend chosen = backend ? *backend : parse_backend(setup.render.backend);
  impl_ = std::make_unique<Impl>(setup, chosen);
}

Renderer::~Renderer() = default;

const camera::CameraModel& Renderer::camera() const { return impl_->camera; }
std::string Renderer::gl_description() const { return impl_->context->description(); }
cv::Mat Renderer::render_linear(const SceneState& state) { return impl_->render_linear(state); }
cv::Mat Renderer::render_8u(const SceneState& state) { return impl_->render_8u(state); }
FrameTruth Renderer::truth(const SceneState& state) const { return impl_->truth(state); }

Frame Renderer::capture(const sim::Trajectory& trajectory, double t) {
  return capture(
      [&](double ts) {
        return SceneState::from_sample(
            trajectory.sample(std::clamp(ts, trajectory.t_begin(), trajectory.t_end())));
      },
      t);
}

Frame Renderer::capture(const StateAt& state_at, double t) {
  const EffectsSpec& fx = impl_->setup.effects;
  EffectsRng& rng = impl_->rng;
  Frame frame;
  const double t_capture = jittered_time(t, fx.jitter_s, rng);
  const SceneState mid = state_at(t_capture);
  frame.truth = impl_->truth(mid);
  frame.truth.t = t_capture;
  if (dropped(fx.drop_probability, rng)) {
    frame.truth.dropped = true;
    return frame;
  }
  const double exposure = impl_->camera.exposure;
  const bool one_render = !(fx.blur_subframes > 1 && exposure > 0);
  const bool plain = fx.blur_subframes <= 1 && fx.noise_read_dn == 0 && fx.noise_shot_gain == 0 &&
                     fx.vignetting == 0 && fx.quantize;
  // Without anything that makes a render's pixels fractional (blur, vignetting, supersampling,
  // distortion), the float frame holds whole numbers, and the noise goes straight onto the 8-bit
  // render: the same frame, bit for bit, without a float frame (apply_noise_8u).
  const bool whole_numbers = one_render && fx.vignetting == 0 && fx.quantize &&
                             impl_->supersample == 1 && !impl_->camera.distorted();
  if (plain || whole_numbers) {
    frame.image = impl_->render_8u(mid);
    apply_noise_8u(frame.image, fx.noise_read_dn, fx.noise_shot_gain, rng);
    return frame;
  }
  // The float image is the frame only when it is not quantised; otherwise it is scratch that the
  // renderer keeps from frame to frame (see render_linear).
  cv::Mat unquantized;
  cv::Mat& linear = fx.quantize ? impl_->linear_scratch : unquantized;
  if (!one_render) {
    // Exposure blur: equally weighted sub-frames over the exposure centred on the capture time,
    // each rendered into the same buffer and added to the running mean.
    FrameMean mean;
    for (int i = 0; i < fx.blur_subframes; ++i) {
      const double ts = t_capture - 0.5 * exposure + (i + 0.5) * exposure / fx.blur_subframes;
      impl_->render_linear(state_at(ts), impl_->subframe);
      mean.add(impl_->subframe);
    }
    linear = mean.finish();
  } else {
    impl_->render_linear(mid, linear);
  }
  if (fx.vignetting > 0)
    apply_vignetting(linear, fx.vignetting, {impl_->camera.K(0, 2), impl_->camera.K(1, 2)});
  apply_noise(linear, fx.noise_read_dn, fx.noise_shot_gain, rng);
  frame.image = fx.quantize ? quantize(linear) : linear;
  return frame;
}

}  // namespace flatland::render
