// Scene loading: YAML text -> validated sim::SimulationSpec. Schema, errors: docs/SCENE.md.
//
// Strictness is the point: a typo in a key or a unit must not silently fall back to a default and
// produce a plausible-looking but wrong simulation. Every error names the offending field and
// echoes what the file said, on one line, so it can be read in a terminal or a log.
#include "flatland/scene/scene.hpp"
#include "flatland/sim/format.hpp"
#include "map_reader.hpp"
#include "spatial_scene.hpp"

#include <yaml-cpp/eventhandler.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <limits>
#include <numbers>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace flatland {

namespace {

using namespace scene_detail;

constexpr double kDegToRad = std::numbers::pi / 180.0;
// Scene files are refused above this size, before they are parsed.
constexpr std::size_t kMaxSceneBytes = 1 << 20;
// A camera image and a supersampled frame: a frame of a few float images must fit in memory.
constexpr long long kMaxCameraPixels = 40000000;
constexpr long long kMaxRenderSamples = 67108864;  // 2^26, e.g. 4096 x 4096 at 2 x 2

void read_gravity(const MapReader& root, sim::SimulationSpec& spec) {
  const MapReader g = root.section("gravity", {"g", "tilt_deg"});
  spec.gravity = g.positive("g");
  const double tilt_deg = g.number_or("tilt_deg", 90.0);
  // Tilts above 90 degrees would just mirror gravity; 0 would leave nothing to roll.
  if (!(tilt_deg > 0 && tilt_deg <= 90))
    g.fail_at("tilt_deg", "must be in (0, 90] degrees, got " + g.node("tilt_deg").Scalar());
  spec.tilt = tilt_deg == 90.0 ? 0.5 * std::numbers::pi : tilt_deg * kDegToRad;
}

// hand.shape's keys: each shape's own, the others refused by name.
struct HandShapeKeys {
  const char* shape;
  std::initializer_list<const char*> keys;
};
constexpr std::array<HandShapeKeys, 5> kHandShapeKeys{{
    {"polynomial", {"a", "b", "c", "d"}},
    {"line", {"angle_deg", "origin"}},
    {"circle", {"radius", "center"}},
    {"points", {"file", "units", "closed", "smoothing", "palm_point", "back_point"}},
    {"polar", {"phi_deg", "r", "cos", "sin", "palm_phi_deg"}},
}};

// A list of finite numbers of at most `max_length` (a table or a series is short; the bound keeps
// a scene's memory bounded).
std::vector<double> number_list(const MapReader& m, const char* key, std::size_t max_length) {
  if (!m.has(key)) m.fail_at(key, "missing required key");
  const YAML::Node n = m.node(key);
  if (!n.IsSequence()) m.fail_at(key, "expected a list of numbers, got " + describe(n));
  if (n.size() > max_length)
    m.fail_at(
        key, "at most " + std::to_string(max_length) + " numbers, got " + std::to_string(n.size()));
  std::vector<double> v;
  for (std::size_t i = 0; i < n.size(); ++i)
    v.push_back(m.to_number(n[i], m.field(key) + "[" + std::to_string(i) + "]"));
  return v;
}

// A measured outline: the CSV's points are read now, relative to the scene file's folder.
void read_points_hand(const MapReader& h, sim::PointsHandSpec& points) {
  namespace fs = std::filesystem;
  const std::string file = h.text("file");
  fs::path path(file);
  if (path.is_relative()) path = fs::path(h.origin()).parent_path() / path;
  const std::string units = h.choice_or("units", {"m", "cm", "mm"}, "m");
  const double scale = units == "mm" ? 1e-3 : units == "cm" ? 1e-2 : 1.0;
  try {
    points.points = sim::read_hand_points_csv(path.string(), scale);
  } catch (const std::invalid_argument& e) {
    h.fail_at("file", e.what());
  }
  points.source = file;
  points.closed = h.boolean_or("closed", false);
  points.smoothing = h.number_or("smoothing", 0.0);
  if (points.smoothing < 0)
    h.fail_at("smoothing", "must be >= 0, got " + h.node("smoothing").Scalar());
  const long long palm = h.integer_or("palm_point", 0, 99999, -1);
  const long long back = h.integer_or("back_point", 0, 99999, -1);
  if ((palm < 0) != (back < 0))
    h.fail_at(palm < 0 ? "back_point" : "palm_point",
              "give both palm_point and back_point, or neither");
  if (palm >= 0 && !points.closed)
    h.fail_at("palm_point", "only for closed: true (an open half runs from the palm to the back)");
  if (palm >= 0) {
    points.palm_point = static_cast<std::size_t>(palm);
    points.back_point = static_cast<std::size_t>(back);
  }
}

// A polar frame: r(phi) as a table (phi_deg, r) or a Fourier series (cos, sin).
void read_polar_hand(const MapReader& h, sim::PolarHandSpec& polar) {
  constexpr std::size_t kMaxTableRows = 10000, kMaxTerms = 64;
  polar.palm_phi = h.number_or("palm_phi_deg", 90.0) * kDegToRad;
  if (h.has("phi_deg") || h.has("r")) {
    h.reject_if_present("cos", "a Fourier series instead of the table (phi_deg, r), not both");
    h.reject_if_present("sin", "a Fourier series instead of the table (phi_deg, r), not both");
    polar.form = sim::PolarHandSpec::Form::kTable;
    polar.phi = number_list(h, "phi_deg", kMaxTableRows);
    for (double& phi : polar.phi) phi *= kDegToRad;
    polar.r = number_list(h, "r", kMaxTableRows);
    if (polar.r.size() != polar.phi.size())
      h.fail_at("r", "one radius per angle of phi_deg (" + std::to_string(polar.phi.size()) +
                         "), got " + std::to_string(polar.r.size()));
  } else {
    polar.form = sim::PolarHandSpec::Form::kFourier;
    polar.cos_terms = number_list(h, "cos", kMaxTerms + 1);
    if (h.has("sin")) polar.sin_terms = number_list(h, "sin", kMaxTerms);
  }
}

void read_hand(const MapReader& root, sim::SimulationSpec& spec) {
  const MapReader h = root.section(
      "hand",
      {"shape",      "a",       "b",      "c",    "d",     "e",           "f",         "angle_deg",
       "origin",     "radius",  "center", "file", "units", "closed",      "smoothing", "palm_point",
       "back_point", "phi_deg", "r",      "cos",  "sin",   "palm_phi_deg"});
  // e and f are fixed by closing the outline (x(+-1) = 0, y'(+-1) = 0); a given value could only
  // disagree with a, b, c, d.
  h.reject_if_present("e", "is derived (e = -(a + c)), remove it");
  h.reject_if_present("f", "is derived (f = -(b + 3 d) / 5), remove it");
  const std::string shape = h.choice("shape", {"polynomial", "line", "circle", "points", "polar"});
  for (const HandShapeKeys& other : kHandShapeKeys)
    if (shape != other.shape)
      for (const char* key : other.keys)
        h.reject_if_present(key, std::string("only for shape: ") + other.shape);
  sim::HandSpec& hand = spec.hand;
  if (shape == "polynomial") {
    hand.shape = sim::HandSpec::Shape::kPolynomial;
    hand.a = h.number("a");
    hand.b = h.number("b");
    hand.c = h.number("c");
    hand.d = h.number("d");
  } else if (shape == "line") {
    hand.shape = sim::HandSpec::Shape::kLine;
    hand.line_angle = h.number_or("angle_deg", 0.0) * kDegToRad;
    const auto origin = h.numbers_or<2>("origin", "[x, y] (m)", {0.0, 0.0});
    hand.line_origin = sim::Vec2(origin[0], origin[1]);
  } else if (shape == "circle") {
    hand.shape = sim::HandSpec::Shape::kCircle;
    hand.well_radius = h.positive("radius");
    const auto center = h.numbers_or<2>("center", "[x, y] (m)", {0.0, 0.0});
    hand.well_center = sim::Vec2(center[0], center[1]);
  } else if (shape == "points") {
    hand.shape = sim::HandSpec::Shape::kPoints;
    read_points_hand(h, hand.points);
  } else {
    hand.shape = sim::HandSpec::Shape::kPolar;
    read_polar_hand(h, hand.polar);
  }
}

void read_ellipse_axes(const MapReader& o, sim::ObjectSpec& obj) {
  if (!o.has("semi_axes")) o.fail_at("semi_axes", "missing required key");
  const YAML::Node axes = o.node("semi_axes");
  if (!axes.IsSequence() || axes.size() != 2)
    o.fail_at("semi_axes", "expected a list of two numbers [x, y], got " +
                               (axes.IsSequence() ? "a list of " + std::to_string(axes.size())
                                                  : describe(axes)));
  double v[2];
  for (std::size_t i = 0; i < 2; ++i) {
    const std::string where = o.field("semi_axes") + "[" + std::to_string(i) + "]";
    v[i] = o.to_number(axes[i], where);
    if (!(v[i] > 0)) fail(o.origin(), where, "must be positive, got " + axes[i].Scalar());
  }
  obj.semi_axis_x = v[0];
  obj.semi_axis_y = v[1];
}

// A ball's keys: solid or hollow, and the rails it may ride on. The rolling radius and inertia
// they imply, and their bounds, are sim's (equivalent_disk), reported when the scene is built.
void read_ball(const MapReader& o, sim::ObjectSpec& obj) {
  obj.hollow = o.boolean_or("hollow", false);
  if (o.has("inertia") && o.has("hollow"))
    o.fail_at("hollow",
              "only chooses the default inertia (2/5 or 2/3 m R^2); remove it when "
              "object.inertia is given");
  if (const auto rails = o.optional_section("rails", {"gap"}))
    obj.rail_gap = rails->positive("gap");
}

void read_object(const MapReader& root, sim::SimulationSpec& spec) {
  const MapReader o = root.section("object", {"type", "radius", "inner_radius", "hollow", "rails",
                                              "semi_axes", "mass", "inertia"});
  auto& obj = spec.object;
  const std::string type = o.choice("type", {"disk", "ring", "ball", "ellipse"});
  if (type != "ring") o.reject_if_present("inner_radius", "only for type: ring");
  if (type != "ball") {
    o.reject_if_present("hollow", "only for type: ball");
    o.reject_if_present("rails", "only for type: ball (a ball riding on two rails)");
  }
  if (type == "ellipse") {
    o.reject_if_present("radius", "only for type: disk, ring, ball (an ellipse has `semi_axes`)");
    obj.kind = sim::ObjectSpec::Kind::kEllipse;
    read_ellipse_axes(o, obj);
  } else {
    o.reject_if_present("semi_axes", "only for type: ellipse (a " + type + " has `radius`)");
    obj.radius = o.positive("radius");
    if (type == "disk") {
      obj.kind = sim::ObjectSpec::Kind::kDisk;
    } else if (type == "ring") {
      obj.kind = sim::ObjectSpec::Kind::kRing;
      obj.inner_radius = o.positive("inner_radius");
    } else {
      obj.kind = sim::ObjectSpec::Kind::kBall;
      read_ball(o, obj);
    }
  }
  obj.mass = o.positive_or("mass", 1.0);
  if (o.has("inertia")) obj.inertia = o.positive("inertia");
}

void read_motion(const MapReader& root, sim::SimulationSpec& spec) {
  const MapReader m = root.section("motion", {"type", "period", "k", "angle_deg"});
  auto& mo = spec.motion;
  if (m.choice("type", {"butterfly", "fixed"}) == "butterfly") {
    m.reject_if_present("angle_deg", "only for type: fixed");
    mo.kind = sim::MotionSpec::Kind::kButterfly;
    mo.period = m.positive("period");
    mo.k = m.number("k");  // k = -2 is rejected by build_problem, which owns the motion's maths
  } else {
    m.reject_if_present("period", "only for type: butterfly");
    m.reject_if_present("k", "only for type: butterfly");
    mo.kind = sim::MotionSpec::Kind::kFixed;
    mo.angle = m.number_or("angle_deg", 0.0) * kDegToRad;
  }
}

void read_initial(const MapReader& root, sim::SimulationSpec& spec) {
  const auto in = root.optional_section("initial", {"s_h", "sdot_h", "s_o", "object_angle_deg"});
  if (!in) return;
  spec.initial.s_h = in->number_or("s_h", spec.initial.s_h);
  spec.initial.sdot_h = in->number_or("sdot_h", spec.initial.sdot_h);
  spec.initial.s_o = in->optional_number("s_o");
  spec.initial.object_angle = in->number_or("object_angle_deg", 0.0) * kDegToRad;
}

void read_integrator(const MapReader& root, sim::SimulationSpec& spec) {
  const auto it =
      root.optional_section("integrator", {"method", "rtol", "atol", "step", "max_step",
                                           "max_steps", "energy_tolerance", "formulation"});
  if (!it) return;
  read_integrator_settings(*it, spec.run.integrator);
  const std::string f = it->choice_or("formulation", {"auto", "general", "reduced"}, "auto");
  spec.run.formulation = f == "general"   ? sim::Formulation::kGeneral
                         : f == "reduced" ? sim::Formulation::kReduced
                                          : sim::Formulation::kAuto;
}

void read_contact(const MapReader& root, sim::SimulationSpec& spec) {
  const auto c =
      root.optional_section("contact", {"model", "mu", "mu_kinetic", "restitution",
                                        "capture_velocity", "rolling_resistance", "drag",
                                        "drag_angular", "stop_on_contact_loss", "event_tolerance"});
  if (!c) return;
  auto& ev = spec.run.events;
  auto& law = spec.contact;
  const bool hybrid = c->choice_or("model", {"rolling", "hybrid"}, "rolling") == "hybrid";
  spec.run.model = hybrid ? sim::ContactModel::kHybrid : sim::ContactModel::kRolling;
  const auto non_negative_key = [&](const char* key) -> std::optional<double> {
    if (!c->has(key)) return std::nullopt;
    const double v = c->number(key);
    if (!(v >= 0)) c->fail_at(key, "must be >= 0, got " + c->node(key).Scalar());
    return v;
  };
  law.mu = non_negative_key("mu");
  law.mu_kinetic = non_negative_key("mu_kinetic");
  if (law.mu_kinetic && !law.mu)
    c->fail_at("mu_kinetic", "needs contact.mu (the static coefficient it may not exceed)");
  if (law.mu_kinetic && !(*law.mu_kinetic <= *law.mu))
    c->fail_at("mu_kinetic", "must not exceed contact.mu (" + c->node("mu").Scalar() + "), got " +
                                 c->node("mu_kinetic").Scalar());
  if (c->has("restitution")) {
    law.restitution = c->number("restitution");
    if (!(law.restitution >= 0 && law.restitution <= 1))
      c->fail_at("restitution", "must be in [0, 1], got " + c->node("restitution").Scalar());
  }
  law.capture_velocity = non_negative_key("capture_velocity").value_or(law.capture_velocity);
  law.rolling_resistance = non_negative_key("rolling_resistance").value_or(0.0);
  law.drag = non_negative_key("drag").value_or(0.0);
  law.drag_angular = non_negative_key("drag_angular").value_or(0.0);
  if (!hybrid) {
    // The rolling model is the paper's: it enforces rolling and has no losses or impacts.
    for (const char* key : {"mu_kinetic", "restitution", "capture_velocity", "rolling_resistance",
                            "drag", "drag_angular"})
      c->reject_if_present(key,
                           "only for model: hybrid (the rolling model enforces rolling "
                           "without losses; it stops where contact is lost or it slips)");
  } else {
    c->reject_if_present("stop_on_contact_loss",
                         "only for model: rolling (the hybrid model flies where contact is lost)");
  }
  ev.stop_on_contact_loss = c->boolean_or("stop_on_contact_loss", ev.stop_on_contact_loss);
  ev.time_tolerance = c->positive_or("event_tolerance", ev.time_tolerance);
}

/// A number in [lo, hi] (bounds included).
double number_in(const MapReader& m, const char* key, double lo, double hi, double fallback) {
  if (!m.has(key)) return fallback;
  const double v = m.number(key);
  if (!(v >= lo && v <= hi))
    m.fail_at(key, "must be in [" + sim::format_number(lo) + ", " + sim::format_number(hi) +
                       "], got " + m.node(key).Scalar());
  return v;
}

double non_negative(const MapReader& m, const char* key, double fallback) {
  if (!m.has(key)) return fallback;
  const double v = m.number(key);
  if (!(v >= 0)) m.fail_at(key, "must be >= 0, got " + m.node(key).Scalar());
  return v;
}

// ---- camera, effects, render, targets (the renderer's plain data) ------------------------------

/// What the renderer's camera model needs (the rules are camera_problem's, below).
void read_camera(const MapReader& root, Scene& scene) {
  const auto c = root.optional_section(
      "camera", {"width", "height", "fx", "fy", "cx", "cy", "distortion", "position", "look_at",
                 "up", "fps", "exposure", "latency", "latency_jitter", "readout", "field_order",
                 "readout_time", "readout_band_rows"});
  if (!c) return;
  CameraSpec cam;
  cam.width = static_cast<int>(c->integer_or("width", 1, kMaxCameraSide, cam.width));
  cam.height = static_cast<int>(c->integer_or("height", 1, kMaxCameraSide, cam.height));
  // The renderer keeps a few float images of the frame: bounded, so that a frame fits in memory.
  if (static_cast<long long>(cam.width) * cam.height > kMaxCameraPixels)
    c->fail_at(
        "width",
        "width x height = " + std::to_string(static_cast<long long>(cam.width) * cam.height) +
            " px; at most " + std::to_string(kMaxCameraPixels) + " (8K, 7680 x 4320, is 33177600)");
  cam.fx = c->positive_or("fx", cam.fx);
  cam.fy = c->positive_or("fy", cam.fy);
  cam.cx = c->number_or("cx", 0.5 * (cam.width - 1));
  cam.cy = c->number_or("cy", 0.5 * (cam.height - 1));
  cam.distortion = c->numbers_or<5>("distortion", "[k1, k2, p1, p2, k3]", cam.distortion);
  cam.position = c->numbers_or<3>("position", "[x, y, z]", cam.position);
  cam.look_at = c->numbers_or<3>("look_at", "[x, y, z]", cam.look_at);
  cam.up = c->numbers_or<3>("up", "[x, y, z]", cam.up);
  cam.fps = c->positive_or("fps", cam.fps);
  cam.exposure = c->number_or("exposure", cam.exposure);
  cam.latency = non_negative(*c, "latency", cam.latency);
  cam.latency_jitter = non_negative(*c, "latency_jitter", cam.latency_jitter);
  if (!(cam.latency_jitter <= cam.latency))
    c->fail_at("latency_jitter", "must not exceed camera.latency (" +
                                     sim::format_number(cam.latency) +
                                     " s): a frame cannot arrive before it is taken, got " +
                                     c->node("latency_jitter").Scalar());
  ReadoutSpec& ro = cam.readout;
  ro.mode = c->choice_or("readout", {"global", "interlaced", "rolling"}, ro.mode.c_str());
  // A key of another readout would be silently ignored (even at its default value).
  for (const auto& [key, mode] :
       {std::pair{"field_order", "interlaced"}, std::pair{"readout_time", "rolling"},
        std::pair{"readout_band_rows", "rolling"}})
    if (c->has(key) && ro.mode != mode)
      c->fail_at(key, std::string("applies to camera.readout: ") + mode + " only (the readout is " +
                          ro.mode + ")");
  ro.field_order = c->choice_or("field_order", {"even_first", "odd_first"}, ro.field_order.c_str());
  ro.time = c->number_or("readout_time", ro.time);
  ro.band_rows =
      static_cast<int>(c->integer_or("readout_band_rows", 1, kMaxCameraSide, ro.band_rows));

  if (auto problem = camera_problem(cam)) c->fail_at(problem->field, problem->reason);
  scene.camera = cam;
}

void read_effects(const MapReader& root, Scene& scene) {
  const auto e = root.optional_section(
      "effects", {"supersample", "blur_subframes", "noise_read_dn", "noise_shot_gain", "quantize",
                  "vignetting", "jitter_s", "drop_probability", "seed"});
  if (!e) return;
  EffectsSpec& fx = scene.effects;
  fx.supersample = static_cast<int>(e->integer_or("supersample", 1, 8, fx.supersample));
  if (scene.camera && static_cast<long long>(scene.camera->width) * scene.camera->height *
                              fx.supersample * fx.supersample >
                          kMaxRenderSamples)
    e->fail_at("supersample",
               std::to_string(fx.supersample) + " x " + std::to_string(fx.supersample) +
                   " samples per pixel of a " + std::to_string(scene.camera->width) + " x " +
                   std::to_string(scene.camera->height) + " camera exceed " +
                   std::to_string(kMaxRenderSamples) + " rendered samples per frame");
  fx.blur_subframes = static_cast<int>(e->integer_or("blur_subframes", 1, 64, fx.blur_subframes));
  // Sub-frames spread over a zero exposure would all be the same image.
  if (fx.blur_subframes > 1 && !(scene.camera && scene.camera->exposure > 0))
    e->fail_at("blur_subframes",
               "exposure blur needs camera.exposure > 0 (got " +
                   (scene.camera ? sim::format_number(scene.camera->exposure) + " s"
                                 : std::string("no camera section")) +
                   ")");
  fx.noise_read_dn = non_negative(*e, "noise_read_dn", fx.noise_read_dn);
  fx.noise_shot_gain = non_negative(*e, "noise_shot_gain", fx.noise_shot_gain);
  fx.quantize = e->boolean_or("quantize", fx.quantize);
  fx.vignetting = number_in(*e, "vignetting", 0.0, 1.0, fx.vignetting);
  fx.jitter_s = non_negative(*e, "jitter_s", fx.jitter_s);
  fx.drop_probability = number_in(*e, "drop_probability", 0.0, 1.0, fx.drop_probability);
  fx.seed = static_cast<std::uint64_t>(e->integer_or(
      "seed", 0, std::numeric_limits<long long>::max(), static_cast<long long>(fx.seed)));
}

void read_render(const MapReader& root, Scene& scene) {
  const auto r = root.optional_section(
      "render", {"backend", "view", "hand_thickness", "disk_thickness", "table_extent"});
  if (!r) return;
  RenderSpec& rs = scene.render;
  rs.backend = r->choice_or("backend", {"osmesa", "egl"}, rs.backend.c_str());
  rs.view = r->choice_or("view", {"overhead", "side"}, rs.view.c_str());
  rs.hand_thickness = r->positive_or("hand_thickness", rs.hand_thickness);
  rs.disk_thickness = r->positive_or("disk_thickness", rs.disk_thickness);
  rs.table_extent = r->positive_or("table_extent", rs.table_extent);
}

void read_material(const MapReader& materials, const char* key, MaterialSpec& m) {
  const auto r = materials.optional_section(key, {"specular", "shininess"});
  if (!r) return;
  m.specular = r->number_or("specular", m.specular);
  m.shininess = r->number_or("shininess", m.shininess);
}

/// After `render`: the lamp is checked against the hand's and the disk's heights.
void read_lighting(const MapReader& root, Scene& scene) {
  const auto l = root.optional_section("lighting", {"position", "color", "intensity", "ambient",
                                                    "specular", "shadows", "falloff", "materials"});
  if (!l) return;
  LightingSpec ls;
  ls.position = l->numbers_or<3>("position", "[x, y, z]", ls.position);
  ls.color = l->numbers_or<3>("color", "[r, g, b]", ls.color);
  ls.intensity = l->number_or("intensity", ls.intensity);
  ls.ambient = l->number_or("ambient", ls.ambient);
  ls.specular = l->boolean_or("specular", ls.specular);
  ls.shadows = l->boolean_or("shadows", ls.shadows);
  ls.falloff = l->boolean_or("falloff", ls.falloff);
  if (const auto m = l->optional_section("materials", {"table", "hand", "face", "band"})) {
    read_material(*m, "table", ls.table);
    read_material(*m, "hand", ls.hand);
    read_material(*m, "face", ls.face);
    read_material(*m, "band", ls.band);
  }
  if (auto problem = lighting_problem(ls, scene.render))
    l->fail_at(problem->field, problem->reason);
  scene.lighting = ls;
}

// ---- joint, controller, estimator, faults (the closed loop's plain data) -----------------------

void read_joint(const MapReader& root, Scene& scene) {
  const auto j =
      root.optional_section("joint", {"inertia", "viscous", "coulomb", "torque_limit",
                                      "encoder_counts", "kp", "kd", "velocity_filter", "rate"});
  if (!j) return;
  JointSpec& js = scene.joint;
  js.inertia = j->positive_or("inertia", js.inertia);
  js.viscous = non_negative(*j, "viscous", js.viscous);
  js.coulomb = non_negative(*j, "coulomb", js.coulomb);
  js.torque_limit = j->positive_or("torque_limit", js.torque_limit);
  js.encoder_counts =
      static_cast<long>(j->integer_or("encoder_counts", 4, 1LL << 40, js.encoder_counts));
  js.kp = j->positive_or("kp", js.kp);
  js.kd = non_negative(*j, "kd", js.kd);
  js.velocity_filter = non_negative(*j, "velocity_filter", js.velocity_filter);
  js.rate = number_in(*j, "rate", 10.0, 1e5, js.rate);
  if (!(js.coulomb < js.torque_limit))
    j->fail_at("coulomb",
               "must be below joint.torque_limit (" + sim::format_number(js.torque_limit) +
                   " N m) or the joint cannot move, got " + sim::format_number(js.coulomb));
  // The PD loop runs at the servo rate; a discrete PD loop with omega dt near 1 rings or diverges.
  const double omega_dt = std::sqrt(js.kp / js.inertia) / js.rate;
  if (!(omega_dt < 0.5))
    j->fail_at("kp", "too stiff for the servo rate: sqrt(kp/inertia)/rate = " +
                         sim::format_number(omega_dt) + " (must be < 0.5)");
}

/// `controller.transverse`: the LQR's weights and grid (read whatever the type, as the paper's keys
/// are; only type transverse uses them).
void read_transverse(const MapReader& controller, TransverseSpec& ts) {
  const auto t = controller.optional_section("transverse", {"q", "r", "terminal", "grid_step"});
  if (!t) return;
  const auto diagonal = [&](const char* key, std::array<double, 3>& weights) {
    weights = t->numbers_or<3>(key, "(theta, theta_dot, sdot_h)", weights);
    for (std::size_t i = 0; i < 3; ++i)
      if (!(weights[i] >= 0))
        t->fail_at(std::string(key) + "[" + std::to_string(i) + "]",
                   "must be >= 0, got " + sim::format_number(weights[i]));
  };
  diagonal("q", ts.q);
  diagonal("terminal", ts.terminal);
  ts.r = t->positive_or("r", ts.r);
  ts.grid_step = t->positive_or("grid_step", ts.grid_step);
  if (ts.grid_step > 0.01)
    t->fail_at("grid_step", "must be at most 0.01 s, got " + t->node("grid_step").Scalar());
}

void read_controller(const MapReader& root, Scene& scene) {
  const auto c = root.optional_section(
      "controller", {"type", "mode", "plan", "law", "kp", "kd", "dip_until", "finish_after",
                     "lost_timeout", "innovation_gate", "innovation_strikes", "max_joint_jump",
                     "stop_deceleration", "settle", "transverse"});
  if (!c) return;
  ControllerSpec& cs = scene.controller;
  // The type names a law compiled from the registry of control (model::compile checks it).
  if (c->has("type")) cs.type = c->text("type");
  cs.mode = c->choice_or("mode", {"feedback", "open-loop"}, cs.mode.c_str());
  cs.plan = c->choice_or("plan", {"scene", "solve"}, cs.plan.c_str());
  cs.law = c->choice_or("law", {"paper", "time-scaled"}, cs.law.c_str());
  cs.kp = c->positive_or("kp", cs.kp);
  cs.kd = non_negative(*c, "kd", cs.kd);
  cs.dip_until = number_in(*c, "dip_until", -1.0, 1.0, cs.dip_until);
  cs.finish_after = number_in(*c, "finish_after", -1.0, 1.0, cs.finish_after);
  if (!(cs.dip_until < cs.finish_after))
    c->fail_at("finish_after", "must exceed controller.dip_until (" +
                                   sim::format_number(cs.dip_until) + "), got " +
                                   sim::format_number(cs.finish_after));
  cs.lost_timeout = c->positive_or("lost_timeout", cs.lost_timeout);
  cs.innovation_gate = c->positive_or("innovation_gate", cs.innovation_gate);
  cs.innovation_strikes =
      static_cast<int>(c->integer_or("innovation_strikes", 1, 1000, cs.innovation_strikes));
  cs.max_joint_jump = c->positive_or("max_joint_jump", cs.max_joint_jump);
  cs.stop_deceleration = c->positive_or("stop_deceleration", cs.stop_deceleration);
  cs.settle = non_negative(*c, "settle", cs.settle);
  read_transverse(*c, cs.transverse);
}

void read_estimator(const MapReader& root, Scene& scene) {
  const auto e = root.optional_section(
      "estimator", {"type", "model", "latency_compensation", "process_noise", "ukf"});
  if (!e) return;
  EstimatorSpec& es = scene.estimator;
  // The type names a filter of control's registry (model::compile checks it).
  if (e->has("type")) es.type = e->text("type");
  es.model = e->choice_or("model", {"rolling", "constant-velocity"}, es.model.c_str());
  es.latency_compensation = e->boolean_or("latency_compensation", es.latency_compensation);
  es.process_noise = e->positive_or("process_noise", es.process_noise);
  if (const auto u = e->optional_section("ukf", {"alpha", "beta", "kappa"})) {
    // The bounds of control::Ukf's check, reported here with the field's path and the file.
    es.ukf.alpha = number_in(*u, "alpha", 1e-4, 1.0, es.ukf.alpha);
    es.ukf.beta = non_negative(*u, "beta", es.ukf.beta);
    es.ukf.kappa = non_negative(*u, "kappa", es.ukf.kappa);
  }
}

void read_faults(const MapReader& root, Scene& scene) {
  const auto f = root.optional_section(
      "faults", {"camera_stop", "camera_stall", "occlusion", "occlusion_duration", "encoder_glitch",
                 "encoder_glitch_size"});
  if (!f) return;
  FaultSpec& fs = scene.faults;
  const auto time = [&](const char* key) -> std::optional<double> {
    if (!f->has(key)) return std::nullopt;
    return non_negative(*f, key, 0.0);
  };
  fs.camera_stop = time("camera_stop");
  fs.camera_stall = time("camera_stall");
  fs.occlusion = time("occlusion");
  fs.occlusion_duration = f->positive_or("occlusion_duration", fs.occlusion_duration);
  fs.encoder_glitch = time("encoder_glitch");
  fs.encoder_glitch_size = f->number_or("encoder_glitch_size", fs.encoder_glitch_size);
}

/// OpenCV's predefined ArUco dictionaries (cv::aruco::PREDEFINED_DICTIONARY_NAME), by name.
constexpr const char* kArucoDictionaries[] = {
    "DICT_4X4_50",         "DICT_4X4_100",       "DICT_4X4_250",       "DICT_4X4_1000",
    "DICT_5X5_50",         "DICT_5X5_100",       "DICT_5X5_250",       "DICT_5X5_1000",
    "DICT_6X6_50",         "DICT_6X6_100",       "DICT_6X6_250",       "DICT_6X6_1000",
    "DICT_7X7_50",         "DICT_7X7_100",       "DICT_7X7_250",       "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL", "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10",
    "DICT_APRILTAG_36h11"};

void read_targets(const MapReader& root, Scene& scene) {
  if (!root.has("targets")) return;
  const YAML::Node list = root.node("targets");
  if (!list.IsSequence())
    root.fail_at("targets",
                 "expected a list of targets (- type: chessboard ...), got " + describe(list));
  for (std::size_t i = 0; i < list.size(); ++i) {
    const MapReader m(
        list[i], "targets[" + std::to_string(i) + "]", root.origin(),
        {"type", "cols", "rows", "square", "marker", "dictionary", "position", "rotation"});
    TargetSpec t;
    const bool charuco = m.choice("type", {"chessboard", "charuco"}) == "charuco";
    t.kind = charuco ? TargetSpec::Kind::kCharuco : TargetSpec::Kind::kChessboard;
    // Counted as OpenCV counts them: a chessboard by its inner corners (cv::findChessboardCorners'
    // patternSize), a ChArUco board by its squares (cv::aruco::CharucoBoard). Either way 9 x 6.
    constexpr long long kMaxSquares = 1000;
    const int corner_count = charuco ? 0 : 1;  // squares = count + 1 for a chessboard
    t.squares_x = corner_count + static_cast<int>(m.integer_or("cols", 2 - corner_count,
                                                               kMaxSquares - corner_count, 9));
    t.squares_y = corner_count + static_cast<int>(m.integer_or("rows", 2 - corner_count,
                                                               kMaxSquares - corner_count, 6));
    t.square = m.positive_or("square", t.square);
    if (charuco) {
      // The default keeps the struct's proportion (0.015 m markers on 0.02 m squares).
      t.marker = m.positive_or("marker", 0.75 * t.square);
      if (!(t.marker < t.square))
        m.fail_at("marker",
                  "must be smaller than the square (" + sim::format_number(t.square) + " m), got " +
                      (m.has("marker") ? m.node("marker").Scalar() : sim::format_number(t.marker)));
      if (m.has("dictionary")) {
        const std::string d = m.text("dictionary");
        const auto known =
            std::find_if(std::begin(kArucoDictionaries), std::end(kArucoDictionaries),
                         [&](const char* k) { return d == k; });
        if (known == std::end(kArucoDictionaries)) {
          std::string allowed;
          for (const char* k : kArucoDictionaries)
            allowed += std::string(allowed.empty() ? "" : ", ") + k;
          m.fail_at("dictionary", "unknown value '" + d + "' (allowed: " + allowed + ")");
        }
        t.dictionary = d;
      }
    } else {
      m.reject_if_present("marker", "only for type: charuco");
      m.reject_if_present("dictionary", "only for type: charuco");
    }
    t.position = m.numbers_or<3>("position", "[x, y, z]", t.position);
    t.rotation = m.numbers_or<3>("rotation", "[rx, ry, rz]", t.rotation);
    scene.targets.push_back(t);
  }
}

/// Counts documents without building them. yaml-cpp 0.7's YAML::LoadAll loops forever, allocating
/// a null document per turn, on some malformed streams (a directive line such as "%}", found by
/// fuzzing: tests/fuzz/regressions/scene/; upstream jbeder/yaml-cpp#1319): its parser reports
/// document after document without consuming input. A scene is one document, so counting stops at
/// two, and YAML::Load, which parses only the first, builds it.
class DocumentCounter : public YAML::EventHandler {
 public:
  void OnDocumentStart(const YAML::Mark&) override {}
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark&, YAML::anchor_t) override {}
  void OnAlias(const YAML::Mark&, YAML::anchor_t) override {}
  void OnScalar(const YAML::Mark&, const std::string&, YAML::anchor_t,
                const std::string&) override {}
  void OnSequenceStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                       YAML::EmitterStyle::value) override {}
  void OnSequenceEnd() override {}
  void OnMapStart(const YAML::Mark&, const std::string&, YAML::anchor_t,
                  YAML::EmitterStyle::value) override {}
  void OnMapEnd() override {}
};

