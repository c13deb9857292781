// The hybrid contact model (sim/hybrid.hpp) against closed forms: rolling or sliding on a straight
// incline, a sliding launch that starts rolling, the parabola of a flight, bounces and the spin an
// impact gives; energy over randomised runs with the hand held still; events at the instant a
// violation appears; the general and the reduced formulation through a slip and a throw.
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/spec.hpp"

#include "test_scale.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

using namespace flatland::sim;

namespace {

using flatland_test::kG;
constexpr double kR = 0.05;

std::shared_ptr<RollingProblem> problem(CurvePtr hand, std::shared_ptr<const HandMotion> motion,
                                        double g = kG) {
  auto pb = std::make_shared<RollingProblem>();
  pb->hand = std::move(hand);
  pb->object = make_uniform_disk(kR);
  pb->motion = std::move(motion);
  pb->gravity = g;
  return pb;
}

/// A flat hand along x (the free side up), held still.
std::shared_ptr<RollingProblem> level(double g = kG) {
  return problem(std::make_shared<LineCurve>(Vec2::Zero(), Vec2(1, 0)),
                 std::make_shared<FixedHand>(0.0), g);
}

RunOptions hybrid(double t_end, Formulation f = Formulation::kReduced) {
  RunOptions o;
  o.t_end = t_end;
  o.formulation = f;
  o.model = ContactModel::kHybrid;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  return o;
}

/// The disk in flight with its centre at p, velocity v, spin w.
HybridState flying(Vec2 p, Vec2 v, double w = 0) {
  HybridState x;
  x.mode = ContactMode::kFlight;
  x.position = p;
  x.velocity = v;
  x.angular_velocity = w;
  return x;
}

std::vector<RecordedEvent> events_of(const RunResult& r, EventKind kind) {
  std::vector<RecordedEvent> out;
  for (const RecordedEvent& e : r.events)
    if (e.kind == kind) out.push_back(e);
  return out;
}

double energy(const Sample& s, const RollingProblem& pb) {
  return 0.5 * pb.object.mass * s.object_velocity.squaredNorm() +
         0.5 * pb.object.inertia * s.object_angular_velocity * s.object_angular_velocity +
         pb.object.mass * pb.gravity * s.object_position.y();
}

class Formulations : public ::testing::TestWithParam<Formulation> {};

}  // namespace

// A uniform disk on a fixed straight incline of angle alpha needs |f_t| / f_n = tan(alpha) / 3 to
// roll: it rolls without slip exactly when mu >= tan(alpha) / 3.
TEST_P(Formulations, InclineRollsExactlyWhenMuReachesTanAlphaOverThree) {
  const double alpha = 0.3, threshold = std::tan(alpha) / 3.0;
  auto pb =
      problem(std::make_shared<LineCurve>(Vec2::Zero(), Vec2(std::cos(alpha), -std::sin(alpha))),
              std::make_shared<FixedHand>(0.0));
  pb->contact.mu = threshold * (1 + 1e-8);
  const RunResult rolls = simulate(pb, InitialContact{}, hybrid(0.5, GetParam()));
  EXPECT_TRUE(events_of(rolls, EventKind::kSlipStart).empty());
  EXPECT_EQ(rolls.final.mode, ContactMode::kRolling);
  EXPECT_NEAR(rolls.mu_required / threshold - 1, 0, 1e-9);

  pb->contact.mu = threshold * (1 - 1e-8);
  const RunResult slides = simulate(pb, InitialContact{}, hybrid(0.5, GetParam()));
  const auto slips = events_of(slides, EventKind::kSlipStart);
  ASSERT_EQ(slips.size(), 1u);
  EXPECT_EQ(slips[0].t, 0.0);  // at the start, not at a later sign change
  EXPECT_EQ(slides.final.mode, ContactMode::kSliding);
}

