// Rolling dynamics against closed forms, the two formulations against each other, integrators,
// events and drift control.
#include "flatland/sim/roots.hpp"
#include "flatland/sim/simulate.hpp"
#include "sim/rolling_support.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

using namespace flatland::sim;

namespace {

using flatland_test::kG;

RunOptions tight(double t_end, Formulation f) {
  RunOptions o;
  o.t_end = t_end;
  o.formulation = f;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  o.events.stop_on_contact_loss = false;
  return o;
}

class BothFormulations : public ::testing::TestWithParam<Formulation> {};

}  // namespace

// A uniform disk on a fixed incline of angle alpha: centre acceleration (2/3) g sin(alpha).
TEST_P(BothFormulations, InclineAcceleration) {
  const double alpha = 0.3;
  auto pb =
      problem(std::make_shared<LineCurve>(Vec2::Zero(), Vec2(std::cos(alpha), -std::sin(alpha))),
              make_uniform_disk(0.05), std::make_shared<FixedHand>(0.0));
  InitialContact ic;
  ic.s_h = 0.0;
  const double t = 1.0;
  const RunResult r = simulate(pb, ic, tight(t, GetParam()));
  const double a = 2.0 * r.final.s_h / (t * t);  // s = a t^2 / 2 (s is arc length here)
  const double expected = 2.0 / 3.0 * kG * std::sin(alpha);
  EXPECT_NEAR(a / expected - 1.0, 0.0, 1e-8);
  EXPECT_NEAR(r.final.sddot_h / expected - 1.0, 0.0, 1e-8);
  // The contact force balances gravity across the incline: f_n = m g cos(alpha).
  EXPECT_NEAR(r.final.fn_ratio, std::cos(alpha), 1e-9);
  EXPECT_NEAR(r.final.mu_required, std::tan(alpha) / 3.0, 1e-9);  // f_t = m g sin / 3
}

// A uniform disk of radius r in a circular well of radius R: small-oscillation period
// 2 pi sqrt(3 (R - r) / (2 g)).
TEST_P(BothFormulations, WellOscillationPeriod) {
  const double R = 0.2, r = 0.05;
  auto pb = problem(std::make_shared<CircleCurve>(Vec2(0, R), R, CircleCurve::Side::kConcaveWell),
                    make_uniform_disk(r), std::make_shared<FixedHand>(0.0));
  const double expected = 2 * std::numbers::pi * std::sqrt(3 * (R - r) / (2 * kG));
  InitialContact ic;
  ic.s_h = 1e-5;  // amplitude small enough that the nonlinear correction (amp^2/16) is < 1e-11
  RunOptions o = tight(3.2 * expected, GetParam());
  o.integrator.atol = 1e-19;
  const RunResult r1 = simulate(pb, ic, o);
  // Upward zero crossings of s_h, located on the dense output.
  std::vector<double> crossings;
  const auto& S = r1.steps;
  for (std::size_t i = 1; i < S.size(); ++i)
    if (S[i - 1].s_h < 0 && S[i].s_h >= 0)
      crossings.push_back(brent_root([&](double t) { return r1.trajectory.s_h(t); }, S[i - 1].t,
                                     S[i].t, S[i - 1].s_h, S[i].s_h, 1e-14)
                              .x);
  ASSERT_GE(crossings.size(), 3u);
  const double period = (crossings[2] - crossings[0]) / 2.0;
  EXPECT_NEAR(period / expected - 1.0, 0.0, 1e-8);
}

// With the hand fixed, the disk rocks in the palm well across the junction s_h = -1 for 100 s:
// mechanical energy is conserved; in the general formulation the constraints hold throughout.
TEST_P(BothFormulations, EnergyConservedOverHundredSecondsWithHandFixed) {
  auto pb = problem(std::make_shared<PolynomialHand>(0.18, -0.18, -0.252, 0.216),
                    make_uniform_disk(0.051), std::make_shared<FixedHand>(0.0));
  InitialContact ic;
  ic.s_h = -0.8;
  const RunResult r = simulate(pb, ic, tight(100.0, GetParam()));
  ASSERT_EQ(r.reason, StopReason::kEndTime);
  EXPECT_GT(r.stats.junction_crossings, 100);  // it really did cross the palm's middle often
  const double e0 = energy(r.initial, pb->object, kG);
  // `scale` is the largest kinetic energy: the part of the energy that actually moves.
  double scale = 0, worst = 0;
  for (const Sample& s : r.steps) {
    scale = std::max(scale, 0.5 * pb->object.mass * s.object_velocity.squaredNorm() +
                                0.5 * pb->object.inertia * s.object_angular_velocity *
                                    s.object_angular_velocity);
    worst = std::max(worst, std::abs(energy(s, pb->object, kG) - e0));
    EXPECT_LE(s.constraint_residual, 1e-12);
  }
  ASSERT_GT(scale, 0.0);
  // Relative to the total energy (potential from the pivot) and, stricter, to the kinetic energy.
  EXPECT_LE(worst / std::abs(e0), 1e-9);
  EXPECT_LE(worst / scale, 1e-8);
}

