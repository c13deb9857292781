// A spatial scene's simulation from its spec: surfaces, object, motion, the start in contact and
// the run's options, each checked once with the field's path in the message.
#include "flatland/sim/spatial_spec.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace flatland::sim {

namespace {

[[noreturn]] void bad(const std::string& field, const std::string& reason) {
  throw std::invalid_argument(field + ": " + reason);
}

Vec3 vec(const std::array<double, 3>& a) { return {a[0], a[1], a[2]}; }

void require_positive(const std::string& field, double v) {
  if (!(v > 0) || !std::isfinite(v))
    bad(field, "must be positive and finite, got " + format_significant(v));
}

Eigen::Matrix3d rodrigues(const std::array<double, 3>& r) {
  const Vec3 v = vec(r);
  const double angle = v.norm();
  if (angle == 0) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, v / angle).toRotationMatrix();
}

SurfacePtr build_hand_surface(const SurfaceSpec& h) {
  switch (h.kind) {
    case SurfaceSpec::Kind::kPlane:
      return std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
    case SurfaceSpec::Kind::kSphere:
    case SurfaceSpec::Kind::kEllipsoid: {
      std::array<double, 3> axes = h.semi_axes;
      if (h.kind == SurfaceSpec::Kind::kSphere) {
        require_positive("hand.radius", h.radius);
        axes = {h.radius, h.radius, h.radius};
      } else {
        for (int i = 0; i < 3; ++i)
          require_positive("hand.semi_axes[" + std::to_string(i) + "]", axes[i]);
      }
      if (!(h.pole_margin > 0 && h.pole_margin < 1.5))
        bad("hand.pole_margin_deg", "must be in (0, 86] degrees, got " +
                                        format_significant(h.pole_margin * 180 / std::numbers::pi));
      return std::make_shared<EllipsoidSurface>(
          axes[0], axes[1], axes[2],
          h.inside ? EllipsoidSurface::Side::kDish : EllipsoidSurface::Side::kConvexBody,
          h.pole_margin);
    }
    case SurfaceSpec::Kind::kExtruded: {
      const HandSpec& p = h.polynomial;
      if (!std::isfinite(p.a) || !std::isfinite(p.b) || !std::isfinite(p.c) || !std::isfinite(p.d))
        bad("hand", "the polynomial's a, b, c, d must be finite");
      const auto curve = std::make_shared<PolynomialHand>(p.a, p.b, p.c, p.d);
      return std::make_shared<ExtrudedSurface>(curve, h.piece);
    }
  }
  bad("hand.surface", "unknown kind");
}

SpatialObject build_object(const SpatialObjectSpec& o) {
  require_positive("object.mass", o.mass);
  SpatialObject obj;
  if (o.kind == SpatialObjectSpec::Kind::kBall) {
    require_positive("object.radius", o.radius);
    obj = uniform_ball(o.radius, o.mass);
  } else {
    for (int i = 0; i < 3; ++i)
      require_positive("object.semi_axes[" + std::to_string(i) + "]", o.semi_axes[i]);
    obj = uniform_ellipsoid(o.semi_axes[0], o.semi_axes[1], o.semi_axes[2], o.mass);
    obj.surface = std::make_shared<EllipsoidSurface>(o.semi_axes[0], o.semi_axes[1], o.semi_axes[2],
                                                     EllipsoidSurface::Side::kConvexBody);
  }
  if (o.inertia) {
    const auto& I = *o.inertia;
    for (int i = 0; i < 3; ++i) require_positive("object.inertia[" + std::to_string(i) + "]", I[i]);
    // A rigid body's principal moments obey the triangle inequality.
    if (!(I[0] <= I[1] + I[2] && I[1] <= I[0] + I[2] && I[2] <= I[0] + I[1]))
      bad("object.inertia",
          "no rigid body has these principal moments (each must be at most "
          "the sum of the other two)");
    obj.inertia = vec(I).asDiagonal();
  }
  return obj;
}

