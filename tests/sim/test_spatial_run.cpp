// Spatial rolling in time against closed forms: a ball on a turntable circles at (2/7) of the
// table's rate about the centre and with the radius Weltner's solution gives, over many
// revolutions; a ball in a spherical bowl keeps its energy and oscillates at
// sqrt(5 g / (7 (R - r))); the constraints hold to 1e-12 after every step.
#include "flatland/sim/spatial_run.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace flatland::sim {
namespace {

constexpr double kPi = std::numbers::pi;

/// A ball of radius r resting on (or rolling over) the hand at the contact s_h, its centre moving
/// at v (tangent to the hand), no spin about the normal; the rates of the contact coordinates
/// roughly right (the run's first projection makes the state consistent).
SpatialState ball_on(const SpatialRollingProblem& pb, const HandPose3& hand, double r,
                     const SurfaceParam& s_h, const Vec3& v, double contact_speed_factor) {
  const SurfaceGeometry gh = pb.hand->geometry(s_h);
  const Vec3 nh = hand.rotation * gh.normal;
  const Vec3 contact = hand.position + hand.rotation * gh.point;
  SpatialState s;
  s.s_h = s_h;
  s.position = contact + r * nh;
  // The ball's chart puts its (0, 0) point, body +x, at the contact.
  s.orientation = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitX(), -nh);
  s.velocity = v;
  const Vec3 ro = -r * nh;
  const Vec3 Vh = hand.velocity + hand.angular_velocity.cross(contact - hand.position);
  // Rolling: v + omega x r_o = the hand's velocity there; omega's normal part 0.
  s.angular_velocity = (v - Vh).cross(ro) / (r * r);
  const Vec3 w = contact_speed_factor * (v - Vh);  // the contact point over both surfaces
  const Mat32 Jh = hand.rotation * gh.jacobian;
  s.sdot_h = (Jh.transpose() * Jh).ldlt().solve(Jh.transpose() * w);
  const SurfaceGeometry go = pb.object.surface->geometry(SurfaceParam::Zero());
  const Mat32 Jo = s.orientation.toRotationMatrix() * go.jacobian;
  s.sdot_o = (Jo.transpose() * Jo).ldlt().solve(Jo.transpose() * w);
  return s;
}

