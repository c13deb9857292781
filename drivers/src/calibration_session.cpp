// A synthetic calibration session rendered from a scene (calibration_session.hpp).
#include "flatland/drivers/calibration_session.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/model/model.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/curve.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numbers>
#include <optional>
#include <random>
#include <stdexcept>

namespace flatland::drivers {

using calibration::JointImage;
using calibration::TablePlacement;

// ---------------------------------------------------------------------------------------------
// A rendered session

namespace {

constexpr double kEdgeMarginPx = 12;  // every board corner (with its border) this far inside

struct SessionRenderer {
  const model::Model& model;
  const Scene& scene;  // model.spec
  const camera::CameraModel camera;
  std::uint64_t seed;
  std::uint64_t images = 0;
  std::unique_ptr<render::Renderer> renderer = nullptr;  // made at the first frame

  /// One 8-bit frame: the hand at `hand_angle`, the disk out of view, the given boards, with the
  /// scene's anti-aliasing and sensor noise.
  cv::Mat frame(double hand_angle, const std::vector<camera::PlacedBoard>& boards) {
    // One renderer for the session, its boards moved from view to view: a GL context and its
    // buffers made per view cost more than the view's render.
    if (!renderer) {
      Scene s = scene;
      s.targets.clear();
      renderer = std::make_unique<render::Renderer>(model::render_setup(*model::compile(s)));
    }
    renderer->set_boards(boards);
    render::SceneState st;
    st.hand_angle = hand_angle;
    st.disk_center = {50.0, 50.0};
    cv::Mat linear = renderer->render_linear(st);
    render::EffectsRng rng(seed * 1000003 + images++);
    render::apply_noise(linear, scene.effects.noise_read_dn, scene.effects.noise_shot_gain, rng);
    return render::quantize(linear);
  }