// Below that, the centre accelerates at g (sin alpha - mu_k cos alpha) and the spin at
// 2 mu_k g cos(alpha) / r (the static coefficient only decides that it slides).
TEST_P(Formulations, SlidingDownAnInclineFollowsCoulomb) {
  const double alpha = 0.3, mu_k = 0.05, t = 0.8;
  auto pb =
      problem(std::make_shared<LineCurve>(Vec2::Zero(), Vec2(std::cos(alpha), -std::sin(alpha))),
              std::make_shared<FixedHand>(0.0));
  pb->contact.mu = 0.08;
  pb->contact.mu_kinetic = mu_k;
  InitialContact at_origin;
  at_origin.s_h = 0;
  const RunResult r = simulate(pb, at_origin, hybrid(t, GetParam()));
  ASSERT_EQ(r.final.mode, ContactMode::kSliding);
  const double a = kG * (std::sin(alpha) - mu_k * std::cos(alpha));
  const double spin = 2.0 * mu_k * kG * std::cos(alpha) / kR;
  EXPECT_NEAR(r.final.s_h / (0.5 * a * t * t) - 1, 0, 1e-8);  // s is arc length on a line
  EXPECT_NEAR(r.final.sdot_h / (a * t) - 1, 0, 1e-8);
  // Friction acts uphill at the contact, below the centre: it spins the disk the way it rolls
  // downhill (clockwise, negative).
  EXPECT_NEAR(r.final.object_angular_velocity / (-spin * t) - 1, 0, 1e-8);
  EXPECT_NEAR(std::abs(r.final.force_tangential) / (mu_k * r.final.force_normal) - 1, 0, 1e-10);
}

