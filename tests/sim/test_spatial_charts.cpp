// Long spatial runs across many chart changes, against closed forms and invariants: Weltner's
// ball on a turntable in a tilted world drifts across the slope at (5/2)(g/Omega) sin(theta) for
// 20 s while its spin grows to thousands of rad/s (three integrators, six worlds); a ball in a
// bowl and an ellipsoid in a dish, both with their charts' poles on the vertical, swing through
// the bottom for 60 s with their energy kept, through at least 50 chart changes each.
#include "flatland/sim/spatial_run.hpp"

#include "test_scale.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>

namespace flatland::sim {
namespace {

using flatland_test::kG;

/// Weltner (Am. J. Phys. 47, 984, 1979): a uniform ball rolling on a plate that spins at Omega
/// about its normal n obeys dv/dt = (2/7) Omega n x v + (5/7) g_t, g_t gravity's part along the
/// plate (Euler's equations about the contact with the rolling constraint). Its steady solution
/// is the drift v_d = (5 / (2 Omega)) n x g_t, across the slope, |v_d| = (5/2)(g/Omega) sin(theta)
/// for gravity tilted by theta from the normal; the rest, u = v - v_d, turns about n at
/// k = (2/7) Omega. So p(t) = p0 + v_d t + (sin(kt)/k) u0 + ((1 - cos(kt))/k) n x u0, and the
/// speed |v_d + u(t)| never exceeds |v_d| + |u0|.
struct Drift {
  double worst_relative = 0;  ///< the centre's largest distance from p(t) over |v_d| t_end
  double speed_over_bound = 0;
  double travelled = 0;  ///< |v_d| t_end, m
  SpatialRunResult run;
};

/// A 2 cm ball on a horizontal plate spinning at `omega` about z, gravity tilted by `theta`
/// towards the azimuth `azimuth` (from x), started on the axis at `v0`, run to `t_end`.
Drift tilted_turntable(double theta, double azimuth, double omega, const Vec3& v0, double t_end,
                       const IntegratorSettings& integrator) {
  const double r = 0.02, k = 2.0 / 7.0 * omega;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(r, 0.2);
  const Vec3 n = Vec3::UnitZ();
  const Vec3 g_t = kG * std::sin(theta) * Vec3(std::cos(azimuth), std::sin(azimuth), 0);
  pb.gravity = g_t - kG * std::cos(theta) * n;
  const SpinningHand3 table(n, omega);
  ContactPlacement at;
  at.velocity = v0;
  const SpatialState initial = place_in_contact(pb, table.at(0), at);
  SpatialRunOptions o;
  o.t_end = t_end;
  o.integrator = integrator;
  o.integrator.max_steps = 10'000'000;
  o.sample_dt = 1e-3;  // every step would be up to 10^6 samples
  Drift d;
  d.run = simulate_spatial(pb, table, initial, 0.0, o);
  const Vec3 v_d = 5.0 / (2.0 * omega) * n.cross(g_t);
  EXPECT_NEAR(v_d.norm(), 2.5 * kG / omega * std::sin(theta), 1e-12);
  const Vec3 p0 = d.run.samples.front().state.position, u0 = v0 - v_d;
  const double bound = v_d.norm() + u0.norm();
  d.travelled = v_d.norm() * t_end;
  for (const SpatialSample& s : d.run.samples) {
    const double t = s.t;
    const Vec3 expected =
        p0 + v_d * t + std::sin(k * t) / k * u0 + (1 - std::cos(k * t)) / k * n.cross(u0);
    d.worst_relative =
        std::max(d.worst_relative, (s.state.position - expected).norm() / d.travelled);
    d.speed_over_bound = std::max(d.speed_over_bound, s.state.velocity.norm() / bound);
  }
  return d;
}

/// The inclined turntable of the report: tilt 0.1 rad (gravity (0, -0.978, -9.751) m/s^2), a
/// 10 rad/s plate, the ball started at rest on the axis, for 20 s. It drifts 4.9 m from the axis,
/// where the plate moves at 49 m/s under it, so it spins at up to (5/2) g sin(theta) t / r =
/// 2 400 rad/s, and every integrator's steps must follow that.
constexpr double kTilt = 0.09998367;  // asin(0.978367483138916 / 9.8)
double inclined_turntable_end() { return test::short_tests() ? 3.0 : 20.0; }
Drift inclined_turntable(const IntegratorSettings& integrator) {
  return tilted_turntable(kTilt, -std::numbers::pi / 2, 10.0, Vec3::Zero(),
                          inclined_turntable_end(), integrator);
}

/// The scene's tolerances.
IntegratorSettings adaptive(Method method) {
  IntegratorSettings is;
  is.method = method;
  is.rtol = 1e-11;
  is.atol = 1e-13;
  return is;
}

void expect_weltner(const Drift& d) {
  ASSERT_EQ(d.run.stop, SpatialStop::kEndTime)
      << to_string(d.run.stop) << " at " << d.run.final.t << " s";
  EXPECT_LT(d.worst_relative, 1e-8)
      << "drifted " << d.travelled << " m, " << d.run.stats.steps << " steps";
  // The bound is reached (u0 = -v_d: the speed swings between 0 and 2 |v_d|), so a rounding
  // margin.
  EXPECT_LE(d.speed_over_bound, 1 + 1e-9);
  EXPECT_LT(d.run.stats.max_constraint_residual, 1e-12);
  // The run's own energy audit: the table's work (the ball spins up to thousands of rad/s)
  // accounts for every joule the ball gains.
  EXPECT_FALSE(d.run.audit.broken);
  EXPECT_LE(std::abs(d.run.audit.balance), d.run.audit.bound());
  EXPECT_GT(d.run.audit.work_hand, 0.0);
}

TEST(SpatialCharts, TheInclinedTurntableDriftsAsWeltnerSaysForTwentySecondsWithDopri5) {
  expect_weltner(inclined_turntable(adaptive(Method::kDormandPrince54)));
}

TEST(SpatialCharts, TheInclinedTurntableDriftsAsWeltnerSaysForTwentySecondsWithDop853) {
  expect_weltner(inclined_turntable(adaptive(Method::kDormandPrince853)));
}

TEST(SpatialCharts, TheInclinedTurntableDriftsAsWeltnerSaysForTwentySecondsWithRk4) {
  // RK4's error here is set by the ball's spin, not by its centre's slow circle: the orientation
  // and the contact's coordinates on the ball turn by omega h per step, and the stages' errors in
  // them reach the centre's acceleration through the omega^2 r terms (2 400^2 x 0.02 m = 1e5
  // m/s^2 at the end). Measured over the 20 s: at 0.12 rad per step of the final spin (50 us)
  // the centre ends 6e-7 of its 4.9 m off, falling as h^5; at 0.05 rad (20 us, 10^6 steps) 7e-9.
  const double t_end = inclined_turntable_end();
  const double final_spin = 2.5 * kG * std::sin(kTilt) * t_end / 0.02;
  IntegratorSettings is;
  is.method = Method::kRungeKutta4;
  is.fixed_step = 0.05 / final_spin;
  expect_weltner(inclined_turntable(is));
}

TEST(SpatialCharts, SixTiltedTurntablesDriftAsWeltnerSays) {
  // Tilts from 0.05 to 0.2 rad towards different azimuths, plates at 10 to 20 rad/s, balls
  // started on the axis at rest or moving. Each drifts for 10 s (up to 4.9 m, spinning at up to
  // 2 400 rad/s: the spin at the end is (5/2) g sin(theta) t / r, whatever the plate's rate).
  struct World {
    double theta, azimuth, omega;
    Vec3 v0;
  };
  const World worlds[] = {
      {0.05, 0.0, 10.0, Vec3::Zero()},         {0.08, 1.0, 20.0, Vec3(0.05, 0, 0)},
      {0.11, 2.0, 14.0, Vec3(0, -0.1, 0)},     {0.14, 3.0, 17.0, Vec3::Zero()},
      {0.17, -2.0, 12.0, Vec3(0.03, 0.04, 0)}, {0.2, -1.0, 10.0, Vec3::Zero()},
  };
  const double t_end = test::short_tests() ? 2.0 : 10.0;
  for (const World& w : worlds) {
    SCOPED_TRACE("theta " + std::to_string(w.theta) + ", Omega " + std::to_string(w.omega));
    expect_weltner(tilted_turntable(w.theta, w.azimuth, w.omega, w.v0, t_end,
                                    adaptive(Method::kDormandPrince853)));
  }
}

/// A fixed dish of depth `depth` (its z semi-axis; its chart's poles on the vertical, so the
/// bottom is a pole) with an object placed `amplitude` rad of latitude up its side, moving along
/// the latitude at `speed` and spinning about the normal, run for 60 s. Its energy is kept within
/// 1e-8 of m g depth, and the run crosses at least 50 chart changes: the dish's as the contact
/// passes near the bottom and climbs towards the sides, the object's as its contact wanders
/// over it.
void expect_kept_energy_over_a_minute(const SpatialRollingProblem& pb, double depth,
                                      double amplitude, double speed, double spin) {
  const FixedHand3 dish;
  ContactPlacement at;
  at.s_h = SurfaceParam(0.0, -std::numbers::pi / 2 + amplitude);
  at.velocity = Vec3(0, speed, 0);
  at.spin = spin;
  const SpatialState initial = place_in_contact(pb, dish.at(0), at);
  SpatialRunOptions o;
  o.t_end = test::short_tests() ? 12.0 : 60.0;
  o.integrator.rtol = 1e-11;
  o.integrator.atol = 1e-14;
  o.integrator.max_steps = 10'000'000;
  const SpatialRunResult run = simulate_spatial(pb, dish, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime) << to_string(run.stop) << " at " << run.final.t;
  const double e0 = run.samples.front().energy, scale = pb.object.mass * kG * depth;
  double worst = 0, lowest = 0;
  for (const SpatialSample& s : run.samples) {
    worst = std::max(worst, std::abs(s.energy - e0));
    lowest = std::min(lowest, s.contact.z() / depth);
  }
  EXPECT_LT(worst / scale, 1e-8) << run.stats.steps << " steps";
  // The run's own audit holds, and the fixed dish does no work (to the constraints' drift).
  EXPECT_FALSE(run.audit.broken);
  EXPECT_LE(std::abs(run.audit.balance), run.audit.bound());
  EXPECT_LT(std::abs(run.audit.work_hand), 1e-8 * scale);
  EXPECT_GE(run.stats.chart_changes, o.t_end < 60 ? 10 : 50);
  EXPECT_LT(run.stats.max_constraint_residual, 1e-12);
  EXPECT_GT(run.stats.min_force_normal, 0);
  // The contact came within 0.57 rad of latitude of the bottom, the dish's own chart's pole,
  // where that chart alone would have had to stop the run.
  EXPECT_LT(lowest, -std::sin(1.0));
}

TEST(SpatialCharts, ABallSwingsInABowlForAMinuteAcrossItsPoles) {
  // Started 1.4 rad from the bottom, it swings through the bottom (the first chart's pole) and
  // climbs, as its swing turns, within 0.57 rad of the points at the rim's height on the x and y
  // axes (the other charts' poles): the bowl's charts change most (about 90 of some 160).
  const double R = 0.3, r = 0.05;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<EllipsoidSurface>(
      EllipsoidSurface::sphere(R, EllipsoidSurface::Side::kDish));
  pb.object = uniform_ball(r, 0.1);
  expect_kept_energy_over_a_minute(pb, R, 1.4, 0.6, 1.0);
}

TEST(SpatialCharts, AnEllipsoidSwingsInADishForAMinuteAcrossItsPoles) {
  // The ellipsoid's own charts change most here (its contact wanders over it as it rolls and
  // spins); started higher or faster, this one rocks off the dish's wall (its contact is lost).
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<EllipsoidSurface>(0.3, 0.4, 0.35, EllipsoidSurface::Side::kDish);
  pb.object = uniform_ellipsoid(0.03, 0.05, 0.04, 0.3);
  expect_kept_energy_over_a_minute(pb, 0.35, 0.6, 0.3, 2.0);
}

}  // namespace
}  // namespace flatland::sim