std::shared_ptr<const HandMotion3> build_motion(const SpatialSpec& s) {
  const SpatialMotionSpec& m = s.motion;
  const Eigen::Matrix3d R0 = rodrigues(s.hand_rotation);
  const Vec3 p0 = vec(s.hand_position);
  switch (m.kind) {
    case SpatialMotionSpec::Kind::kFixed:
      return std::make_shared<FixedHand3>(R0, p0);
    case SpatialMotionSpec::Kind::kSpin:
      if (!(vec(m.axis).norm() > 0)) bad("motion.axis", "must be a non-zero vector");
      if (!std::isfinite(m.rate)) bad("motion.rate", "must be finite");
      return std::make_shared<SpinningHand3>(vec(m.axis), m.rate, vec(m.point), R0, p0);
    case SpatialMotionSpec::Kind::kButterfly: {
      std::shared_ptr<const HandMotion> planar;
      try {
        planar = std::make_shared<ButterflyMotion>(m.period, m.k);
      } catch (const std::invalid_argument& e) {
        bad("motion", e.what());
      }
      return std::make_shared<PlanarHand3>(planar, R0, p0);
    }
    case SpatialMotionSpec::Kind::kTabulated: {
      if (!(vec(m.axis).norm() > 0)) bad("motion.axis", "must be a non-zero vector");
      HandPose3 start;
      start.rotation = R0;
      start.position = p0;
      start.velocity = vec(m.velocity);
      try {
        return std::make_shared<TabulatedHand3>(m.rows, vec(m.axis), start, m.angular_velocity);
      } catch (const std::invalid_argument& e) {
        bad("motion.rows", e.what());
      }
    }
  }
  bad("motion.type", "unknown kind");
}

void check_integrator(const IntegratorSettings& is) {
  require_positive("integrator.rtol", is.rtol);
  require_positive("integrator.atol", is.atol);
  require_positive("integrator.step", is.fixed_step);
  if (!(is.max_step > 0)) bad("integrator.max_step", "must be positive");
}

}  // namespace

double SpatialSpec::end_time() const {
  if (duration) return *duration;
  if (motion.kind == SpatialMotionSpec::Kind::kButterfly) return motion.period;
  return 1.0;
}

SpatialSetup build_spatial(const SpatialSpec& spec) {
  SpatialSetup setup;
  const Vec3 g = vec(spec.gravity);
  if (!g.allFinite()) bad("gravity", "must be finite");
  setup.problem.gravity = g;
  setup.problem.hand = build_hand_surface(spec.hand);
  setup.problem.object = build_object(spec.object);
  if (spec.mu && !(*spec.mu >= 0 && std::isfinite(*spec.mu)))
    bad("contact.mu", "must be >= 0 and finite");
  setup.problem.mu = spec.mu;
  if (!vec(spec.hand_position).allFinite() || !vec(spec.hand_rotation).allFinite())
    bad("hand", "position and rotation must be finite");
  setup.motion = build_motion(spec);
  check_integrator(spec.integrator);
  const double t_end = spec.end_time();
  require_positive(spec.duration ? "duration" : "motion.period", t_end);
  require_positive("contact.event_tolerance", spec.event_tolerance);
  setup.t0 = 0;
  setup.options.t_end = t_end;
  setup.options.integrator = spec.integrator;
  setup.options.time_tolerance = spec.event_tolerance;
  setup.options.stop_on_contact_loss = spec.stop_on_contact_loss;
  try {
    setup.initial = place_in_contact(setup.problem, setup.motion->at(setup.t0), spec.initial);
    const SpatialState& s = setup.initial;
    if (!s.position.allFinite() || !s.velocity.allFinite() || !s.angular_velocity.allFinite() ||
        !s.sdot_o.allFinite() || !s.sdot_h.allFinite() || !s.orientation.coeffs().allFinite())
      bad("initial", "the start is not finite (a length, speed or rate too large to compute with)");
    // The start's physics (the fit of the curvatures, the rank of A, the patches) is checked by
    // the run itself: one short step, nothing recorded.
    SpatialRunOptions probe = setup.options;
    probe.t_end = setup.t0 + std::min(1e-9, t_end);
    probe.record = false;
    simulate_spatial(setup.problem, *setup.motion, setup.initial, setup.t0, probe);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    if (what.rfind("initial: ", 0) == 0) throw;
    bad("initial", what);
  } catch (const std::runtime_error& e) {  // the first step failed: the start cannot be run
    bad("initial", std::string("the run cannot start: ") + e.what());
  }
  return setup;
}

SpatialRunResult run_spatial(const SpatialSetup& setup) {
  return simulate_spatial(setup.problem, *setup.motion, setup.initial, setup.t0, setup.options);
}

}  // namespace flatland::sim
