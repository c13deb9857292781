// The spatial run's integrators, events, dense output and hand motions against closed forms and
// independent computations: a ball rolling off a dome leaves it at cos(theta) = 10/17 (with its
// start speed's share) and slips where 2 sin(theta) / (17 cos(theta) - 10) reaches mu; a ball
// leaving a dish's patch stops on the patch's edge; DOPRI5, DOP853 and RK4 (at its 4th order) on
// Weltner's turntable, also between steps; tabulated accelerations move the hand as their
// integrals and a ball on an accelerating plate at 2/7 of its acceleration; the paper's
// butterfly about the z axis carries a ball on the extruded hand as the planar run carries a disk.
#include "flatland/sim/rolling.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_run.hpp"
#include "flatland/sim/spec.hpp"

#include "sim/spatial_support.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace flatland::sim {
namespace {

using flatland_test::kG;

/// A ball of radius r on top of a fixed dome (a sphere of radius R, its chart's (0, 0) point on
/// top, the contact running along the chart's equator), moving at v0 along world x.
struct DomeRun {
  SpatialRollingProblem pb;
  std::unique_ptr<FixedHand3> hand;
  SpatialState initial;
};

DomeRun ball_on_dome(double R, double r, double v0) {
  DomeRun d;
  d.pb.hand = std::make_shared<EllipsoidSurface>(
      EllipsoidSurface::sphere(R, EllipsoidSurface::Side::kConvexBody));
  d.pb.object = uniform_ball(r, 0.1);
  Eigen::Matrix3d rotation;  // hand x -> world z (up), hand y -> world x
  rotation << 0, 1, 0, 0, 0, 1, 1, 0, 0;
  d.hand = std::make_unique<FixedHand3>(rotation);
  d.initial = ball_on(d.pb, d.hand->at(0), r, SurfaceParam::Zero(), Vec3(v0, 0, 0), R / (R + r));
  return d;
}

/// The angle of the ball's centre from the top of the dome.
double angle_from_top(const SpatialSample& s, double rho) {
  return std::acos(std::clamp(s.state.position.z() / rho, -1.0, 1.0));
}

TEST(SpatialEvents, ABallLeavesADomeWhereItsNormalForceVanishes) {
  // Energy (7/10) m (v^2 - v0^2) = m g rho (1 - cos) and N = m g cos - m v^2 / rho, rho = R + r:
  // N = 0 at cos = (10/17) (1 + 7 v0^2 / (10 g rho)).
  const double R = 0.2, r = 0.03, v0 = 0.05, rho = R + r;
  const DomeRun d = ball_on_dome(R, r, v0);
  SpatialRunOptions o;
  o.t_end = 10;
  const SpatialRunResult run = simulate_spatial(d.pb, *d.hand, d.initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kContactLost);
  const double expected = std::acos(10.0 / 17.0 * (1 + 7 * v0 * v0 / (10 * kG * rho)));
  EXPECT_NEAR(angle_from_top(run.final, rho), expected, 1e-8);
  EXPECT_LT(std::abs(run.final.force_normal), 1e-7 * d.pb.object.mass * kG);
  EXPECT_GT(run.stats.event_evals, 0);
  EXPECT_LT(run.final.t, o.t_end);
  EXPECT_EQ(run.samples.back().t, run.final.t);
}

TEST(SpatialEvents, ABallSlipsOffADomeWhereItNeedsMoreThanMu) {
  // Friction (2/7) m g sin, N = (m g / 7) (17 cos - 10) - m v0^2 / rho: the run stops where
  // their ratio reaches mu, found here by bisection on that formula.
  const double R = 0.2, r = 0.03, v0 = 0.05, rho = R + r, mu = 0.3;
  DomeRun d = ball_on_dome(R, r, v0);
  d.pb.mu = mu;
  const auto required = [&](double a) {
    return 2 * std::sin(a) / (17 * std::cos(a) - 10 - 7 * v0 * v0 / (kG * rho));
  };
  double lo = 0, hi = std::acos(10.0 / 17.0);
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    const double need = required(mid);
    ((need > 0 && need < mu) ? lo : hi) = mid;
  }
  SpatialRunOptions o;
  o.t_end = 10;
  const SpatialRunResult run = simulate_spatial(d.pb, *d.hand, d.initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kSlip);
  EXPECT_NEAR(angle_from_top(run.final, rho), lo, 1e-8);
  EXPECT_NEAR(run.final.mu_required, mu, 1e-7);
  EXPECT_LE(run.stats.max_mu_required, mu + 1e-7);
  // Without friction's limit the same run goes on to lose its contact later.
  d.pb.mu.reset();
  const SpatialRunResult free = simulate_spatial(d.pb, *d.hand, d.initial, 0.0, o);
  EXPECT_EQ(free.stop, SpatialStop::kContactLost);
  EXPECT_GT(free.final.t, run.final.t);
}

