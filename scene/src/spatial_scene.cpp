// Spatial scenes: YAML -> sim::SpatialSpec, validated by building it once.
#include "spatial_scene.hpp"

#include "map_reader.hpp"

#include <numbers>
#include <vector>

namespace flatland::scene_detail {

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
// A tabulated motion's rows are bounded by the scene's size (1 MiB); this keeps a pathological
// file from building a huge table before anything else is checked.
constexpr std::size_t kMaxTableRows = 100000;

void read_hand(const MapReader& root, sim::SpatialSpec& spec) {
  const MapReader h =
      root.section("hand", {"surface", "side", "radius", "semi_axes", "pole_margin_deg", "a", "b",
                            "c", "d", "piece", "position", "rotation"});
  sim::SurfaceSpec& s = spec.hand;
  const std::string kind = h.choice("surface", {"plane", "sphere", "ellipsoid", "extruded"});
  const bool curved = kind == "sphere" || kind == "ellipsoid";
  if (!curved) {
    h.reject_if_present("side", "only for surface: sphere or ellipsoid");
    h.reject_if_present("pole_margin_deg", "only for surface: sphere or ellipsoid");
  }
  if (kind != "sphere") h.reject_if_present("radius", "only for surface: sphere");
  if (kind != "ellipsoid") h.reject_if_present("semi_axes", "only for surface: ellipsoid");
  if (kind != "extruded")
    for (const char* key : {"a", "b", "c", "d", "piece"})
      h.reject_if_present(key, "only for surface: extruded (the paper's hand)");
  if (kind == "plane") {
    s.kind = sim::SurfaceSpec::Kind::kPlane;
  } else if (curved) {
    s.kind =
        kind == "sphere" ? sim::SurfaceSpec::Kind::kSphere : sim::SurfaceSpec::Kind::kEllipsoid;
    s.inside = h.choice_or("side", {"outside", "inside"}, "outside") == "inside";
    if (kind == "sphere")
      s.radius = h.positive("radius");
    else {
      if (!h.has("semi_axes")) h.fail_at("semi_axes", "missing required key");
      s.semi_axes = h.numbers_or<3>("semi_axes", "[a, b, c]", {});
    }
    s.pole_margin = h.number_or("pole_margin_deg", s.pole_margin / kDegToRad) * kDegToRad;
  } else {
    s.kind = sim::SurfaceSpec::Kind::kExtruded;
    s.polynomial.a = h.number_or("a", s.polynomial.a);
    s.polynomial.b = h.number_or("b", s.polynomial.b);
    s.polynomial.c = h.number_or("c", s.polynomial.c);
    s.polynomial.d = h.number_or("d", s.polynomial.d);
    s.piece = static_cast<int>(h.integer_or("piece", -1000, 1000, 0));
  }
  spec.hand_position = h.numbers_or<3>("position", "[x, y, z]", spec.hand_position);
  spec.hand_rotation =
      h.numbers_or<3>("rotation", "[rx, ry, rz] (Rodrigues, rad)", spec.hand_rotation);
}

void read_object(const MapReader& root, sim::SpatialSpec& spec) {
  const MapReader o = root.section("object", {"type", "radius", "semi_axes", "mass", "inertia"});
  sim::SpatialObjectSpec& obj = spec.object;
  if (o.choice("type", {"ball", "ellipsoid"}) == "ball") {
    o.reject_if_present("semi_axes", "only for type: ellipsoid (a ball has `radius`)");
    obj.kind = sim::SpatialObjectSpec::Kind::kBall;
    obj.radius = o.positive("radius");
  } else {
    o.reject_if_present("radius", "only for type: ball (an ellipsoid has `semi_axes`)");
    obj.kind = sim::SpatialObjectSpec::Kind::kEllipsoid;
    if (!o.has("semi_axes")) o.fail_at("semi_axes", "missing required key");
    obj.semi_axes = o.numbers_or<3>("semi_axes", "[a, b, c]", {});
  }
  obj.mass = o.positive_or("mass", obj.mass);
  if (o.has("inertia"))
    obj.inertia = o.numbers_or<3>("inertia", "[Ixx, Iyy, Izz] (principal, kg m^2)", {});
}

std::vector<sim::TabulatedHand3::Row> read_rows(const MapReader& m) {
  if (!m.has("rows")) m.fail_at("rows", "missing required key");
  const YAML::Node rows = m.node("rows");
  if (!rows.IsSequence() || rows.size() < 2)
    m.fail_at("rows", "expected a list of at least two rows [t, ax, ay, az, alpha], got " +
                          (rows.IsSequence() ? "a list of " + std::to_string(rows.size())
                                             : describe(rows)));
  if (rows.size() > kMaxTableRows)
    m.fail_at("rows", "more than " + std::to_string(kMaxTableRows) + " rows");
  std::vector<sim::TabulatedHand3::Row> out;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const std::string where = m.field("rows") + "[" + std::to_string(i) + "]";
    const YAML::Node r = rows[i];
    if (!r.IsSequence() || r.size() != 5)
      fail(m.origin(), where,
           "expected [t, ax, ay, az, alpha] (s, m/s^2, rad/s^2), got " +
               (r.IsSequence() ? "a list of " + std::to_string(r.size()) : describe(r)));
    double v[5];
    for (std::size_t j = 0; j < 5; ++j)
      v[j] = m.to_number(r[j], where + "[" + std::to_string(j) + "]");
    if (i > 0 && !(v[0] > out.back().t))
      fail(m.origin(), where + "[0]", "times must increase strictly");
    out.push_back({v[0], sim::Vec3(v[1], v[2], v[3]), v[4]});
  }
  return out;
}

