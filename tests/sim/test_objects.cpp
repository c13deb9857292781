// Rolling objects other than the uniform disk (issue 26): the conversion of a physical description
// (disk, ring, ball, ball on rails, a given inertia) into the disk the planar dynamics see, its
// bounds, and the dynamics with an inertia above m r^2 (a ball on rails) against closed forms: a
// well's period, energy and the rolling relation on the paper's hand held still, and an impact's
// impulse law with J = 3 m r^2.
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/roots.hpp"
#include "flatland/sim/spec.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <string>

using namespace flatland::sim;

namespace {

using flatland_test::kG;

std::string error_of(const ObjectSpec& o) {
  try {
    equivalent_disk(o);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

ObjectSpec ball(double radius, double mass, std::optional<double> gap, bool hollow = false) {
  ObjectSpec o;
  o.kind = ObjectSpec::Kind::kBall;
  o.radius = radius;
  o.mass = mass;
  o.rail_gap = gap;
  o.hollow = hollow;
  return o;
}

}  // namespace

// Each description's rolling radius and inertia against the textbook formulas, computed here.
TEST(Objects, ConversionOfEachDescription) {
  ObjectSpec disk;
  disk.radius = 0.05;
  disk.mass = 2.0;
  EXPECT_DOUBLE_EQ(equivalent_disk(disk).radius, 0.05);
  EXPECT_DOUBLE_EQ(equivalent_disk(disk).inertia, 0.5 * 2.0 * 0.0025);

  ObjectSpec ring = disk;
  ring.kind = ObjectSpec::Kind::kRing;
  ring.inner_radius = 0.03;
  EXPECT_DOUBLE_EQ(equivalent_disk(ring).radius, 0.05);
  // An annulus: integral of rho^2 dm over [R_i, R] with dm proportional to rho d rho.
  EXPECT_NEAR(equivalent_disk(ring).inertia, 0.5 * 2.0 * (0.0025 + 0.0009), 1e-15);

  EXPECT_DOUBLE_EQ(equivalent_disk(ball(0.04, 3.0, std::nullopt)).radius, 0.04);
  EXPECT_NEAR(equivalent_disk(ball(0.04, 3.0, std::nullopt)).inertia, 0.4 * 3.0 * 0.0016, 1e-15);
  EXPECT_NEAR(equivalent_disk(ball(0.04, 3.0, std::nullopt, true)).inertia,
              2.0 / 3.0 * 3.0 * 0.0016, 1e-15);

  // A ball of radius 5 cm between plates 6 cm apart touches them 3 cm from its equator's plane:
  // a 3-4-5 triangle, rolling radius 4 cm.
  const RollingDisk on_rails = equivalent_disk(ball(0.05, 1.5, 0.06));
  EXPECT_NEAR(on_rails.radius, 0.04, 1e-15);
  EXPECT_NEAR(on_rails.inertia, 0.4 * 1.5 * 0.0025, 1e-15);
  EXPECT_EQ(ball_on_rails(0.05, 0.06, 1.5, false).radius, on_rails.radius);
  const RollingDisk hollow = ball_on_rails(0.05, 0.06, 1.5, true);
  EXPECT_NEAR(hollow.inertia, 2.0 / 3.0 * 1.5 * 0.0025, 1e-15);
  // Its own inertia exceeds m r^2 of the rolling radius: 2/3 R^2 = 16.7e-4 > r^2 = 16e-4.
  EXPECT_GT(hollow.inertia, 1.5 * hollow.radius * hollow.radius);

  // A given inertia replaces the description's.
  ObjectSpec given = ball(0.05, 1.5, 0.06);
  given.inertia = 3e-3;
  EXPECT_EQ(equivalent_disk(given).inertia, 3e-3);
  EXPECT_NEAR(equivalent_disk(given).radius, 0.04, 1e-15);
}

// The gap near the diameter: the rolling radius keeps its digits.
TEST(Objects, RollingRadiusNearTheDiameterKeepsItsDigits) {
  const double R = 0.05, gap = 2 * R - 2e-12;
  // d = R - gap/2 is exact (Sterbenz: the two are within a factor 2): r = sqrt(d (2R - d)).
  const double d = R - 0.5 * gap;
  const double r = ball_on_rails(R, gap, 1.0, false).radius;
  EXPECT_NEAR(r / std::sqrt(d * (2 * R - d)) - 1, 0, 1e-14);
}

TEST(Objects, ImpossibleDescriptionsNameTheField) {
  EXPECT_NE(
      error_of(ball(0.05, 1.0, 0.1)).find("object.rails.gap: larger than the ball's diameter"),
      std::string::npos)
      << error_of(ball(0.05, 1.0, 0.1));
  EXPECT_NE(error_of(ball(0.05, 1.0, 0.12)).find("object.rails.gap"), std::string::npos);
  EXPECT_NE(error_of(ball(0.05, 1.0, 0.0)).find("object.rails.gap: must be positive"),
            std::string::npos);
  EXPECT_NE(error_of(ball(0.05, 1.0, -0.01)).find("object.rails.gap"), std::string::npos);
  EXPECT_NE(error_of(ball(-0.05, 1.0, std::nullopt)).find("object.radius"), std::string::npos);
  EXPECT_NE(error_of(ball(0.05, 0.0, std::nullopt)).find("object.mass"), std::string::npos);

  ObjectSpec ring;
  ring.kind = ObjectSpec::Kind::kRing;
  ring.radius = 0.05;
  ring.inner_radius = 0.05;
  EXPECT_NE(error_of(ring).find("object.inner_radius: must be below object.radius"),
            std::string::npos)
      << error_of(ring);
  ring.inner_radius = 0;
  EXPECT_NE(error_of(ring).find("object.inner_radius: must be positive"), std::string::npos);

  // Bounds of a given inertia: m R^2 with R the ball's own radius, not the rolling radius.
  ObjectSpec on_rails = ball(0.05, 2.0, 0.06);  // r = 0.04: m r^2 = 3.2e-3, m R^2 = 5e-3
  on_rails.inertia = 4.5e-3;
  EXPECT_EQ(error_of(on_rails), "");
  on_rails.inertia = 5.01e-3;
  EXPECT_NE(error_of(on_rails).find("object.inertia: a ball of mass 2 kg within 0.05 m"),
            std::string::npos)
      << error_of(on_rails);
  on_rails.inertia = 0;
  EXPECT_NE(error_of(on_rails).find("object.inertia: must be positive"), std::string::npos);
  // A ring has no mass inside its hole: m R_i^2 <= J <= m R^2.
  ring.inner_radius = 0.03;
  ring.mass = 1.0;
  ring.inertia = 0.8e-3;  // below m R_i^2 = 0.9e-3
  EXPECT_NE(error_of(ring).find("object.inertia: a ring of mass 1 kg with no mass inside 0.03 m"),
            std::string::npos)
      << error_of(ring);
  ring.inertia = 2.5e-3;  // the thin ring: the bound itself
  EXPECT_EQ(error_of(ring), "");
}

// A ball on rails in a circular well of radius R_w (its rails' edge an arc): the centre moves on
// a circle of radius R_w - r, and the energy 1/2 (m + J/r^2) v^2 + m g h gives the small
// oscillation period 2 pi sqrt((1 + J/(m r^2)) (R_w - r) / g), here with J/(m r^2) = 1.5625.
TEST(Objects, BallOnRailsWellPeriodUsesItsOwnInertia) {
  const double R_w = 0.2;
  const RollingDisk d = ball_on_rails(0.05, 0.06, 1.0, false);  // r = 0.04, J = 1e-3
  auto pb = std::make_shared<RollingProblem>();
  pb->hand = std::make_shared<CircleCurve>(Vec2(0, R_w), R_w, CircleCurve::Side::kConcaveWell);
  pb->object = make_disk(d.radius, 1.0, d.inertia);
  pb->motion = std::make_shared<FixedHand>(0.0);
  pb->gravity = kG;
  const double expected =
      2 * std::numbers::pi *
      std::sqrt((1 + d.inertia / (d.radius * d.radius)) * (R_w - d.radius) / kG);
  InitialContact ic;
  ic.s_h = 1e-5;  // the nonlinear correction (amplitude^2 / 16) below 1e-11
  RunOptions o;
  o.t_end = 2.2 * expected;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-19;
  const RunResult r = simulate(pb, ic, o);
  std::vector<double> crossings;  // upward zero crossings of s_h on the dense output
  for (std::size_t i = 1; i < r.steps.size(); ++i)
    if (r.steps[i - 1].s_h < 0 && r.steps[i].s_h >= 0)
      crossings.push_back(brent_root([&](double t) { return r.trajectory.s_h(t); },
                                     r.steps[i - 1].t, r.steps[i].t, r.steps[i - 1].s_h,
                                     r.steps[i].s_h, 1e-14)
                              .x);
  ASSERT_GE(crossings.size(), 2u);
  EXPECT_NEAR((crossings[1] - crossings[0]) / expected - 1.0, 0.0, 1e-8);
}

// A ball on rails (J = 1.5625 m r^2) released off the palm well's bottom on the paper's hand held
// still, built from its description as a scene is: the rolling relation |v| = r |omega| with the
// rolling radius, and the energy 1/2 m v^2 + 1/2 J omega^2 + m g y with the ball's own J, both
// computed here from the description.
TEST(Objects, BallOnRailsOnThePapersHandRollsWithItsRadiusAndConservesEnergy) {
  SimulationSpec spec;
  spec.object = ball(0.05, 0.7, 0.06);
  spec.motion.kind = MotionSpec::Kind::kFixed;
  spec.initial.s_h = -0.8;
  spec.duration = 3.0;
  spec.run.integrator.rtol = 1e-12;
  spec.run.integrator.atol = 1e-14;
  const double m = 0.7, r = 0.04, J = 0.4 * m * 0.05 * 0.05;
  const RunResult run = run_spec(spec);
  ASSERT_EQ(run.reason, StopReason::kEndTime);
  const auto energy = [&](const Sample& s) {
    return 0.5 * m * s.object_velocity.squaredNorm() +
           0.5 * J * s.object_angular_velocity * s.object_angular_velocity +
           m * spec.gravity * s.object_position.y();
  };
  const double e0 = energy(run.initial);
  double kinetic_max = 0, worst_energy = 0, worst_rolling = 0, speed_max = 0;
  for (const Sample& s : run.steps) {
    kinetic_max = std::max(kinetic_max, energy(s) - m * spec.gravity * s.object_position.y());
    worst_energy = std::max(worst_energy, std::abs(energy(s) - e0));
    speed_max = std::max(speed_max, s.object_velocity.norm());
    worst_rolling = std::max(worst_rolling, std::abs(s.object_velocity.norm() -
                                                     r * std::abs(s.object_angular_velocity)));
  }
  ASSERT_GT(speed_max, 0.1);  // it did roll
  EXPECT_LE(worst_energy / kinetic_max, 1e-8);
  EXPECT_LE(worst_rolling / speed_max, 1e-9);
}

// An impact with J = 3 m r^2 on a level hand, hit at (vx, -vy) without spin. The impulse (P_t,
// P_n) acts at the contact, r below the centre: dv = P / m, d omega = r P_t / J, so the contact's
// slip u = vx + omega r changes by P_t (1/m + r^2/J) = P_t 4 / (3 m). Sticking (large mu):
// P_t = -3 m vx / 4, so vx' = vx / 4, omega' = -vx / (4 r); P_n = m (1 + e) vy. The angular
// momentum about the contact point, J omega - m r vx, is kept (-m r vx), and the kinetic energy
// falls by 1/2 m (1 - e^2) vy^2 + 3/8 m vx^2. Sliding (small mu): P_t = -mu (1 + e) m vy, so
// vx' = vx - mu (1 + e) vy and omega' = -mu (1 + e) vy / (3 r).
TEST(Objects, ImpactWithInertiaAboveMrSquaredKeepsMomentumAndLosesTheClosedFormEnergy) {
  const double r = 0.05, m = 0.8, J = 3 * m * r * r, e = 0.5, vx = 0.6, vy0 = 1.0, h = 0.02;
  const double vy = std::sqrt(vy0 * vy0 + 2 * kG * h);  // at the impact
  for (double mu : {0.05, 2.0}) {
    auto pb = std::make_shared<RollingProblem>();
    pb->hand = std::make_shared<LineCurve>(Vec2::Zero(), Vec2(1, 0));
    pb->object = make_disk(r, m, J);
    pb->motion = std::make_shared<FixedHand>(0.0);
    pb->gravity = kG;
    pb->contact.mu = mu;
    pb->contact.restitution = e;
    HybridState x;
    x.mode = ContactMode::kFlight;
    x.position = Vec2(0, r + h);
    x.velocity = Vec2(vx, -vy0);
    RunOptions o;
    o.t_end = 0.1;
    o.model = ContactModel::kHybrid;
    o.integrator.rtol = 1e-12;
    o.integrator.atol = 1e-14;
    const RunResult run = simulate_hybrid(pb, x, o);
    const RecordedEvent* impact = nullptr;
    for (const RecordedEvent& ev : run.events)
      if (ev.kind == EventKind::kImpact) {
        impact = &ev;
        break;
      }
    ASSERT_NE(impact, nullptr);
    const Sample after = run.trajectory.sample(impact->t);
    const Vec2 v = after.object_velocity;
    const double w = after.object_angular_velocity;
    EXPECT_NEAR(v.y() / (e * vy) - 1, 0, 1e-9);
    if (mu > 1) {
      EXPECT_TRUE(impact->impact->sticking);
      EXPECT_NEAR(v.x() / (vx / 4) - 1, 0, 1e-9);
      EXPECT_NEAR(w / (-vx / (4 * r)) - 1, 0, 1e-9);
      // About the contact point (r below the centre): L = J omega - m r vx.
      EXPECT_NEAR((J * w - m * r * v.x()) / (-m * r * vx) - 1, 0, 1e-9);
      const double lost = 0.5 * m * (1 - e * e) * vy * vy + 3.0 / 8.0 * m * vx * vx;
      EXPECT_NEAR(impact->energy_change / -lost - 1, 0, 1e-9);
    } else {
      EXPECT_FALSE(impact->impact->sticking);
      EXPECT_NEAR(v.x() / (vx - mu * (1 + e) * vy) - 1, 0, 1e-9);
      EXPECT_NEAR(w / (-mu * (1 + e) * vy / (3 * r)) - 1, 0, 1e-9);
      // Kelvin: the work of the impulse at the average of the contact's velocities before and
      // after; the slip goes from vx to vx - (4/3) mu (1 + e) vy.
      const double Pn = m * (1 + e) * vy, Pt = -mu * Pn;
      const double slip_after = vx - 4.0 / 3.0 * mu * (1 + e) * vy;
      const double change = 0.5 * Pn * (-vy + e * vy) + 0.5 * Pt * (vx + slip_after);
      EXPECT_NEAR(impact->energy_change / change - 1, 0, 1e-9);
    }
    // The energy the run reports just after, from the states, with J.
    const double before = 0.5 * m * (vx * vx + vy * vy);
    const double kinetic_after = 0.5 * m * v.squaredNorm() + 0.5 * J * w * w;
    EXPECT_NEAR((kinetic_after - before) / impact->energy_change - 1, 0, 1e-9);
  }
}