// A disk launched sliding without spin on a level surface starts rolling at t = v0 / (3 mu g),
// with speed 2 v0 / 3, and rolls on at that speed.
TEST_P(Formulations, SlidingLaunchStartsRollingAtTheClosedForm) {
  const double v0 = 2.0, mu = 0.2;
  auto pb = level();
  pb->contact.mu = mu;
  HybridState x;
  x.mode = ContactMode::kSliding;
  x.sdot_h = v0;
  x.s_o = -0.5 * std::numbers::pi;  // the disk's lowest point (general formulation)
  x.position = {0, kR};
  x.velocity = {v0, 0};
  const RunResult r = simulate_hybrid(pb, x, hybrid(0.6, GetParam()));
  const auto sticks = events_of(r, EventKind::kStick);
  ASSERT_EQ(sticks.size(), 1u);
  const double t_roll = v0 / (3 * mu * kG);
  EXPECT_NEAR(sticks[0].t / t_roll - 1, 0, 1e-8);
  EXPECT_NEAR(r.trajectory.sample(t_roll).sdot_h / (2 * v0 / 3) - 1, 0, 1e-8);
  EXPECT_EQ(r.final.mode, ContactMode::kRolling);
  EXPECT_NEAR(r.final.sdot_h / (2 * v0 / 3) - 1, 0, 1e-8);
  EXPECT_NEAR(r.final.object_angular_velocity, -r.final.sdot_h / kR, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(Hybrid, Formulations,
                         ::testing::Values(Formulation::kReduced, Formulation::kGeneral),
                         [](const auto& info) { return to_string(info.param); });

// Flight in the table plane (tilted 5 degrees) is a parabola with constant spin, and the landing
// on a level hand is found where the closed form puts it.
TEST(Hybrid, FlightIsAParabolaWithConstantSpinAndLandsOnTime) {
  const double g = kG * std::sin(5.0 * std::numbers::pi / 180.0);
  auto pb = level(g);
  pb->contact.mu = 0.5;
  pb->contact.restitution = 0.5;
  const Vec2 p0(0.0, 0.3), v0(0.4, 0.5);
  const double w0 = 3.0;
  const RunResult r = simulate_hybrid(pb, flying(p0, v0, w0), hybrid(2.0));
  const double t_land = (v0.y() + std::sqrt(v0.y() * v0.y() + 2 * g * (p0.y() - kR))) / g;
  const auto impacts = events_of(r, EventKind::kImpact);
  ASSERT_FALSE(impacts.empty());
  EXPECT_NEAR(impacts[0].t / t_land - 1, 0, 1e-8);
  for (double t : {0.05, 0.3, 0.5 * t_land, 0.99 * t_land}) {
    const Sample s = r.trajectory.sample(t);
    EXPECT_EQ(s.mode, ContactMode::kFlight);
    EXPECT_NEAR(s.object_position.x(), p0.x() + v0.x() * t, 1e-12);
    EXPECT_NEAR(s.object_position.y(), p0.y() + v0.y() * t - 0.5 * g * t * t, 1e-12);
    EXPECT_NEAR(s.object_angle, w0 * t, 1e-12);
    EXPECT_NEAR(s.object_angular_velocity, w0, 1e-12);
    EXPECT_NEAR(s.gap, p0.y() + v0.y() * t - 0.5 * g * t * t - kR, 1e-12);
    EXPECT_EQ(s.force_normal, 0.0);
  }
}

// Dropped without friction on a level hand, the disk bounces to e^2 of its height; the next
// impact comes 2 e v / g later; its spin and horizontal velocity do not change.
TEST(Hybrid, FrictionlessDropBouncesToRestitutionSquaredOfItsHeight) {
  const double h = 0.1, e = 0.6;
  auto pb = level();
  pb->contact.mu = 0.0;
  pb->contact.restitution = e;
  const RunResult r = simulate_hybrid(pb, flying({0, kR + h}, {0.1, 0}, 2.0), hybrid(0.6));
  const auto impacts = events_of(r, EventKind::kImpact);
  ASSERT_GE(impacts.size(), 2u);
  const double t1 = std::sqrt(2 * h / kG), v = std::sqrt(2 * kG * h);
  EXPECT_NEAR(impacts[0].t / t1 - 1, 0, 1e-8);
  EXPECT_NEAR(impacts[0].impact->vn_after / (e * v) - 1, 0, 1e-8);
  EXPECT_NEAR(impacts[1].t / (t1 + 2 * e * v / kG) - 1, 0, 1e-8);
  const Sample apex = r.trajectory.sample(t1 + e * v / kG);
  EXPECT_NEAR((apex.object_position.y() - kR) / (e * e * h) - 1, 0, 1e-8);
  EXPECT_NEAR(apex.object_velocity.x(), 0.1, 1e-12);
  EXPECT_NEAR(apex.object_angular_velocity, 2.0, 1e-12);
  EXPECT_FALSE(impacts[0].caught);
  // Kinetic energy lost in the bounce: (1 - e^2) of the normal part.
  EXPECT_NEAR(impacts[0].energy_change / (-(1 - e * e) * 0.5 * v * v) - 1, 0, 1e-8);
}

// The spin an impact gives, from the impulse law's closed form for a uniform disk on a level hand
// hit at (vx, -vy) without spin: a sliding impulse (small mu) gives
// omega = -2 mu (1 + e) vy / r and vx' = vx - mu (1 + e) vy; a sticking one (large mu) ends the
// slip, vx' = 2 vx / 3 and omega = -2 vx / (3 r), whatever e.
TEST(Hybrid, SpinAfterAFrictionalImpactMatchesTheImpulseLaw) {
  const double vx = 0.5, vy0 = 1.0, h = 0.02, e = 0.5;
  const double vy = std::sqrt(vy0 * vy0 + 2 * kG * h);  // at the impact
  for (double mu : {0.05, 1.0}) {
    auto pb = level();
    pb->contact.mu = mu;
    pb->contact.restitution = e;
    const RunResult r = simulate_hybrid(pb, flying({0, kR + h}, {vx, -vy0}), hybrid(0.1));
    const auto impacts = events_of(r, EventKind::kImpact);
    ASSERT_FALSE(impacts.empty());
    const Sample after = r.trajectory.sample(impacts[0].t);  // right after: the next part
    if (mu < 0.1) {
      EXPECT_FALSE(impacts[0].impact->sticking);
      EXPECT_NEAR(after.object_angular_velocity / (-2 * mu * (1 + e) * vy / kR) - 1, 0, 1e-9);
      EXPECT_NEAR(after.object_velocity.x() / (vx - mu * (1 + e) * vy) - 1, 0, 1e-9);
    } else {
      EXPECT_TRUE(impacts[0].impact->sticking);
      EXPECT_NEAR(after.object_angular_velocity / (-2 * vx / (3 * kR)) - 1, 0, 1e-9);
      EXPECT_NEAR(after.object_velocity.x() / (2 * vx / 3) - 1, 0, 1e-9);
    }
    EXPECT_NEAR(after.object_velocity.y() / (e * vy) - 1, 0, 1e-9);
    EXPECT_LE(impacts[0].energy_change, 0.0);
  }
}

// The paper's butterfly needs |f_t| / f_n = 0.0727 at t = 0: with mu = 0.05 the slip is there at
// the start (not at the next sign change of the margin, 0.08 s later).
TEST(Hybrid, PaperSceneWithLowFrictionSlipsAtTheStart) {
  SimulationSpec spec;
  spec.contact.mu = 0.05;
  const RunResult rolling = run_spec(spec);
  EXPECT_EQ(rolling.reason, StopReason::kSlip);
  EXPECT_EQ(rolling.final.t, 0.0);
  spec.run.model = ContactModel::kHybrid;
  const RunResult hybrid_run = run_spec(spec);
  const auto slips = events_of(hybrid_run, EventKind::kSlipStart);
  ASSERT_FALSE(slips.empty());
  EXPECT_EQ(slips[0].t, 0.0);
}

// A violation caused by a jump of the hand's acceleration is an event at that instant: the disk
// rests in the palm well until the dip starts at t = 0, where the tangential force jumps.
TEST(Hybrid, AccelerationJumpViolatesFrictionAtThatInstant) {
  SimulationSpec spec;
  spec.initial.t0 = -0.1;
  spec.contact.mu = 0.01;
  spec.duration = 0.3;
  const RunResult rolling = run_spec(spec);
  EXPECT_EQ(rolling.reason, StopReason::kSlip);
  EXPECT_EQ(rolling.final.t, 0.0);
  spec.run.model = ContactModel::kHybrid;
  const auto slips = events_of(run_spec(spec), EventKind::kSlipStart);
  ASSERT_FALSE(slips.empty());
  EXPECT_EQ(slips[0].t, 0.0);
}

// The general formulation (A x = b with Coulomb's row while sliding) and the reduced one agree
// through slips and re-sticks on the paper's butterfly (mu = 0.25 < 0.306 it needs), and through
// a throw over the fingertip and the catch on the back (2T = 1.05 s, faster than the fastest
// motion that keeps contact).
TEST(Hybrid, GeneralAndReducedAgreeThroughSlipAndThrow) {
  SimulationSpec spec;
  spec.run.model = ContactModel::kHybrid;
  spec.run.integrator.rtol = 1e-12;
  spec.run.integrator.atol = 1e-14;
  spec.contact.mu = 0.25;
  spec.duration = 1.5;
  struct Case {
    double period, mu, e;
  };
  for (const Case c : {Case{1.181, 0.25, 0.3}, Case{1.05, 1.0, 0.3}}) {
    SCOPED_TRACE(c.period);
    spec.motion.period = c.period;
    spec.motion.k = solve_k(spec, c.period).k;
    spec.contact.mu = c.mu;
    spec.contact.restitution = c.e;
    spec.run.formulation = Formulation::kReduced;
    const RunResult reduced = run_spec(spec);
    spec.run.formulation = Formulation::kGeneral;
    const RunResult general = run_spec(spec);
    // The same transitions at the same times.
    std::vector<RecordedEvent> a, b;
    for (const auto& e : reduced.events)
      if (e.kind != EventKind::kJunction && e.kind != EventKind::kApex) a.push_back(e);
    for (const auto& e : general.events)
      if (e.kind != EventKind::kJunction && e.kind != EventKind::kApex) b.push_back(e);
    ASSERT_EQ(a.size(), b.size());
    ASSERT_GE(a.size(), 2u);
    for (std::size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].kind, b[i].kind);
      EXPECT_NEAR(a[i].t, b[i].t, 1e-8);
      EXPECT_NEAR(a[i].s_h, b[i].s_h, 1e-7);
    }
    for (double t = 0.1; t < 1.5; t += 0.1) {
      const Sample x = reduced.trajectory.sample(t), y = general.trajectory.sample(t);
      EXPECT_EQ(x.mode, y.mode);
      EXPECT_NEAR(x.s_h, y.s_h, 1e-7) << "t = " << t;
      EXPECT_NEAR((x.object_position - y.object_position).norm(), 0, 1e-8) << "t = " << t;
    }
    if (c.period < 1.1) {
      EXPECT_FALSE(events_of(reduced, EventKind::kLiftOff).empty());
      EXPECT_FALSE(events_of(reduced, EventKind::kImpact).empty());
    } else {
      EXPECT_FALSE(events_of(reduced, EventKind::kStick).empty());
    }
  }
}