INSTANTIATE_TEST_SUITE_P(Dynamics, BothFormulations,
                         ::testing::Values(Formulation::kReduced, Formulation::kGeneral),
                         [](const auto& info) { return to_string(info.param); });

TEST(Dynamics, GeneralAndReducedAgreeOnTheButterfly) {
  auto pb = butterfly();
  const InitialContact ic;
  const RunResult red = simulate(pb, ic, tight(1.181, Formulation::kReduced));
  const RunResult gen = simulate(pb, ic, tight(1.181, Formulation::kGeneral));
  EXPECT_EQ(red.formulation, Formulation::kReduced);
  EXPECT_EQ(gen.formulation, Formulation::kGeneral);
  double worst = 0, worst_fn = 0;
  for (double t = 0; t <= 1.181; t += 0.001) {
    const Sample a = red.trajectory.sample(t), b = gen.trajectory.sample(t);
    worst = std::max(worst, std::abs(a.s_h - b.s_h));
    worst_fn = std::max(worst_fn, std::abs(a.fn_ratio - b.fn_ratio));
    EXPECT_NEAR((a.object_position - b.object_position).norm(), 0, 1e-9);
  }
  EXPECT_LE(worst, 1e-9);
  EXPECT_LE(worst_fn, 1e-7);
  // The disk crosses the palm's middle during the dip and comes back (paper-notes.md).
  EXPECT_GE(gen.stats.junction_crossings, 2);
  EXPECT_LE(gen.stats.max_constraint_residual, 1e-12);
  EXPECT_LE(gen.stats.max_redundant_residual, 1e-9);
  for (const Sample& s : gen.steps) EXPECT_LE(s.constraint_residual, 1e-12);
}

// The general formulation with an ellipse of equal axes is a disk: it must match the reduced
// disk model (an independent check of the general equations with another object class).
TEST(Dynamics, EllipseWithEqualAxesMatchesDisk) {
  auto disk = butterfly();
  auto round = butterfly();
  round->object = make_uniform_ellipse(0.051, 0.051);
  InitialContact ic;
  const RunResult a = simulate(disk, ic, tight(1.181, Formulation::kReduced));
  ic.s_o = -0.5 * std::numbers::pi;
  const RunResult b = simulate(round, ic, tight(1.181, Formulation::kAuto));
  EXPECT_EQ(b.formulation, Formulation::kGeneral);
  EXPECT_NEAR(a.final.s_h, b.final.s_h, 1e-8);
}

// A genuine ellipse rocking on a flat fixed hand conserves energy (general formulation only).
TEST(Dynamics, EllipseRockingConservesEnergy) {
  auto pb = problem(std::make_shared<LineCurve>(Vec2::Zero(), Vec2(1, 0)),
                    make_uniform_ellipse(0.06, 0.03), std::make_shared<FixedHand>(0.0));
  InitialContact ic;
  ic.s_h = 0.0;
  ic.s_o = -0.5 * std::numbers::pi + 0.3;  // tilted off its flat side: it rocks
  const RunResult r = simulate(pb, ic, tight(5.0, Formulation::kAuto));
  const double e0 = energy(r.initial, pb->object, kG);
  double worst = 0, swing = 0;
  for (const Sample& s : r.steps) {
    worst = std::max(worst, std::abs(energy(s, pb->object, kG) - e0));
    swing = std::max(swing, std::abs(s.object_angle - r.initial.object_angle));
  }
  EXPECT_GT(swing, 0.2);
  EXPECT_LE(worst / (pb->object.mass * kG * 0.03), 1e-9);
  EXPECT_THROW(simulate(pb, ic, tight(1.0, Formulation::kReduced)), std::invalid_argument);
}

