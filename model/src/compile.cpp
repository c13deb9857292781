// The compile step: a Scene into a Model (model.hpp), its camera and boards (compile.hpp).
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"

#include "flatland/sim/spec.hpp"

#include <algorithm>
#include <array>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace flatland::model {

namespace {

[[noreturn]] void fail(const std::string& field, const std::string& reason) {
  throw std::invalid_argument(field + ": " + reason);
}

cv::Vec3d to_vec(const std::array<double, 3>& v) { return {v[0], v[1], v[2]}; }

}  // namespace

camera::CameraModel compile_camera(const CameraSpec& spec) {
  static_assert(kMaxCameraSide == camera::kMaxImageSide);
  if (auto problem = camera_problem(spec)) fail("camera." + problem->field, problem->reason);
  const cv::Vec3d position = to_vec(spec.position);
  const cv::Vec3d view = to_vec(spec.look_at) - position;
  const cv::Vec3d z_c = view / cv::norm(view);
  const cv::Vec3d up = to_vec(spec.up);
  const cv::Vec3d side = z_c.cross(up / cv::norm(up));
  const double side_norm = cv::norm(side);
  // x_c = z_c x up points to the image right when `up` is the image up: for a camera above the
  // origin looking down with up = +y this gives x_c = +x, y_c = z_c x x_c = -y (image rows grow
  // towards table -y), i.e. the natural overhead view with table +y up in the image.
  const cv::Vec3d x_c = side / side_norm;
  const cv::Vec3d y_c = z_c.cross(x_c);

  camera::CameraModel cam;
  cam.width = spec.width;
  cam.height = spec.height;
  cam.K = cv::Matx33d(spec.fx, 0, spec.cx, 0, spec.fy, spec.cy, 0, 0, 1);
  for (int i = 0; i < 5; ++i) cam.dist[i] = spec.distortion[static_cast<std::size_t>(i)];
  cam.R = cv::Matx33d(x_c[0], x_c[1], x_c[2], y_c[0], y_c[1], y_c[2], z_c[0], z_c[1], z_c[2]);
  cam.t = -(cam.R * position);
  cam.fps = spec.fps;
  cam.exposure = spec.exposure;
  return cam;
}

camera::PlacedBoard compile_target(const TargetSpec& target) {
  if (!camera::aruco_dictionary_id(target.dictionary))
    throw std::invalid_argument("targets.dictionary: unknown ArUco dictionary '" +
                                target.dictionary + "'");
  camera::PlacedBoard placed;
  placed.board.kind = target.kind == TargetSpec::Kind::kCharuco ? camera::Board::Kind::kCharuco
                                                                : camera::Board::Kind::kChessboard;
  placed.board.squares_x = target.squares_x;
  placed.board.squares_y = target.squares_y;
  placed.board.square = target.square;
  placed.board.marker = target.marker;
  placed.board.dictionary = target.dictionary;
  placed.position = {target.position[0], target.position[1], target.position[2]};
  placed.rotation = {target.rotation[0], target.rotation[1], target.rotation[2]};
  return placed;
}