// With the hand held still, the disk's energy never increases: not across sliding, rest, drag or
// rolling resistance, nor at any impact or change of mode. Randomised drops onto the paper's hand
// held at random angles, with random friction, restitution and losses.
TEST(Hybrid, EnergyNeverIncreasesWithTheHandHeldStill) {
  std::mt19937_64 rng(20261124);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int runs = flatland::test::short_tests() ? 12 : 60;
  int impacts = 0, slips = 0, sticks = 0, rests = 0, lift_offs = 0;
  for (int i = 0; i < runs; ++i) {
    SCOPED_TRACE(i);
    // Mostly with a well facing up (palm up near 0, back up near pi), where disks settle.
    const double angle = i % 3 == 0 ? 2 * std::numbers::pi * u(rng)
                                    : (i % 3 == 1 ? 0.0 : std::numbers::pi) + 0.5 * (u(rng) - 0.5);
    const double g = u(rng) < 0.5 ? kG : kG * std::sin(5.0 * std::numbers::pi / 180.0);
    auto hand = std::make_shared<PolynomialHand>(0.18, -0.18, -0.252, 0.216);
    std::shared_ptr<RollingProblem> pb = problem(hand, std::make_shared<FixedHand>(angle), g);
    pb->object = make_uniform_disk(0.051);
    ContactLaw& law = pb->contact;
    law.mu = 0.05 + 0.95 * u(rng);
    law.mu_kinetic = *law.mu * (0.5 + 0.5 * u(rng));
    law.restitution = 0.9 * u(rng);
    // Below mu_k r (the bound the model asks for), up to the 2 mm of a soft rim.
    law.rolling_resistance =
        u(rng) < 0.6 ? std::min(2e-3, 0.9 * *law.mu_kinetic * 0.051) * (0.2 + 0.8 * u(rng)) : 0.0;
    law.drag = u(rng) < 0.5 ? 0.1 * u(rng) : 0.0;
    law.drag_angular = u(rng) < 0.5 ? 1e-4 * u(rng) : 0.0;
    // Start in flight just above a random upward-facing point of the outline, moving at random.
    Eigen::Matrix2d R;
    R << std::cos(angle), -std::sin(angle), std::sin(angle), std::cos(angle);
    double s = 0;
    CurveGeometry geo;
    do {
      s = -1 + 4 * u(rng);
      geo = hand->geometry(s, hand->piece_at(s, +1));
    } while ((R * geo.normal).y() < 0.3);
    HandKinematics h;
    h.angle = angle;
    Vec2 p = R * (geo.point + (0.051 + 0.001 + 0.03 * u(rng)) * geo.normal);
    Vec2 v = 0.6 * Vec2(u(rng) - 0.5, u(rng) - 0.5);
    if (i == 0) {
      // The first drop is not left to chance: the palm up, dropped 5 mm onto the palm's slope,
      // it bounces, rolls in the well and comes to rest (whatever the number of runs).
      pb = problem(hand, std::make_shared<FixedHand>(0.0), kG);
      pb->object = make_uniform_disk(0.051);
      pb->contact.mu = 0.6;
      pb->contact.mu_kinetic = 0.5;
      pb->contact.restitution = 0.3;
      pb->contact.rolling_resistance = 2e-3;
      h.angle = 0;
      const CurveGeometry slope = hand->geometry(-0.85, 0);
      p = slope.point + (0.051 + 0.005) * slope.normal;
      v = Vec2(0.05, 0);
    }
    if (!(disk_gap(*pb, h, p).distance > 0)) continue;  // in a well's corner: no room
    RunOptions o = hybrid(3.0);
    o.integrator.rtol = 1e-10;
    o.integrator.atol = 1e-12;
    const RunResult r = simulate_hybrid(pb, flying(p, v, 20 * (u(rng) - 0.5)), o);
    const double scale = pb->object.mass * pb->gravity * 0.3;
    for (std::size_t k = 1; k < r.steps.size(); ++k) {
      const double gain = energy(r.steps[k], *pb) - energy(r.steps[k - 1], *pb);
      ASSERT_LE(gain, 1e-8 * scale)
          << "at t = " << r.steps[k].t << " s, mode " << to_string(r.steps[k].mode);
    }
    for (const RecordedEvent& e : r.events) {
      if (e.kind == EventKind::kImpact) {
        EXPECT_LE(e.energy_change, 1e-12 * scale);
        ++impacts;
      }
      slips += e.kind == EventKind::kSlipStart;
      sticks += e.kind == EventKind::kStick;
      rests += e.kind == EventKind::kRest;
      lift_offs += e.kind == EventKind::kLiftOff;
    }
  }
  // The runs went through every kind of transition.
  EXPECT_GT(impacts, 0);
  EXPECT_GT(slips, 0);
  EXPECT_GT(sticks, 0);
  EXPECT_GT(rests, 0);
  EXPECT_GT(lift_offs, 0);
}