int count_documents_up_to_two(const std::string& text) {
  std::istringstream in(text);
  YAML::Parser parser(in);
  DocumentCounter counter;
  int n = 0;
  while (n < 2 && parser.HandleNextDocument(counter)) ++n;
  return n;
}

}  // namespace

namespace {

/// camera_problem's rules for the readout (ReadoutSpec).
std::optional<FieldProblem> readout_problem(const CameraSpec& cam) {
  const ReadoutSpec& ro = cam.readout;
  const auto problem = [](std::string field, std::string reason) {
    return std::optional<FieldProblem>(FieldProblem{std::move(field), std::move(reason)});
  };
  const bool interlaced = ro.mode == "interlaced", rolling = ro.mode == "rolling";
  if (!ro.global() && !interlaced && !rolling)
    return problem("readout", "must be global, interlaced or rolling, got '" + ro.mode + "'");
  if (ro.field_order != "even_first" && ro.field_order != "odd_first")
    return problem("field_order", "must be even_first or odd_first, got '" + ro.field_order + "'");
  // A field is exposed within its own field interval: the next field starts 1/(2 fps) later.
  if (interlaced && !(cam.exposure <= 0.5 / cam.fps))
    return problem("exposure",
                   "an interlaced field's exposure must not exceed the field interval "
                   "1/(2 fps) = " +
                       sim::format_number(0.5 / cam.fps) + " s, got " +
                       sim::format_number(cam.exposure));
  if (!rolling) {
    if (ro.time != 0)
      return problem("readout_time",
                     "applies to camera.readout: rolling only (the readout is " + ro.mode + ")");
    if (ro.band_rows != 1)
      return problem("readout_band_rows",
                     "applies to camera.readout: rolling only (the readout is " + ro.mode + ")");
    return std::nullopt;
  }
  // The last row is read before the next frame's first.
  if (!(ro.time > 0) || !(ro.time <= 1.0 / cam.fps))
    return problem("readout_time", "a rolling readout's time must be in (0, 1/fps = " +
                                       sim::format_number(1.0 / cam.fps) + "] s, got " +
                                       sim::format_number(ro.time));
  if (ro.band_rows < 1 || ro.band_rows > cam.height)
    return problem("readout_band_rows",
                   "must be in [1, camera.height = " + std::to_string(cam.height) + "], got " +
                       std::to_string(ro.band_rows));
  return std::nullopt;
}

}  // namespace