TEST(SpatialRun, BallOnATurntableCirclesAsWeltnerSays) {
  // Weltner (Am. J. Phys. 47, 984, 1979): dv/dt = (2/7) Omega z x v, so the centre runs on a
  // circle about c = p0 + z x v0 / k with radius |v0| / k at the rate k = (2/7) Omega.
  const double omega = 10.0, r = 0.02, k = 2.0 / 7.0 * omega;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(r, 0.2);
  const SpinningHand3 table(Vec3::UnitZ(), omega);
  const Vec3 v0(0.05, 0.03, 0);
  SpatialState initial = ball_on(pb, table.at(0), r, SurfaceParam(0.12, -0.04), v0, 1.0);
  initial.angular_velocity.z() = 1.5;  // a spin about the vertical, which stays
  const double revolutions = 8, t_end = revolutions * 2 * kPi / k;
  SpatialRunOptions o;
  o.t_end = t_end;
  o.rtol = 1e-11;
  o.atol = 1e-13;
  const SpatialRunResult run = simulate_spatial(pb, table, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  const Vec3 p0 = run.steps.front().state.position;
  const Vec3 c = p0 + Vec3::UnitZ().cross(v0) / k;
  const double radius = v0.norm() / k;
  double worst = 0;
  for (const SpatialSample& s : run.steps) {
    const Vec3 expected = c + Eigen::AngleAxisd(k * s.t, Vec3::UnitZ()) * (p0 - c);
    worst = std::max(worst, (s.state.position - expected).norm());
    ASSERT_LT(s.constraint_residual, 1e-12) << "t " << s.t;
  }
  EXPECT_LT(worst / radius, 1e-8) << "over " << revolutions << " revolutions";
  EXPECT_NEAR(run.final.state.position.z(), r, 1e-12);
  EXPECT_NEAR(run.final.state.angular_velocity.z(), 1.5, 1e-8);
  EXPECT_LT(run.stats.max_redundant_residual, 1e-10);
}

TEST(SpatialRun, BallOnAnInclinedTurntableDriftsAcrossTheSlope) {
  // Weltner: on a plate inclined by theta and spinning at Omega about its normal n, the centre
  // obeys dv/dt = (2/7) Omega n x v + (5/7) g_t (g_t gravity along the plate), so it circles at
  // k = (2/7) Omega about a centre that drifts at v_d = (5 / (2 Omega)) n x g_t, across the slope,
  // |v_d| = (5/2) (g / Omega) sin(theta): p(t) = p0 + v_d t + (sin(kt)/k) u + ((1 - cos kt)/k)
  // n x u, u = v0 - v_d.
  // The ball's speed over the plate grows as (5/2) g sin(theta) t wherever it starts (the plate
  // turns under the drifting centre): a few circles of a fast plate keep that moderate.
  const double omega = 40.0, theta = 0.05, r = 0.03, g = 9.8, k = 2.0 / 7.0 * omega;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(r, 0.2);
  pb.gravity = Vec3(0, 0, -g);
  const Eigen::Matrix3d tilt = Eigen::AngleAxisd(theta, Vec3::UnitX()).toRotationMatrix();
  const Vec3 n = tilt * Vec3::UnitZ();
  const SpinningHand3 table(n, omega, Vec3::Zero(), tilt);
  const HandPose3 start = table.at(0);
  const Vec3 v0 = tilt * Vec3(0.04, -0.02, 0);
  const SpatialState initial = ball_on(pb, start, r, SurfaceParam(0.05, 0.03), v0, 1.0);
  const Vec3 g_t = pb.gravity - pb.gravity.dot(n) * n;
  const Vec3 v_d = 5.0 / (2.0 * omega) * n.cross(g_t);
  ASSERT_NEAR(v_d.norm(), 2.5 * g / omega * std::sin(theta), 1e-12);
  SpatialRunOptions o;
  o.t_end = 3 * 2 * kPi / k;  // three circles
  o.rtol = 1e-11;
  o.atol = 1e-13;
  o.max_steps = 200000;
  const SpatialRunResult run = simulate_spatial(pb, table, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  const Vec3 p0 = run.steps.front().state.position, u = v0 - v_d;
  double worst = 0;
  for (const SpatialSample& s : run.steps) {
    const double t = s.t;
    const Vec3 expected =
        p0 + v_d * t + std::sin(k * t) / k * u + (1 - std::cos(k * t)) / k * n.cross(u);
    worst = std::max(worst, (s.state.position - expected).norm());
  }
  const double travelled = v_d.norm() * o.t_end;
  EXPECT_LT(worst / travelled, 1e-8) << "drifted " << travelled << " m";
  EXPECT_LT(run.stats.max_constraint_residual, 1e-12);
}

TEST(SpatialRun, BallRollsStraightOnForManyTurnsAcrossItsChartsPoles) {
  // Without gravity along the plane a rolling ball keeps its velocity. The ball's chart has its
  // poles on the rolling axis's great circle, so the contact reaches them within a quarter turn:
  // the chart is turned again and again, and the motion must not notice.
  const double r = 0.02, speed = 0.3;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(r, 0.2);
  const FixedHand3 hand;
  const SpatialState initial =
      ball_on(pb, hand.at(0), r, SurfaceParam(0.0, 0.0), Vec3(speed, 0, 0), 1.0);
  const double turns = 10;
  SpatialRunOptions o;
  o.t_end = turns * 2 * kPi * r / speed;
  o.rtol = 1e-12;
  o.atol = 1e-14;
  const SpatialRunResult run = simulate_spatial(pb, hand, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  EXPECT_GE(run.stats.chart_changes, static_cast<int>(2 * turns));
  for (const SpatialSample& s : run.steps) {
    ASSERT_LT((s.state.position - Vec3(speed * s.t, 0, r)).norm(), 1e-10 * speed * o.t_end)
        << "t " << s.t;
    ASSERT_LT((s.state.angular_velocity - Vec3(0, speed / r, 0)).norm(), 1e-9 * speed / r);
    ASSERT_LT(s.constraint_residual, 1e-12);
  }
  // The body turned by the distance over r about world y: its x axis is where it began after
  // whole turns.
  const Vec3 body_x = run.final.state.orientation * Vec3::UnitX();
  const Vec3 expected =
      Eigen::AngleAxisd(speed * o.t_end / r, Vec3::UnitY()) * (initial.orientation * Vec3::UnitX());
  EXPECT_LT((body_x - expected).norm(), 1e-9);
}

/// A spherical bowl of radius R (the hand turned so that its chart's poles are horizontal) with
/// a ball of radius r touching it `angle` from the bottom, moving at `speed` along the horizontal
/// tangent.
struct BowlRun {
  SpatialRollingProblem pb;
  std::unique_ptr<FixedHand3> hand;
  SpatialState initial;
};

BowlRun ball_in_bowl(double R, double r, double angle, double speed) {
  BowlRun b;
  b.pb.hand = std::make_shared<EllipsoidSurface>(
      EllipsoidSurface::sphere(R, EllipsoidSurface::Side::kDish));
  b.pb.object = uniform_ball(r, 0.1);
  // Hand z (the chart's pole axis) along world -y: the bottom, world -z, is at (u, v) =
  // (-pi/2, 0), on the chart's equator.
  b.hand =
      std::make_unique<FixedHand3>(Eigen::AngleAxisd(kPi / 2, Vec3::UnitX()).toRotationMatrix());
  const SurfaceParam s_h(-kPi / 2 + angle, 0.0);  // displaced along world x
  // The centre moves on a sphere of radius R - r; the contact on the bowl R / (R - r) as fast.
  b.initial = ball_on(b.pb, b.hand->at(0), r, s_h, Vec3(0, speed, 0), R / (R - r));
  return b;
}

TEST(SpatialRun, BallInABowlKeepsItsEnergy) {
  const double R = 0.3, r = 0.05, g = 9.8;
  const BowlRun b = ball_in_bowl(R, r, 0.4, 0.3);
  SpatialRunOptions o;
  o.t_end = 10.0;
  o.rtol = 1e-12;
  o.atol = 1e-14;
  const SpatialRunResult run = simulate_spatial(b.pb, *b.hand, b.initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  const double scale = b.pb.object.mass * g * (R - r);  // the energy of a fall across the bowl
  const double e0 = run.steps.front().energy;
  double worst = 0, lowest_fn = INFINITY;
  for (const SpatialSample& s : run.steps) {
    worst = std::max(worst, std::abs(s.energy - e0));
    lowest_fn = std::min(lowest_fn, s.force_normal);
    ASSERT_LT(s.constraint_residual, 1e-12) << "t " << s.t;
  }
  EXPECT_LT(worst / scale, 1e-9) << run.stats.steps << " steps";
  EXPECT_GT(lowest_fn, 0);
  // It moved: the centre swung through the bottom and round.
  EXPECT_GT((run.final.state.position - run.steps.front().state.position).norm(), 1e-3);
}

TEST(SpatialRun, BallInABowlOscillatesAtTheClosedFormFrequency) {
  // Small oscillations of a uniform ball rolling in a spherical bowl: omega^2 = 5 g / (7 (R - r)).
  const double R = 0.3, r = 0.05, g = 9.8;
  const BowlRun b = ball_in_bowl(R, r, 1e-3, 0.0);
  const double omega = std::sqrt(5 * g / (7 * (R - r))), period = 2 * kPi / omega;
  SpatialRunOptions o;
  o.t_end = 5.2 * period;
  o.rtol = 1e-12;
  o.atol = 1e-15;
  o.max_step = period / 200;
  const SpatialRunResult run = simulate_spatial(b.pb, *b.hand, b.initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  // Downward crossings of x = 0 (the bottom), located by cubic Hermite interpolation of x and
  // its rate between steps.
  std::vector<double> crossings;
  for (std::size_t i = 1; i < run.steps.size(); ++i) {
    const SpatialSample &a = run.steps[i - 1], &c = run.steps[i];
    const double xa = a.state.position.x(), xc = c.state.position.x();
    if (!(xa > 0 && xc <= 0)) continue;
    double lo = 0, hi = 1;
    const double h = c.t - a.t, va = a.state.velocity.x() * h, vc = c.state.velocity.x() * h;
    const auto x_at = [&](double s) {
      const double s2 = s * s, s3 = s2 * s;
      return (2 * s3 - 3 * s2 + 1) * xa + (s3 - 2 * s2 + s) * va + (-2 * s3 + 3 * s2) * xc +
             (s3 - s2) * vc;
    };
    for (int it = 0; it < 60; ++it) ((x_at(0.5 * (lo + hi)) > 0) ? lo : hi) = 0.5 * (lo + hi);
    crossings.push_back(a.t + 0.5 * (lo + hi) * h);
  }
  ASSERT_GE(crossings.size(), 5u);
  const double measured = (crossings.back() - crossings.front()) / (crossings.size() - 1);
  EXPECT_NEAR(measured / period, 1.0, 1e-6) << crossings.size() << " crossings";
}

TEST(SpatialRun, ABallLargerThanItsBowlIsRefused) {
  // Relative curvature 1/r - 1/R: positive for a ball smaller than the bowl, negative for one
  // larger (it would touch the rim, not the bottom).
  BowlRun b = ball_in_bowl(0.3, 0.05, 0.1, 0.0);
  SpatialRunOptions o;
  o.t_end = 0.01;
  EXPECT_NO_THROW(simulate_spatial(b.pb, *b.hand, b.initial, 0.0, o));
  b = ball_in_bowl(0.3, 0.4, 0.1, 0.0);
  try {
    simulate_spatial(b.pb, *b.hand, b.initial, 0.0, o);
    FAIL() << "a ball larger than its bowl was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("does not fit the hand's curvature"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("-0.833333 1/m"), std::string::npos) << e.what();
  }
}

TEST(SpatialRun, BadProblemsAndOptionsAreRefused) {
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(0.02);
  const FixedHand3 hand;
  SpatialState s = ball_on(pb, hand.at(0), 0.02, SurfaceParam::Zero(), Vec3::Zero(), 1.0);
  SpatialRunOptions o;
  o.t_end = -1;
  EXPECT_THROW(simulate_spatial(pb, hand, s, 0.0, o), std::invalid_argument);
  o.t_end = 1;
  o.rtol = 0;
  EXPECT_THROW(simulate_spatial(pb, hand, s, 0.0, o), std::invalid_argument);
  o.rtol = 1e-10;
  pb.object.inertia(0, 1) = 1;  // not symmetric
  EXPECT_THROW(simulate_spatial(pb, hand, s, 0.0, o), std::invalid_argument);
  EXPECT_THROW(uniform_ball(-1), std::invalid_argument);
  EXPECT_THROW(SpinningHand3(Vec3::Zero(), 1.0), std::invalid_argument);
}

}  // namespace
}  // namespace flatland::sim
