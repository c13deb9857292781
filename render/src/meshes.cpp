#include "meshes.hpp"

#include "flatland/render/renderer.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <stdexcept>
#include <vector>

namespace flatland::render {

namespace {

void add_triangle(Mesh& m, const cv::Vec3d& a, const cv::Vec3d& b, const cv::Vec3d& c,
                  const cv::Vec3d& normal, const cv::Vec3f& color,
                  std::array<cv::Vec2f, 3> uv = {cv::Vec2f(0, 0), cv::Vec2f(0, 0),
                                                cv::Vec2f(0, 0)}) {
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

}  // namespace

Mesh hand_mesh(const sim::HandCurve& hand, double thickness, double table_extent) {
  if (const auto* well = dynamic_cast<const sim::CircleWellHand*>(&hand))
    return well_ring_mesh(*well, thickness);
  return plate_mesh(hand_plate_outline(hand, table_extent), thickness);
}

// The disk's rubber side wall (its top is drawn by kDiskFragmentShader on disk_top_quad), and a
// ring's inner wall around its hole (radius `hole` > 0, facing the centre).
Mesh disk_side_mesh(double r, double thickness, double hole) {
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

Mesh walls_of(const Mesh& mesh) {
  Mesh walls;
  for (std::size_t i = 0; i + 2 < mesh.size(); i += 3)
    if (std::abs(mesh[i].n[2]) < 0.5f) walls.insert(walls.end(), &mesh[i], &mesh[i] + 3);
  return walls;
}

// ---- spatial bodies ----

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

}  // namespace flatland::render