std::optional<FieldProblem> camera_problem(const CameraSpec& cam) {
  const auto problem = [](std::string field, std::string reason) {
    return std::optional<FieldProblem>(FieldProblem{std::move(field), std::move(reason)});
  };
  const auto size_rule = "must be in [1, " + std::to_string(kMaxCameraSide) + "] px, got ";
  if (cam.width < 1 || cam.width > kMaxCameraSide)
    return problem("width", size_rule + std::to_string(cam.width));
  if (cam.height < 1 || cam.height > kMaxCameraSide)
    return problem("height", size_rule + std::to_string(cam.height));
  // `!(x > 0)` rather than `x <= 0` so that NaN breaks the rule too.
  if (!(cam.fx > 0) || !std::isfinite(cam.fx))
    return problem("fx", "must be positive and finite, got " + sim::format_number(cam.fx));
  if (!(cam.fy > 0) || !std::isfinite(cam.fy))
    return problem("fy", "must be positive and finite, got " + sim::format_number(cam.fy));
  if (!std::isfinite(cam.cx))
    return problem("cx", "must be finite, got " + sim::format_number(cam.cx));
  if (!std::isfinite(cam.cy))
    return problem("cy", "must be finite, got " + sim::format_number(cam.cy));
  for (double d : cam.distortion)
    if (!std::isfinite(d))
      return problem("distortion", "coefficients must be finite, got " + sim::format_number(d));
  if (!(cam.fps > 0) || !std::isfinite(cam.fps))
    return problem("fps", "must be positive and finite, got " + sim::format_number(cam.fps));
  const auto vec3 = [](const std::array<double, 3>& v) {
    return "(" + sim::format_number(v[0]) + ", " + sim::format_number(v[1]) + ", " +
           sim::format_number(v[2]) + ")";
  };
  for (const auto& [field, v] : {std::pair{"position", &cam.position},
                                 std::pair{"look_at", &cam.look_at}, std::pair{"up", &cam.up}})
    for (double x : *v)
      if (!std::isfinite(x)) return problem(field, "must be finite, got " + vec3(*v));
  if (!(cam.position[2] > 0))
    return problem("position", "the camera must be above the table (z > 0), got z = " +
                                   sim::format_number(cam.position[2]));
  const double view[3] = {cam.look_at[0] - cam.position[0], cam.look_at[1] - cam.position[1],
                          cam.look_at[2] - cam.position[2]};
  const double view_len = std::hypot(view[0], view[1], view[2]);
  if (!(view_len > 1e-9))
    return problem("look_at", "must differ from camera.position (the camera looks nowhere)");
  // Looking level or upwards would put the table plane behind the camera (or at the horizon).
  if (!(view[2] < 0))
    return problem("look_at", "must be below the camera so that the table is in front of it, got " +
                                  vec3(cam.look_at) + " from camera.position " +
                                  vec3(cam.position));
  const double up_len = std::hypot(cam.up[0], cam.up[1], cam.up[2]);
  if (!(up_len > 0)) return problem("up", "must not be the zero vector");
  // |view x up| / (|view| |up|) = sin of the angle between them; below ~0.06 deg the image's
  // orientation would hinge on rounding.
  const double cross[3] = {view[1] * cam.up[2] - view[2] * cam.up[1],
                           view[2] * cam.up[0] - view[0] * cam.up[2],
                           view[0] * cam.up[1] - view[1] * cam.up[0]};
  if (!(std::hypot(cross[0], cross[1], cross[2]) > 1e-6 * view_len * up_len))
    return problem("up", "must not be parallel to the viewing direction (look_at - position)");
  if (!(cam.exposure >= 0))
    return problem("exposure", "must be >= 0 s, got " + sim::format_number(cam.exposure));
  if (!(cam.exposure <= 1.0 / cam.fps))
    return problem("exposure", "must not exceed the frame interval 1/fps = " +
                                   sim::format_number(1.0 / cam.fps) + " s, got " +
                                   sim::format_number(cam.exposure));
  return readout_problem(cam);
}