namespace {

void compile_loop(Model& m) {
  const Scene& scene = m.spec;
  const EstimatorSpec& e = scene.estimator;
  control::EstimatorConfig& ec = m.estimator.config;
  m.estimator.type = e.type;
  ec.model = control::parse_estimator_model(e.model);
  ec.latency_compensation = e.latency_compensation;
  ec.process_noise = e.process_noise;
  m.estimator.ukf = {e.ukf.alpha, e.ukf.beta, e.ukf.kappa};
  // The estimator re-propagates from the capture time of a late frame: its history must reach
  // back past the worst latency and a frame or two.
  if (scene.camera)
    ec.history = std::max(ec.history, 3.0 * (scene.camera->latency + scene.camera->latency_jitter) +
                                          2.0 / scene.camera->fps);
  const auto& known_estimators = control::estimator_types();
  if (std::find(known_estimators.begin(), known_estimators.end(), e.type) == known_estimators.end())
    throw std::invalid_argument(
        scene.origin + ": " +
        control::unknown_type_message("estimator.type", e.type, known_estimators));

  const ControllerSpec& c = scene.controller;
  m.controller.type = c.type;
  m.controller.paper.feedback = c.mode == "feedback";
  m.controller.paper.law = control::parse_servo_law(c.law);
  m.controller.paper.kp = c.kp;
  m.controller.paper.kd = c.kd;
  m.controller.paper.dip_until = c.dip_until;
  m.controller.paper.finish_after = c.finish_after;
  m.controller.transverse.q = c.transverse.q;
  m.controller.transverse.r = c.transverse.r;
  m.controller.transverse.terminal = c.transverse.terminal;
  m.controller.transverse.grid_step = c.transverse.grid_step;
  const auto& known_controllers = control::controller_types();
  if (std::find(known_controllers.begin(), known_controllers.end(), c.type) ==
      known_controllers.end())
    throw std::invalid_argument(
        scene.origin + ": " +
        control::unknown_type_message("controller.type", c.type, known_controllers));
  // Open-loop playback is the plan without a law: the paper's controller's mode, no other type's.
  if (c.mode == "open-loop" && c.type != "paper")
    throw std::invalid_argument(scene.origin +
                                ": controller.mode: open-loop plays the plan "
                                "without feedback, which only controller.type paper does (got '" +
                                c.type + "')");
  m.control_dt = 1.0 / scene.joint.rate;
  m.safety.stop_deceleration = c.stop_deceleration;
  m.safety.lost_timeout = c.lost_timeout;
  m.safety.innovation_gate = c.innovation_gate;
  m.safety.innovation_strikes = c.innovation_strikes;
  m.safety.max_joint_jump = c.max_joint_jump;
}

void compile_vision(Model& m) {
  const Scene& scene = m.spec;
  if (!m.camera) return;
  // The tracked edge is the disk's top face.
  m.tracker.camera = *m.camera;
  m.tracker.plane_z = scene.render.disk_thickness;
  // The frame's time stamp is mid-exposure; what the image shows is the mean over the exposure
  // (and an interlaced frame's two fields): the tracker takes the difference off.
  const CameraSpec& cam = *scene.camera;
  m.tracker.image_time_variance_frames2 = vision::image_time_variance_frames2(
      cam.exposure, 1.0 / cam.fps, cam.readout.mode == "interlaced", 1.0 / cam.fps);
  if (!tracking_problem(scene.sim.object)) m.mapping = hand_mapping(m, *m.camera);
}

}  // namespace

std::optional<std::string> tracking_problem(const sim::ObjectSpec& object) {
  switch (object.kind) {
    case sim::ObjectSpec::Kind::kDisk:
      return std::nullopt;
    case sim::ObjectSpec::Kind::kBall:
      if (!object.rail_gap) return std::nullopt;
      return "object.rails: the tracker follows a disk's face seen whole; a ball on rails reaches "
             "between them, behind the hand, beyond its rolling radius";
    case sim::ObjectSpec::Kind::kRing:
      return "object.type: ring: the tracker follows a solid disk's face; a ring's hole is not in "
             "its model";
    case sim::ObjectSpec::Kind::kEllipse:
      break;
  }
  return "object.type: ellipse: the tracker and the mapping follow a disk's centre";
}

render::RenderSetup render_setup(const Model& model) {
  if (!model.camera)
    throw std::invalid_argument("camera: the scene has no camera section (needed to render)");
  return {*model.camera,         model.hand,          model.boards,
          model.spec.sim.object, model.spec.render,   model.spec.effects,
          std::nullopt,          model.spec.lighting, model.spec.camera->readout};
}

