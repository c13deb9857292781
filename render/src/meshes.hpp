// The renderer's meshes: the table, the hand's plate, the disk, calibration boards and a spatial
// scene's surfaces, as triangles with their normals and colours, and the rigid transforms that
// place them.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/surface.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::render {

// Interleaved vertex: position, normal, colour, texture coordinate.
struct Vertex {
  float p[3], n[3], c[3], uv[2];
};
using Mesh = std::vector<Vertex>;

// Colours (linear RGB stored as BGR-free RGB; the shader output is read back as BGRA).
const cv::Vec3f kTable(0.20f, 0.22f, 0.25f);
const cv::Vec3f kAluminium(0.60f, 0.61f, 0.63f);
const cv::Vec3f kPivot(0.30f, 0.30f, 0.32f);
const cv::Vec3f kDiskFace(0.92f, 0.92f, 0.90f);
const cv::Vec3f kRubber(0.05f, 0.05f, 0.05f);
const cv::Vec3f kMarker(0.10f, 0.12f, 0.55f);
const cv::Vec3f kBall(0.92f, 0.92f, 0.90f);
const cv::Vec3f kBallCell(0.10f, 0.12f, 0.55f);
const cv::Vec3f kBackground(0.08f, 0.08f, 0.09f);

/// The hand's plate (hand_plate_outline extruded to `thickness`, with its pivot), or a circular
/// well's ring.
Mesh hand_mesh(const sim::HandCurve& hand, double thickness, double table_extent);
/// The disk's rubber side wall (its top is drawn by kDiskFragmentShader on disk_top_quad), and a
/// ring's inner wall around its hole (radius `hole` > 0, facing the centre).
Mesh disk_side_mesh(double r, double thickness, double hole = 0);
/// The disk's top face as one quad whose texture coordinates are disk-frame coordinates in radii.
Mesh disk_top_quad(double r, double thickness);
/// A surface's chart tessellated over `range` (nu x nv quads, flat-shaded), in a checkerboard of
/// `cells` cells of `color` and `cell_color` when cells > 0.
Mesh surface_mesh(const sim::Surface& surface, const sim::SurfacePatch& range, int nu, int nv,
                  const cv::Vec3f& color, int cells, const cv::Vec3f& cell_color);
/// The part of the hand's chart drawn: the extent asked for, its unbounded sides cut at the patch.
sim::SurfacePatch drawn_range(const sim::Surface& s, const sim::SurfacePatch& extent);
Mesh table_mesh(double extent);
/// The triangles of `mesh` whose normal is horizontal (an extruded body's walls): what casts its
/// shadow on the table (a ray from a table point outside the body into it crosses a wall).
Mesh walls_of(const Mesh& mesh);
/// A chessboard's white board (one square of margin) and its black squares, in the board plane.
Mesh chessboard_background(const camera::Board& t);
Mesh chessboard_squares(const camera::Board& t);
/// A quad w x h textured with a whole image (a ChArUco board).
Mesh textured_quad(double w, double h);

/// A row-major matrix in GL's column-major layout.
cv::Matx44f to_gl(const cv::Matx44d& m);
cv::Matx44d rigid(const cv::Matx33d& R, const cv::Vec3d& t);
cv::Matx33d rot_z(double a);

}  // namespace flatland::render