  /// The board's outer corners (with its printed border) in the image, or nullopt if any is
  /// off the image (by the margin) or behind the camera.
  std::optional<std::vector<cv::Point2d>> outline_px(const camera::PlacedBoard& t) const {
    cv::Matx33d R;
    cv::Rodrigues(t.rotation, R);
    const cv::Vec3d o = t.position;
    const camera::Board& b = t.board;
    const double m = b.kind == camera::Board::Kind::kChessboard ? b.square : 0.0;
    const double w = b.squares_x * b.square, h = b.squares_y * b.square;
    std::vector<cv::Point2d> out;
    for (const auto& [bx, by] : {std::pair{-m, -m}, {w + m, -m}, {w + m, h + m}, {-m, h + m}}) {
      const cv::Vec3d p = o + R * cv::Vec3d(bx, by, 0);
      const cv::Vec3d pc = camera.R * p + camera.t;
      if (!(pc[2] > 1e-3)) return std::nullopt;
      const cv::Point2d px = camera.project(cv::Point3d(p[0], p[1], p[2]));
      if (!(px.x > kEdgeMarginPx && px.y > kEdgeMarginPx &&
            px.x < camera.width - 1 - kEdgeMarginPx && px.y < camera.height - 1 - kEdgeMarginPx))
        return std::nullopt;
      out.push_back(px);
    }
    return out;
  }
};

// OpenCV's sample chessboard (9x6 inner corners), its square sized so that the board is about a
// quarter of the view's width on the table, to the millimetre.
camera::Board default_board(const camera::CameraModel& camera) {
  const double depth = std::abs(camera.t[2]);  // the table origin's depth
  const double view_width = camera.width * depth / camera.K(0, 0);
  camera::Board b;
  b.squares_x = 10;
  b.squares_y = 7;
  b.square = std::max(0.001, std::round(view_width / 40 * 1000) / 1000);
  return b;
}

// The hand turned to `angle`: its drawn plate's (render::hand_plate_outline) axis-aligned bounding
// box in the table frame, widened by `margin`.
cv::Rect2d hand_box(const sim::HandCurve& hand, double angle, double margin, double table_extent) {
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  const double c = std::cos(angle), s = std::sin(angle);
  for (const cv::Point2d& p : render::hand_plate_outline(hand, table_extent)) {
    const double x = c * p.x - s * p.y, y = s * p.x + c * p.y;
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
  return {x0 - margin, y0 - margin, x1 - x0 + 2 * margin, y1 - y0 + 2 * margin};
}

// A board facing the camera: its centre on the ray through a random pixel (not the outer tenth),
// at the depth at which it spans 35-60 % of the image width, tilted 15-40 deg about a random axis
// and turned in its plane by up to 0.5 rad.
camera::PlacedBoard random_facing_pose(const camera::CameraModel& cam, const camera::Board& board,
                                       std::mt19937_64& rng) {
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const double w = board.squares_x * board.square, h = board.squares_y * board.square;
  const double fraction = 0.35 + 0.25 * U(rng);
  const double depth = cam.K(0, 0) * w / (fraction * cam.width);
  const double u = cam.width * (0.1 + 0.8 * U(rng)), v = cam.height * (0.1 + 0.8 * U(rng));
  const cv::Vec3d centre_cam((u - cam.K(0, 2)) / cam.K(0, 0) * depth,
                             (v - cam.K(1, 2)) / cam.K(1, 1) * depth, depth);
  const double tilt = (15 + 25 * U(rng)) * std::numbers::pi / 180;
  const double phi = 2 * std::numbers::pi * U(rng);
  const double psi = U(rng) - 0.5;
  cv::Matx33d Rt, Rz;
  cv::Rodrigues(cv::Vec3d(tilt * std::cos(phi), tilt * std::sin(phi), 0), Rt);
  cv::Rodrigues(cv::Vec3d(0, 0, psi), Rz);
  // Board x along the image's x, board y up the image, its printed face towards the camera.
  const cv::Matx33d facing(1, 0, 0, 0, -1, 0, 0, 0, -1);
  const cv::Matx33d R_table = cam.R.t() * (Rt * facing * Rz);
  const cv::Vec3d centre = cam.R.t() * (centre_cam - cam.t);
  const cv::Vec3d origin = centre - R_table * cv::Vec3d(w / 2, h / 2, 0);
  cv::Vec3d rv;
  cv::Rodrigues(R_table, rv);
  camera::PlacedBoard t;
  t.board = board;
  t.position = origin;
  t.rotation = rv;
  return t;
}

// Lowest table height of a board's printed area (with border).
double lowest_z(const camera::PlacedBoard& t) {
  cv::Matx33d R;
  cv::Rodrigues(t.rotation, R);
  const camera::Board& b = t.board;
  const double m = b.square, w = b.squares_x * b.square, h = b.squares_y * b.square;
  double z = 1e9;
  for (double bx : {-m, w + m})
    for (double by : {-m, h + m}) z = std::min(z, (R * cv::Vec3d(bx, by, 0))[2] + t.position[2]);
  return z;
}

void check_count(int n, int lo, int hi, const std::string& name) {
  if (n < lo || n > hi)
    throw std::invalid_argument(name + ": must be in [" + std::to_string(lo) + ", " +
                                std::to_string(hi) + "], got " + std::to_string(n));
}

std::string numbered(const std::string& dir, const std::string& stem, int i) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "%02d", i);
  return dir + "/" + stem + "_" + buf + ".png";
}

// Table placements: random board positions and turns wholly in view and clear of the hand (turned
// to `hand_angle`), then `n` of them spread apart (each next the farthest from those chosen).
std::vector<TablePlacement> spread_placements(const SessionRenderer& sr, const camera::Board& board,
                                              double hand_angle, int n, std::mt19937_64& rng) {
  const Scene& scene = sr.scene;
  const double extent = scene.render.table_extent;
  const cv::Rect2d hand = hand_box(*sr.model.hand, hand_angle, board.square, extent);
  const double board_z = 0.0005;  // a printed sheet: half a millimetre thick
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::vector<TablePlacement> candidates;
  for (int attempt = 0; attempt < 20000 && candidates.size() < 400; ++attempt) {
    TablePlacement p;
    p.x = extent * (2 * U(rng) - 1);
    p.y = extent * (2 * U(rng) - 1);
    p.z = board_z;
    p.yaw = 0.6 * (U(rng) - 0.5) + (U(rng) < 0.5 ? 0.0 : std::numbers::pi);
    if (!sr.outline_px(p.placed(board))) continue;
    // The board's footprint on the table against the hand's box.
    const double c = std::cos(p.yaw), s = std::sin(p.yaw);
    const double w = board.squares_x * board.square, h = board.squares_y * board.square;
    double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
    for (double bx : {-board.square, w + board.square})
      for (double by : {-board.square, h + board.square}) {
        x0 = std::min(x0, p.x + c * bx - s * by);
        x1 = std::max(x1, p.x + c * bx - s * by);
        y0 = std::min(y0, p.y + s * bx + c * by);
        y1 = std::max(y1, p.y + s * bx + c * by);
      }
    if ((cv::Rect2d(x0, y0, x1 - x0, y1 - y0) & hand).area() > 0) continue;
    candidates.push_back(p);
  }
  if (static_cast<int>(candidates.size()) < n)
    throw std::invalid_argument(
        "table views: the camera sees too little of the table beside the hand for " +
        std::to_string(n) + " placements of the board " + board.notation() +
        " (use a smaller board or a wider view)");
  std::vector<TablePlacement> chosen;
  std::vector<double> distance(candidates.size(), 1e9);
  std::size_t next = 0;
  for (std::size_t i = 0; i < candidates.size(); ++i)  // start from the farthest out
    if (std::hypot(candidates[i].x, candidates[i].y) >
        std::hypot(candidates[next].x, candidates[next].y))
      next = i;
  while (static_cast<int>(chosen.size()) < n) {
    chosen.push_back(candidates[next]);
    for (std::size_t i = 0; i < candidates.size(); ++i)
      distance[i] = std::min(distance[i], std::hypot(candidates[i].x - candidates[next].x,
                                                     candidates[i].y - candidates[next].y));
    next = static_cast<std::size_t>(std::max_element(distance.begin(), distance.end()) -
                                    distance.begin());
  }
  return chosen;
}

}  // namespace