// Classical RK4 converges with order 4: halving the step divides the error by about 16 (checked
// on the dip, before the first junction), and it converges through the junctions too.
TEST(Integrators, Rk4ConvergesWithOrderFour) {
  auto pb = butterfly();
  auto rk4 = [&](double t_end, double h) {
    RunOptions o = tight(t_end, Formulation::kReduced);
    o.integrator.method = Method::kRungeKutta4;
    o.integrator.fixed_step = h;
    o.record = false;
    return simulate(pb, {}, o);
  };
  const double smooth_end = 0.15;  // the first junction crossing is at t ~ 0.21 s
  const RunResult ref_smooth = simulate(pb, {}, tight(smooth_end, Formulation::kReduced));
  ASSERT_EQ(ref_smooth.stats.junction_crossings, 0);
  const double e1 = std::abs(rk4(smooth_end, 4e-3).final.s_h - ref_smooth.final.s_h);
  const double e2 = std::abs(rk4(smooth_end, 2e-3).final.s_h - ref_smooth.final.s_h);
  const double e3 = std::abs(rk4(smooth_end, 1e-3).final.s_h - ref_smooth.final.s_h);
  EXPECT_NEAR(e1 / e2, 16.0, 2.0);
  EXPECT_NEAR(e2 / e3, 16.0, 2.0);
  const double ref = simulate(pb, {}, tight(1.181, Formulation::kReduced)).final.s_h;
  double last = 1.0;
  for (double h : {1e-3, 5e-4, 2.5e-4}) {
    const RunResult r = rk4(1.181, h);
    EXPECT_EQ(r.stats.junction_crossings, 2);
    const double e = std::abs(r.final.s_h - ref);
    EXPECT_LT(e, last / 8.0);
    last = e;
  }
  EXPECT_LT(last, 1e-7);
}

// Dormand-Prince error decreases with tolerance.
TEST(Integrators, DormandPrinceErrorFollowsTolerance) {
  auto pb = butterfly();
  const double ref = simulate(pb, {}, tight(1.181, Formulation::kReduced)).final.s_h;
  double last = 1.0;
  for (double rtol : {1e-5, 1e-7, 1e-9}) {
    RunOptions o = tight(1.181, Formulation::kReduced);
    o.integrator.rtol = rtol;
    o.integrator.atol = rtol * 1e-2;
    const double e = std::abs(simulate(pb, {}, o).final.s_h - ref);
    EXPECT_LT(e, 1e3 * rtol);
    EXPECT_LT(e, last);
    last = e;
  }
}

// Too fast a motion throws the disk: the loss of contact is located where f_n reaches 0.
TEST(Events, ContactLossIsLocated) {
  auto pb = butterfly(0.9, -1.16);
  RunOptions o = tight(0.9, Formulation::kReduced);
  o.events.stop_on_contact_loss = true;
  const RunResult r = simulate(pb, {}, o);
  ASSERT_EQ(r.reason, StopReason::kContactLost);
  EXPECT_LT(r.final.t, 0.9);
  EXPECT_NEAR(r.final.fn_ratio, 0.0, 1e-7);
  EXPECT_TRUE(r.contact_lost);
  // Without stopping, rolling is enforced and the force goes negative past that time.
  o.events.stop_on_contact_loss = false;
  const RunResult through = simulate(pb, {}, o);
  EXPECT_LT(through.fn_min_ratio, 0.0);
  EXPECT_NEAR(through.trajectory.sample(r.final.t).fn_ratio, 0.0, 1e-7);
}

TEST(Events, SlipIsLocatedAtTheFrictionLimit) {
  auto pb = butterfly();
  RunOptions o = tight(1.181, Formulation::kReduced);
  pb->contact.mu = 0.2;  // the paper's solution needs about 0.306
  const RunResult r = simulate(pb, {}, o);
  ASSERT_EQ(r.reason, StopReason::kSlip);
  EXPECT_NEAR(std::abs(r.final.force_tangential), 0.2 * r.final.force_normal,
              1e-7 * std::abs(r.final.force_normal));
  pb->contact.mu = 0.5;
  EXPECT_EQ(simulate(pb, {}, o).reason, StopReason::kEndTime);
}

TEST(Events, JunctionCrossingsLandOnTheJunction) {
  auto pb = butterfly();
  const RunResult r = simulate(pb, {}, tight(1.181, Formulation::kReduced));
  int junctions = 0;
  for (const RecordedEvent& e : r.events)
    if (e.kind == EventKind::kJunction) {
      ++junctions;
      EXPECT_NEAR(std::abs(e.s_h), 1.0, 1e-9);
    }
  EXPECT_EQ(junctions, r.stats.junction_crossings);
  EXPECT_GE(junctions, 2);
}

TEST(Integrators, BadSettingsAreRejected) {
  auto pb = butterfly();
  RunOptions o = tight(1.0, Formulation::kReduced);
  o.integrator.rtol = -1;
  EXPECT_THROW(simulate(pb, {}, o), std::invalid_argument);
  o = tight(1.0, Formulation::kReduced);
  o.integrator.method = Method::kRungeKutta4;
  o.integrator.fixed_step = 0;
  EXPECT_THROW(simulate(pb, {}, o), std::invalid_argument);
  o = tight(-1.0, Formulation::kReduced);
  EXPECT_THROW(simulate(pb, {}, o), std::invalid_argument);
  InitialContact ic;
  ic.s_h = std::nan("");
  EXPECT_THROW(simulate(pb, ic, tight(1.0, Formulation::kReduced)), std::invalid_argument);
}