TEST(SpatialEvents, ABallLeavingTheDishsPatchStopsOnItsEdge) {
  // A bowl whose chart stops 1 rad short of its poles (latitude 0.5708); the ball, sent from the
  // bottom towards a pole, stops where its contact reaches that latitude.
  const double R = 0.3, r = 0.05, margin = 1.0;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<EllipsoidSurface>(R, R, R, EllipsoidSurface::Side::kDish, margin);
  pb.object = uniform_ball(r, 0.1);
  // Hand z (the chart's pole axis) along world x, the bottom (world -z) at (u, v) = (0, 0).
  Eigen::Matrix3d rotation;
  rotation << 0, 0, 1, 0, 1, 0, -1, 0, 0;
  const FixedHand3 hand(rotation);
  const SpatialState initial =
      ball_on(pb, hand.at(0), r, SurfaceParam::Zero(), Vec3(1.0, 0, 0), R / (R - r));
  SpatialRunOptions o;
  o.t_end = 5;
  const SpatialRunResult run = simulate_spatial(pb, hand, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kLeftPatch);
  EXPECT_NEAR(run.final.state.s_h.y(), std::numbers::pi / 2 - margin, 1e-9);
  EXPECT_NEAR(run.final.state.s_h.x(), 0, 1e-9);
  // A start outside the patch is refused.
  SpatialState outside = initial;
  outside.s_h.y() = 0.6;
  SpatialRollingProblem beyond = pb;
  EXPECT_THROW(
      simulate_spatial(beyond, hand,
                       ball_on(pb, hand.at(0), r, SurfaceParam(0, 0.6), Vec3::Zero(), 1.0), 0.0, o),
      std::invalid_argument);
}

/// Weltner's turntable (test_spatial_run.cpp): the centre's largest distance from the closed
/// form over the samples, relative to the circle's radius.
struct Turntable {
  static constexpr double omega = 10.0, r = 0.02;
  SpatialRollingProblem pb;
  SpinningHand3 table{Vec3::UnitZ(), omega};
  Vec3 v0{0.05, 0.03, 0};
  SpatialState initial;
  Turntable() {
    pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
    pb.object = uniform_ball(r, 0.2);
    initial = ball_on(pb, table.at(0), r, SurfaceParam(0.12, -0.04), v0, 1.0);
  }
  double worst_error(const SpatialRunResult& run) const {
    const double k = 2.0 / 7.0 * omega;
    const Vec3 p0 = run.samples.front().state.position;
    const Vec3 c = p0 + Vec3::UnitZ().cross(v0) / k;
    double worst = 0;
    for (const SpatialSample& s : run.samples) {
      const Vec3 expected = c + Eigen::AngleAxisd(k * s.t, Vec3::UnitZ()) * (p0 - c);
      worst = std::max(worst, (s.state.position - expected).norm());
    }
    return worst / (v0.norm() / k);
  }
};