std::optional<FieldProblem> lighting_problem(const LightingSpec& lighting,
                                             const RenderSpec& render) {
  const auto& p = lighting.position;
  for (std::size_t i = 0; i < 3; ++i)
    if (!std::isfinite(p[i]))
      return FieldProblem{"position[" + std::to_string(i) + "]", "must be finite"};
  // A lamp at or below the hand's or the disk's top would light them from the side or from below:
  // its shadows would not fall on the table as a projection through them.
  const double top = std::max(render.hand_thickness, render.disk_thickness);
  if (!(p[2] > top))
    return FieldProblem{"position", "the lamp must be above the hand and the disk (z > " +
                                        sim::format_number(top) +
                                        " m, their top), got z = " + sim::format_number(p[2])};
  for (std::size_t i = 0; i < 3; ++i)
    if (!(lighting.color[i] >= 0 && lighting.color[i] <= 1))
      return FieldProblem{"color[" + std::to_string(i) + "]",
                          "must be in [0, 1], got " + sim::format_number(lighting.color[i])};
  if (!(lighting.intensity >= 0 && std::isfinite(lighting.intensity)))
    return FieldProblem{"intensity",
                        "must be finite and >= 0, got " + sim::format_number(lighting.intensity)};
  if (!(lighting.ambient >= 0 && lighting.ambient <= 1))
    return FieldProblem{"ambient",
                        "must be in [0, 1], got " + sim::format_number(lighting.ambient)};
  const std::pair<const char*, const MaterialSpec*> materials[] = {{"table", &lighting.table},
                                                                   {"hand", &lighting.hand},
                                                                   {"face", &lighting.face},
                                                                   {"band", &lighting.band}};
  for (const auto& [name, m] : materials) {
    if (!(m->specular >= 0 && m->specular <= 1))
      return FieldProblem{std::string("materials.") + name + ".specular",
                          "must be in [0, 1], got " + sim::format_number(m->specular)};
    if (!(m->shininess >= 1 && m->shininess <= 1e4))
      return FieldProblem{std::string("materials.") + name + ".shininess",
                          "must be in [1, 10000], got " + sim::format_number(m->shininess)};
  }
  return std::nullopt;
}