void read_motion(const MapReader& root, sim::SpatialSpec& spec) {
  const MapReader m = root.section("motion", {"type", "axis", "rate", "point", "period", "k",
                                              "rows", "velocity", "angular_velocity"});
  sim::SpatialMotionSpec& mo = spec.motion;
  const std::string type = m.choice("type", {"fixed", "spin", "butterfly", "tabulated"});
  const auto only = [&](std::initializer_list<const char*> keys, const char* types) {
    for (const char* key : keys) m.reject_if_present(key, std::string("only for type: ") + types);
  };
  if (type != "spin") only({"rate", "point"}, "spin");
  if (type != "spin" && type != "tabulated") only({"axis"}, "spin or tabulated");
  if (type != "butterfly") only({"period", "k"}, "butterfly");
  if (type != "tabulated") only({"rows", "velocity", "angular_velocity"}, "tabulated");
  if (type == "fixed") {
    mo.kind = sim::SpatialMotionSpec::Kind::kFixed;
  } else if (type == "spin") {
    mo.kind = sim::SpatialMotionSpec::Kind::kSpin;
    mo.axis = m.numbers_or<3>("axis", "[x, y, z]", mo.axis);
    mo.rate = m.number("rate");
    mo.point = m.numbers_or<3>("point", "[x, y, z]", mo.point);
  } else if (type == "butterfly") {
    mo.kind = sim::SpatialMotionSpec::Kind::kButterfly;
    mo.period = m.positive("period");
    mo.k = m.number("k");
  } else {
    mo.kind = sim::SpatialMotionSpec::Kind::kTabulated;
    mo.axis = m.numbers_or<3>("axis", "[x, y, z]", mo.axis);
    mo.rows = read_rows(m);
    mo.velocity = m.numbers_or<3>("velocity", "[vx, vy, vz]", mo.velocity);
    mo.angular_velocity = m.number_or("angular_velocity", 0.0);
  }
}

void read_initial(const MapReader& root, sim::SpatialSpec& spec) {
  const auto in = root.optional_section("initial", {"s_h", "s_o", "twist_deg", "velocity", "spin"});
  if (!in) return;
  sim::ContactPlacement& at = spec.initial;
  const auto sh = in->numbers_or<2>("s_h", "[u, v]", {at.s_h.x(), at.s_h.y()});
  const auto so = in->numbers_or<2>("s_o", "[u, v]", {at.s_o.x(), at.s_o.y()});
  at.s_h = sim::SurfaceParam(sh[0], sh[1]);
  at.s_o = sim::SurfaceParam(so[0], so[1]);
  at.twist = in->number_or("twist_deg", 0.0) * kDegToRad;
  const auto v = in->numbers_or<3>("velocity", "[vx, vy, vz]", {0.0, 0.0, 0.0});
  at.velocity = sim::Vec3(v[0], v[1], v[2]);
  at.spin = in->number_or("spin", 0.0);
}

void read_integrator(const MapReader& root, sim::SpatialSpec& spec) {
  const auto it = root.optional_section("integrator", {"method", "rtol", "atol", "step", "max_step",
                                                       "max_steps", "energy_tolerance"});
  if (it) read_integrator_settings(*it, spec.integrator);
}

void read_contact(const MapReader& root, sim::SpatialSpec& spec) {
  const auto c =
      root.optional_section("contact", {"mu", "stop_on_contact_loss", "event_tolerance"});
  if (!c) return;
  if (c->has("mu")) {
    const double mu = c->number("mu");
    if (!(mu >= 0)) c->fail_at("mu", "must be >= 0, got " + c->node("mu").Scalar());
    spec.mu = mu;
  }
  spec.stop_on_contact_loss = c->boolean_or("stop_on_contact_loss", spec.stop_on_contact_loss);
  spec.event_tolerance = c->positive_or("event_tolerance", spec.event_tolerance);
}

}  // namespace

bool is_spatial(const YAML::Node& document, const std::string& origin) {
  if (!document.IsMap() || !document["space"]) return false;
  const YAML::Node space = document["space"];
  if (space.IsScalar() && space.Scalar() == "3d") return true;
  if (space.IsScalar() && space.Scalar() == "2d") return false;
  fail(origin, "space", "unknown value " + describe(space) + " (allowed: 2d, 3d)");
}

sim::SpatialSpec read_spatial_scene(const MapReader& root, std::string& name) {
  const std::string& origin = root.origin();
  if (root.has("name")) name = root.text("name");
  sim::SpatialSpec spec;
  if (!root.has("gravity")) root.fail_at("gravity", "missing required key");
  spec.gravity = root.numbers_or<3>("gravity", "[gx, gy, gz] (m/s^2, world)", spec.gravity);
  read_hand(root, spec);
  read_object(root, spec);
  read_motion(root, spec);
  read_initial(root, spec);
  if (root.has("duration")) spec.duration = root.positive("duration");
  read_integrator(root, spec);
  read_contact(root, spec);
  try {
    sim::build_spatial(spec);
  } catch (const std::invalid_argument& e) {
    throw SceneError(one_line(origin + ": " + e.what()));
  }
  return spec;
}

}  // namespace flatland::scene_detail