TEST(SpatialEvents, EveryIntegratorFollowsWeltnersCircle) {
  const Turntable tt;
  SpatialRunOptions o;
  o.t_end = 2.0;
  o.integrator.method = Method::kDormandPrince853;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  const SpatialRunResult dop853 = simulate_spatial(tt.pb, tt.table, tt.initial, 0.0, o);
  ASSERT_EQ(dop853.stop, SpatialStop::kEndTime);
  EXPECT_LT(tt.worst_error(dop853), 1e-9);
  o.integrator.method = Method::kDormandPrince54;
  const SpatialRunResult dopri5 = simulate_spatial(tt.pb, tt.table, tt.initial, 0.0, o);
  EXPECT_LT(tt.worst_error(dopri5), 1e-9);
  EXPECT_LT(dop853.stats.steps, dopri5.stats.steps / 3) << "the 8th order takes longer steps";
  // RK4 at (at least) its order: halving the step divides the error by 16 or more (24-31 measured
  // from 8 ms to 0.5 ms steps: the projection takes part of the error out).
  o.integrator.method = Method::kRungeKutta4;
  o.integrator.fixed_step = 4e-3;
  // The order is measured on the coarse steps' own error, which is beyond the energy audit's
  // default RK4 bound (1e-6 relative): that run would stop as a numerical failure first.
  o.integrator.energy_tolerance = 1.0;
  const SpatialRunResult coarse_run = simulate_spatial(tt.pb, tt.table, tt.initial, 0.0, o);
  ASSERT_EQ(coarse_run.stop, SpatialStop::kEndTime);
  const double coarse = tt.worst_error(coarse_run);
  o.integrator.fixed_step = 2e-3;
  const SpatialRunResult fine_run = simulate_spatial(tt.pb, tt.table, tt.initial, 0.0, o);
  const double fine = tt.worst_error(fine_run);
  EXPECT_EQ(fine_run.stats.steps, 1000);
  EXPECT_LT(fine, 1e-5);
  EXPECT_GT(coarse / fine, 14.0);
  EXPECT_LT(coarse / fine, 40.0);
}

TEST(SpatialEvents, DenseOutputSamplesTheCircleBetweenSteps) {
  const Turntable tt;
  for (const Method method : {Method::kDormandPrince54, Method::kDormandPrince853}) {
    SpatialRunOptions o;
    o.t_end = 2.0;
    o.sample_dt = 0.01;
    o.integrator.method = method;
    o.integrator.rtol = 1e-12;
    o.integrator.atol = 1e-14;
    const SpatialRunResult run = simulate_spatial(tt.pb, tt.table, tt.initial, 0.0, o);
    ASSERT_EQ(run.samples.size(), 201u);
    for (std::size_t i = 0; i < run.samples.size(); ++i) {
      ASSERT_NEAR(run.samples[i].t, 0.01 * static_cast<double>(i), 1e-12);
      ASSERT_LT(run.samples[i].constraint_residual, 1e-12);
    }
    EXPECT_LT(tt.worst_error(run), 1e-8);
  }
}