Scene parse_scene(const std::string& yaml_text, const std::string& origin) {
  if (yaml_text.size() > kMaxSceneBytes)
    fail(origin, "(document)", "larger than 1 MiB; a scene is a few kB");
  std::vector<YAML::Node> docs;
  try {
    const int count = count_documents_up_to_two(yaml_text);
    if (count > 1)
      fail(origin, "(document)",
           "contains several YAML documents (a '---' line?); a scene is exactly one");
    if (count == 1) docs.push_back(YAML::Load(yaml_text));
  } catch (const YAML::Exception& e) {
    // yaml-cpp marks are 0-based; editors count from 1.
    std::string where = e.mark.is_null() ? std::string("(document)")
                                         : "line " + std::to_string(e.mark.line + 1) + ", column " +
                                               std::to_string(e.mark.column + 1);
    fail(origin, where, "invalid YAML: " + e.msg);
  }
  if (docs.empty()) fail(origin, "(document)", "empty scene (expected a mapping of sections)");

  Scene scene;
  scene.origin = origin;
  if (is_spatial(docs.front(), origin)) {
    const MapReader root(docs.front(), "", origin, kSpatialSceneKeys);
    scene.spatial = read_spatial_scene(root, scene.name);
    read_camera(root, scene);
    read_effects(root, scene);
    read_render(root, scene);
    return scene;
  }
  const MapReader root(docs.front(), "", origin,
                       {"name", "space", "gravity", "hand", "object", "motion", "initial",
                        "duration", "integrator", "contact", "camera", "effects", "render",
                        "lighting", "targets", "joint", "controller", "estimator", "faults"});
  if (root.has("name")) scene.name = root.text("name");
  sim::SimulationSpec& spec = scene.sim;
  read_gravity(root, spec);
  read_hand(root, spec);
  read_object(root, spec);
  read_motion(root, spec);
  read_initial(root, spec);
  if (root.has("duration")) spec.duration = root.positive("duration");
  read_integrator(root, spec);
  read_contact(root, spec);
  read_camera(root, scene);
  read_effects(root, scene);  // after the camera: exposure blur needs its exposure
  read_render(root, scene);
  read_lighting(root, scene);  // after render: the lamp above the hand's and the disk's tops
  read_targets(root, scene);
  read_joint(root, scene);
  read_controller(root, scene);
  read_estimator(root, scene);
  read_faults(root, scene);

  // Physics that needs more than one field (hand shape against the disk, k = -2, inertia bounds,
  // formulation against the object) is validated where it is implemented; its messages already
  // start with the field path.
  try {
    const auto problem = sim::build_problem(spec);
    sim::resolve_formulation(*problem, spec.run.formulation);
  } catch (const std::invalid_argument& e) {
    throw SceneError(one_line(origin + ": " + e.what()));
  }
  return scene;
}