// The impact law never creates energy and never leaves the contact approaching, also when the
// hand's own inertia couples the normal and tangential directions (random inverse effective
// masses); without coupling (a disk on a prescribed hand) its impulse is inside the cone.
TEST(Hybrid, ImpactLawNeverCreatesEnergy) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 20000; ++i) {
    const bool coupled = i % 2 == 0;
    Eigen::Matrix2d L;
    L << 1 + u(rng), 0, coupled ? u(rng) : 0.0, 1 + u(rng);
    const Eigen::Matrix2d W = L * L.transpose() + 1e-3 * Eigen::Matrix2d::Identity();
    ContactLaw law;
    law.mu = 1.5 * (u(rng) + 1);
    law.mu_kinetic = *law.mu * 0.5 * (u(rng) + 1);
    law.restitution = 0.5 * (u(rng) + 1);
    const double vn = -std::abs(u(rng)) - 1e-3, vt = u(rng);
    const ImpactResult r = impact(W, vn, vt, law);
    EXPECT_LE(r.energy_change, 0.0);
    const Eigen::Vector2d p(r.impulse_normal, r.impulse_tangential);
    const Eigen::Vector2d v = Eigen::Vector2d(vn, vt) + W * p;
    EXPECT_LE(p.dot(Eigen::Vector2d(vn, vt) + v) / 2, 1e-12);
    EXPECT_GE(r.impulse_normal, 0.0);
    EXPECT_GE(v[0], -1e-12);  // the contact does not keep approaching
    EXPECT_LE(v[0], law.restitution * -vn + 1e-12);
    if (!coupled) {
      EXPECT_LE(std::abs(r.impulse_tangential), *law.mu * r.impulse_normal * (1 + 1e-12));
      EXPECT_NEAR(v[0], -law.restitution * vn, 1e-12);
      if (!r.sticking) {
        EXPECT_GE(v[1] * vt, 0.0);  // the slip is slowed, never reversed
      }
    }
  }
}