TEST(SpatialEvents, TabulatedAccelerationsIntegrateToThePose) {
  HandPose3 start;
  start.position = Vec3(0.1, -0.2, 0.3);
  start.velocity = Vec3(0.5, 0, -0.1);
  const Vec3 axis = Vec3(1, 2, 2) / 3;
  const TabulatedHand3 motion(
      {{0.0, Vec3(1, 0, 0), 2.0}, {0.5, Vec3(0, -3, 1), -1.0}, {1.0, Vec3::Zero(), 0.0}}, axis,
      start, 0.4);
  ASSERT_EQ(motion.breakpoints(), (std::vector<double>{0.0, 0.5, 1.0}));
  // The pose's derivatives by central differences within each segment.
  for (const double t : {-0.3, 0.2, 0.7, 1.4}) {
    const int seg = motion.segment_at(t);
    const double h = 1e-5;
    const HandPose3 p = motion.at(t, seg), a = motion.at(t - h, seg), b = motion.at(t + h, seg);
    EXPECT_LT(((b.position - a.position) / (2 * h) - p.velocity).norm(), 1e-8) << t;
    EXPECT_LT(((b.velocity - a.velocity) / (2 * h) - p.acceleration).norm(), 1e-8) << t;
    const Eigen::Matrix3d W = (b.rotation - a.rotation) / (2 * h) * p.rotation.transpose();
    EXPECT_LT((Vec3(W(2, 1), W(0, 2), W(1, 0)) - p.angular_velocity).norm(), 1e-8) << t;
    EXPECT_LT(((b.angular_velocity - a.angular_velocity) / (2 * h) - p.angular_acceleration).norm(),
              1e-8)
        << t;
  }
  // Continuous across the knots: both segments' formulas agree there.
  for (const double t : {0.0, 0.5, 1.0}) {
    const int right = motion.segment_at(t);
    const HandPose3 l = motion.at(t, right - 1), r = motion.at(t, right);
    EXPECT_LT((l.position - r.position).norm(), 1e-15);
    EXPECT_LT((l.velocity - r.velocity).norm(), 1e-15);
    EXPECT_LT((l.rotation - r.rotation).norm(), 1e-15);
  }
  // The closed form at the end: position p0 + v0 t + the integrals, angle along the axis.
  const HandPose3 end = motion.at(1.0);
  const Vec3 v_half = start.velocity + 0.5 * Vec3(1, 0, 0);
  const Vec3 p_half = start.position + 0.5 * start.velocity + 0.125 * Vec3(1, 0, 0);
  EXPECT_LT((end.position - (p_half + 0.5 * v_half + 0.125 * Vec3(0, -3, 1))).norm(), 1e-15);
  const double angle = 0.4 * 0.5 + 0.125 * 2.0 + 0.5 * (0.4 + 2.0 * 0.5) + 0.125 * -1.0;
  EXPECT_LT((end.rotation - Eigen::AngleAxisd(angle, axis).toRotationMatrix()).norm(), 1e-14);
  EXPECT_THROW(TabulatedHand3({{0.0, Vec3::Zero(), 0.0}}, axis), std::invalid_argument);
  EXPECT_THROW(TabulatedHand3({{0.0, Vec3::Zero(), 0.0}, {0.0, Vec3::Zero(), 0.0}}, axis),
               std::invalid_argument);
  EXPECT_THROW(TabulatedHand3({{0.0, Vec3::Zero(), 0.0}, {1.0, Vec3::Zero(), 0.0}}, Vec3::Zero()),
               std::invalid_argument);
}

TEST(SpatialEvents, ABallOnAnAcceleratingPlateFollowsAtTwoSevenths) {
  // The plate accelerates at a along x from t = 0.1 s: friction m a_b and the ball's spin give
  // a_b = (2/7) a while the plate accelerates, and nothing before.
  const double r = 0.02, a = 3.0;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  pb.object = uniform_ball(r, 0.2);
  const TabulatedHand3 plate({{0.1, Vec3(a, 0, 0), 0.0}, {0.6, Vec3::Zero(), 0.0}}, Vec3::UnitZ());
  const SpatialState initial =
      ball_on(pb, plate.at(0), r, SurfaceParam::Zero(), Vec3(0.02, 0.01, 0), 1.0);
  SpatialRunOptions o;
  o.t_end = 0.8;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  const SpatialRunResult run = simulate_spatial(pb, plate, initial, 0.0, o);
  ASSERT_EQ(run.stop, SpatialStop::kEndTime);
  EXPECT_EQ(run.stats.restarts, 2);
  const Vec3 p0 = run.samples.front().state.position;
  for (const SpatialSample& s : run.samples) {
    const double tau = std::clamp(s.t, 0.1, 0.6) - 0.1, after = std::max(s.t - 0.6, 0.0);
    const Vec3 expected = p0 + s.t * Vec3(0.02, 0.01, 0) +
                          (2.0 / 7.0) * a * Vec3(0.5 * tau * tau + 0.5 * after, 0, 0);
    ASSERT_LT((s.state.position - expected).norm(), 1e-11) << "t " << s.t;
  }
}