CalibrationSession render_calibration_session(const model::Model& model,
                                              const SessionOptions& options,
                                              const SessionImageSink& sink) {
  const Scene& scene = model.spec;
  if (!model.camera) throw std::invalid_argument(scene.origin + ": camera: missing");
  check_count(options.intrinsics_views, 3, 200, "intrinsics views");
  check_count(options.table_views, 1, 50, "table views");
  check_count(options.joint_views, 3, 100, "joint views");
  SessionRenderer sr{model, scene, *model.camera, options.seed};
  const camera::CameraModel& cam = sr.camera;

  CalibrationSession session;
  session.board = options.board.empty() ? default_board(cam) : camera::Board::parse(options.board);
  const camera::Board& board = session.board;
  // The table views are read by estimate_table_pose: a chessboard whose corners cannot be matched
  // the wrong way round.
  const cv::Size inner = board.pattern_size();
  if (board.kind != camera::Board::Kind::kChessboard || (inner.width + inner.height) % 2 == 0)
    throw std::invalid_argument(
        "--board: the table views need a chessboard whose inner-corner "
        "counts add to an odd number (e.g. chessboard:9x6:0.02), got " +
        board.notation());
  session.truth.camera_name = scene.name.empty() ? "flatland" : scene.name;
  session.truth.camera = cam;
  session.truth.has_table_pose = true;
  session.truth.joint = camera::JointCalibration{};
  std::mt19937_64 rng(options.seed);
  // The hand across the view while boards are in it: where a lab would turn it.
  const double hand_aside = std::numbers::pi / 2;

  // ---- intrinsics: the board held at random poses, above the hand, detected
  const double above = scene.render.hand_thickness + scene.render.disk_thickness + 0.01;
  int attempts = 0;
  while (static_cast<int>(session.intrinsics_images.size()) < options.intrinsics_views) {
    if (++attempts > 50 * options.intrinsics_views)
      throw std::invalid_argument("intrinsics views: no pose of the board " + board.notation() +
                                  " is wholly in view and detected (a board too large or too "
                                  "small for this camera?)");
    const camera::PlacedBoard t = random_facing_pose(cam, board, rng);
    if (!sr.outline_px(t) || lowest_z(t) < above) continue;
    const cv::Mat image = sr.frame(hand_aside, {t});
    if (!calibration::detect_board(image, board)) continue;
    const std::string name =
        numbered("intrinsics", "view", static_cast<int>(session.intrinsics_images.size()));
    sink(name, image);
    session.intrinsics_images.push_back(name);
  }

  // ---- table: the board lying flat at spread placements
  session.table = spread_placements(sr, board, hand_aside, options.table_views, rng);
  for (std::size_t i = 0; i < session.table.size(); ++i) {
    TablePlacement& p = session.table[i];
    p.image = numbered("table", "board", static_cast<int>(i));
    sink(p.image, sr.frame(hand_aside, {p.placed(board)}));
  }

  // ---- joint: the hand alone at encoder angles over a half turn (the encoder reads the truth)
  for (int i = 0; i < options.joint_views; ++i) {
    JointImage j;
    j.encoder = 0.05 + i * std::numbers::pi / options.joint_views;
    j.image = numbered("joint", "hand", i);
    sink(j.image, sr.frame(j.encoder, {}));
    session.joint.push_back(j);
  }
  return session;
}

}  // namespace flatland::drivers