// Flight is modelled for a disk: another object's hybrid run slides as a disk's does, but stops
// where it would lift off (contact_lost), saying so instead of flying it wrongly.
TEST(Hybrid, NonDiskObjectStopsWhereItWouldFly) {
  SimulationSpec spec;
  spec.object.kind = ObjectSpec::Kind::kEllipse;
  spec.object.semi_axis_x = 0.05;
  spec.object.semi_axis_y = 0.045;
  spec.motion.period = 0.9;  // far faster than any motion that keeps contact
  spec.run.model = ContactModel::kHybrid;
  spec.contact.mu = 1.0;
  const RunResult r = run_spec(spec);
  EXPECT_EQ(r.formulation, Formulation::kGeneral);
  EXPECT_EQ(r.reason, StopReason::kContactLost);
  ASSERT_FALSE(r.events.empty());
  EXPECT_FALSE(events_of(r, EventKind::kContactLost).empty());
  EXPECT_NEAR(r.final.force_normal, 0.0, 1e-6 * kG);
  EXPECT_LT(r.final.t, 0.9);
}

TEST(Hybrid, BadContactLawsNameTheField) {
  const auto message = [](const ContactLaw& law) {
    try {
      law.validate();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  ContactLaw law;
  law.mu = -0.1;
  EXPECT_NE(message(law).find("contact.mu:"), std::string::npos);
  law.mu = 0.3;
  law.mu_kinetic = 0.4;
  EXPECT_NE(message(law).find("contact.mu_kinetic:"), std::string::npos);
  law.mu_kinetic = 0.2;
  law.restitution = 1.5;
  EXPECT_NE(message(law).find("contact.restitution:"), std::string::npos);
  law.restitution = 0.5;
  law.drag = -1;
  EXPECT_NE(message(law).find("contact.drag:"), std::string::npos);
  law.drag = 0;
  law.rolling_resistance = -1e-3;
  EXPECT_NE(message(law).find("contact.rolling_resistance:"), std::string::npos);
  law.rolling_resistance = 0;
  EXPECT_EQ(message(law), "(accepted)");
}