TEST(SpatialEvents, TheButterflyCarriesABallOnTheExtrudedHandAsThePlanarRunADisk) {
  // The paper's butterfly about z, a ball (I = 2/5 m r^2) on the extruded hand in the plane z =
  // 0, against the planar general model's run of a disk of that inertia (dense output at the
  // same times): s_h(t), the forces and the object's path agree while the contact stays on the
  // palm's piece of the outline, and the k* that puts the disk on the tip at T puts the ball
  // there too.
  SimulationSpec spec;
  spec.object.inertia = 0.4 * spec.object.mass * spec.object.radius * spec.object.radius;
  spec.run.formulation = Formulation::kGeneral;
  spec.run.integrator.rtol = 1e-12;
  spec.run.integrator.atol = 1e-14;
  // k* of the planar disk with the ball's inertia: s_h(T) = 0 at the half period.
  spec.motion.k = solve_k(spec, spec.motion.period).k;
  const double T = 0.5 * spec.motion.period;
  const auto planar = build_problem(spec);
  const RunResult reference = run_spec(spec);
  ASSERT_FALSE(reference.trajectory.empty());

  // From t = 0.3 s, after the dip has taken the disk back over the palm's edge (s_h < -1, onto
  // the next piece of the outline) and returned it, until the contact reaches the tip (s_h = 1).
  const double t0 = 0.3;
  const Sample start = reference.trajectory.sample(t0);
  ASSERT_GT(start.s_h, -1);
  SpatialRollingProblem pb;
  pb.object = uniform_ball(spec.object.radius, spec.object.mass);
  pb.gravity = Vec3(0, -planar->gravity, 0);
  pb.hand = std::make_shared<ExtrudedSurface>(planar->hand, planar->hand->piece_at(start.s_h, +1));
  SpatialState st;
  st.position = Vec3(start.object_position.x(), start.object_position.y(), 0);
  st.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(start.object_angle, Vec3::UnitZ()));
  st.s_o = SurfaceParam(start.s_o, 0);  // the sphere's equator is the disk's rim
  st.s_h = SurfaceParam(start.s_h, 0);
  st.velocity = Vec3(start.object_velocity.x(), start.object_velocity.y(), 0);
  st.angular_velocity = Vec3(0, 0, start.object_angular_velocity);
  st.sdot_o = SurfaceParam(start.sdot_o, 0);
  st.sdot_h = SurfaceParam(start.sdot_h, 0);
  const PlanarHand3 motion(planar->motion);
  SpatialRunOptions o;
  o.t_end = spec.end_time();
  o.sample_dt = 0.01;
  o.integrator = spec.run.integrator;
  const SpatialRunResult run = simulate_spatial(pb, motion, st, t0, o);
  ASSERT_EQ(run.stop, SpatialStop::kLeftPatch);
  EXPECT_NEAR(run.final.state.s_h.x(), 1.0, 1e-9);
  EXPECT_GT(run.final.t, 0.7);
  int compared = 0;
  for (const SpatialSample& s : run.samples) {
    const Sample p = reference.trajectory.sample(s.t);
    SCOPED_TRACE("t " + std::to_string(s.t));
    ASSERT_NEAR(s.state.s_h.x(), p.s_h, 1e-9);
    ASSERT_NEAR(s.state.s_h.y(), 0, 1e-12);
    ASSERT_NEAR(s.force_normal, p.force_normal, 1e-9 * (1 + std::abs(p.force_normal)));
    ASSERT_NEAR(s.state.position.x(), p.object_position.x(), 1e-10);
    ASSERT_NEAR(s.state.position.y(), p.object_position.y(), 1e-10);
    ASSERT_NEAR(s.state.position.z(), 0, 1e-12);
    ++compared;
  }
  EXPECT_GT(compared, 30);
  // The spatial run at the planar k* reaches the tip at T as well: the same k* solves both.
  o.t_end = T;
  o.sample_dt = 0;
  const SpatialRunResult to_T = simulate_spatial(pb, motion, st, t0, o);
  ASSERT_EQ(to_T.stop, SpatialStop::kEndTime);
  EXPECT_NEAR(reference.trajectory.sample(T).s_h, 0.0, 1e-9);
  EXPECT_NEAR(to_T.final.state.s_h.x(), 0.0, 1e-9);
}

}  // namespace
}  // namespace flatland::sim