Scene load_scene(const std::string& path) {
  // C stdio rather than ifstream: errno is reliably set, so the error can say why.
  const auto unreadable = [&](int err) {
    return SceneError(one_line(path + ": cannot read scene file (" + std::strerror(err) + ")"));
  };
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw unreadable(errno);
  std::string text;
  char buf[8192];
  std::size_t n;
  // A scene is a few kB; reading stops past the limit, so /dev/zero or a huge file costs no more.
  while (text.size() <= kMaxSceneBytes && (n = std::fread(buf, 1, sizeof buf, f)) > 0)
    text.append(buf, n);
  // A directory opens fine on Linux and only fails here, with EISDIR.
  const bool bad = std::ferror(f);
  const int err = errno;
  std::fclose(f);
  if (bad) throw unreadable(err);
  if (text.size() > kMaxSceneBytes)
    throw SceneError(one_line(path + ": (document): larger than 1 MiB; a scene is a few kB"));
  return parse_scene(text, path);
}

std::string data_directory() {
  namespace fs = std::filesystem;
  std::vector<fs::path> places;
  if (const char* env = std::getenv("FLATLAND_DATA_DIR"); env && *env) places.emplace_back(env);
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    places.push_back(self.parent_path() / ".." / "share" / "flatland");         // PREFIX/bin
    places.push_back(self.parent_path() / ".." / ".." / "share" / "flatland");  // PREFIX/libexec/x
  }
  places.emplace_back(FLATLAND_INSTALL_DATA_DIR);
  for (const fs::path& p : places)
    if (fs::is_regular_file(p / "scenes" / "butterfly.yaml", ec))
      return p.lexically_normal().string();
  // Nothing found: the first place, so that loading names where the scenes were expected.
  return places.front().lexically_normal().string();
}

std::string default_scene_path() { return data_directory() + "/scenes/butterfly.yaml"; }

}  // namespace flatland