namespace {
/// The part of a spatial hand's chart drawn: a sphere or ellipsoid whole, a plane or an extruded
/// hand's piece out to render.table_extent.
sim::SurfacePatch spatial_hand_extent(const sim::SpatialSpec& spec, double extent) {
  const double pi = std::numbers::pi;
  switch (spec.hand.kind) {
    case sim::SurfaceSpec::Kind::kSphere:
    case sim::SurfaceSpec::Kind::kEllipsoid:
      return {{-pi, -pi / 2}, {pi, pi / 2}};
    case sim::SurfaceSpec::Kind::kExtruded: {  // along the outline, its piece (the patch)
      const double inf = std::numeric_limits<double>::infinity();
      return {{-inf, -extent}, {inf, extent}};
    }
    case sim::SurfaceSpec::Kind::kPlane:
      break;
  }
  return {{-extent, -extent}, {extent, extent}};
}
}  // namespace

render::RenderSetup spatial_render_setup(const Scene& scene, const sim::SpatialSetup& setup) {
  if (!scene.spatial) throw std::logic_error("spatial_render_setup: a planar scene");
  if (!scene.camera)
    throw std::invalid_argument(scene.origin +
                                ": camera: the scene has no camera section (needed to render)");
  const EffectsSpec& e = scene.effects;
  if (e.blur_subframes > 1 || e.noise_read_dn > 0 || e.noise_shot_gain > 0 || e.vignetting > 0 ||
      e.jitter_s > 0 || e.drop_probability > 0 || !e.quantize)
    throw std::invalid_argument(scene.origin +
                                ": effects: a spatial scene's frames have supersampling and the "
                                "camera's distortion only (blur, noise, vignetting, jitter, drops "
                                "and float images are not built for spatial scenes)");
  if (!scene.camera->readout.global())
    throw std::invalid_argument(scene.origin +
                                ": camera.readout: a spatial scene's frames are read globally (" +
                                scene.camera->readout.mode + " is built for planar scenes)");
  render::RenderSetup rs;
  rs.camera = compile_camera(*scene.camera);
  rs.render = scene.render;
  rs.effects = scene.effects;
  rs.spatial =
      render::SpatialBodies{setup.problem.hand, setup.problem.object.surface,
                            spatial_hand_extent(*scene.spatial, scene.render.table_extent)};
  return rs;
}

vision::HandMapping hand_mapping(const Model& model, const camera::CameraModel& camera,
                                 cv::Point2d axis_table) {
  const Scene& scene = model.spec;
  if (const auto problem = tracking_problem(scene.sim.object))
    throw std::invalid_argument(scene.origin + ": " + *problem);
  vision::HandMapping mapping;
  mapping.camera = camera;
  mapping.axis_table = axis_table;
  // The tracked edge lies on the disk's top face.
  mapping.plane_z = scene.render.disk_thickness;
  // The centre rides the hand's outline at the rolling radius (a ball on rails': below R).
  mapping.disk_radius = *model.plant->object.disk_radius;
  mapping.hand = model.hand;
  return mapping;
}

std::shared_ptr<const Model> compile(Scene scene) {
  if (scene.spatial)
    throw std::invalid_argument(scene.origin +
                                ": a spatial scene (space: 3d) compiles into no Model (no camera, "
                                "joint or controller in space yet); `flatland simulate` runs it");
  auto m = std::make_shared<Model>();
  m->spec = std::move(scene);
  const Scene& s = m->spec;
  m->plant = sim::build_problem(s.sim);
  m->hand = std::dynamic_pointer_cast<const sim::HandCurve>(m->plant->hand);
  if (!m->hand) throw std::logic_error("compile: the plant's hand is not a hand's outline");
  // The paper's model differs from the scene's in its contact law alone (no losses): the same
  // hand, object and motion, not built (and checked) twice.
  auto paper = std::make_shared<sim::RollingProblem>(*m->plant);
  paper->contact = sim::paper_model(s.sim).contact;
  m->paper_plant = std::move(paper);
  if (s.camera) m->camera = compile_camera(*s.camera);
  for (const TargetSpec& t : s.targets) m->boards.push_back(compile_target(t));
  compile_loop(*m);
  compile_vision(*m);
  return m;
}

}  // namespace flatland::model
