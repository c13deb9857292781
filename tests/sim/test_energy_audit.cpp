// The energy audit every planar run keeps (sim/energy.hpp): a fixed hand does no work, the hand's
// work equals the joint's torque integrated over its rate (computed here from the recorded
// forces and the hand's geometry, apart from the audit), the losses only take energy, impacts are
// booked by the law, every formulation balances within its bound, and a deliberately wrong
// impulse ends the run as a numerical failure instead of a success.
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spec.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

using namespace flatland::sim;

namespace {

using flatland_test::kDeg;
using flatland_test::kG;

std::shared_ptr<RollingProblem> paper_problem(std::shared_ptr<const HandMotion> motion,
                                              double g = kG) {
  auto pb = std::make_shared<RollingProblem>();
  pb->hand = std::make_shared<PolynomialHand>(0.18, -0.18, -0.252, 0.216);
  pb->object = make_uniform_disk(0.051);
  pb->motion = std::move(motion);
  pb->gravity = g;
  return pb;
}

RunOptions options(double t_end, double rtol = 1e-10) {
  RunOptions o;
  o.t_end = t_end;
  o.integrator.rtol = rtol;
  o.integrator.atol = rtol * 1e-2;
  return o;
}

/// The air table's throw: the paper's hand at 5 deg playing a butterfly faster than the fastest
/// that keeps contact (as assets/scenes/throw-catch.yaml): it slips, flies, bounces and is caught.
std::shared_ptr<RollingProblem> throw_problem() {
  const double g = kG * std::sin(5 * kDeg);
  auto pb = paper_problem(std::make_shared<ButterflyMotion>(3.556, -1.155794), g);
  pb->contact.mu = 0.8;
  pb->contact.mu_kinetic = 0.6;
  pb->contact.restitution = 0.4;
  pb->contact.drag = 0.015;
  pb->contact.drag_angular = 2e-5;
  pb->contact.rolling_resistance = 5e-5;
  return pb;
}

RunOptions hybrid_options(double t_end) {
  RunOptions o = options(t_end);
  o.model = ContactModel::kHybrid;
  return o;
}

void expect_holds(const EnergyAudit& a) {
  EXPECT_FALSE(a.broken);
  EXPECT_LE(std::abs(a.balance), a.bound());
  EXPECT_LE(a.worst, a.bound());
  EXPECT_GT(a.checks, 0);
  // The terms add up to the balance (the report's arithmetic).
  EXPECT_NEAR(a.final - a.initial - a.work_hand - a.work_losses - a.impact_losses, a.balance,
              1e-15 * (std::abs(a.final) + std::abs(a.initial) + 1));
}

}  // namespace

// A disk rocking in the palm's well for 10 s, the hand held still: the hand's point at the
// contact never moves, so the hand does no work at all, and the energy is conserved to within
// the bound (the junction s_h = -1 is crossed on every swing).
TEST(EnergyAudit, AFixedHandDoesNoWork) {
  auto pb = paper_problem(std::make_shared<FixedHand>(0.0));
  InitialContact ic;
  ic.s_h = -0.8;
  RunOptions o = options(10.0);
  o.events.stop_on_contact_loss = false;
  const RunResult r = simulate(pb, ic, o);
  ASSERT_EQ(r.reason, StopReason::kEndTime);
  EXPECT_GT(r.stats.junction_crossings, 10);
  EXPECT_EQ(r.audit.work_hand, 0.0);
  EXPECT_EQ(r.audit.work_losses, 0.0);
  expect_holds(r.audit);
  EXPECT_LE(std::abs(r.audit.final - r.audit.initial), r.audit.bound());
  EXPECT_EQ(r.audit.tolerance, 1e3 * 1e-10);  // the default: 1000 x rtol
}

// The paper's butterfly (rolling model): the hand's work on the disk equals the work the joint
// does against the disk's reaction, the integral of theta' (rho x f), computed here from the
// recorded contact forces and the hand's geometry by Simpson's rule on a fine grid of the dense
// output. Both agree with E(2T) - E(0).
TEST(EnergyAudit, TheHandsWorkIsTheJointTorqueTimesItsRate) {
  auto pb = paper_problem(std::make_shared<ButterflyMotion>(1.181, -1.1393));
  RunOptions o = options(1.181, 1e-12);
  o.events.stop_on_contact_loss = false;
  const RunResult r = simulate(pb, {}, o);
  ASSERT_EQ(r.reason, StopReason::kEndTime);
  expect_holds(r.audit);
  const auto power = [&](double t) {
    const Sample s = r.trajectory.sample(t);
    const int piece = pb->hand->piece_at(s.s_h, s.sdot_h < 0 ? -1 : +1);
    const CurveGeometry g = pb->hand->geometry(s.s_h, piece);
    const double c = std::cos(s.theta), sn = std::sin(s.theta);
    const auto turn = [&](const Vec2& v) {
      return Vec2(c * v.x() - sn * v.y(), sn * v.x() + c * v.y());
    };
    const Vec2 force = s.force_normal * turn(g.normal) + s.force_tangential * turn(g.tangent);
    return s.theta_dot * cross2(turn(g.point), force);
  };
  const int n = 20000;  // even
  const double h = 1.181 / n;
  double work = power(0.0) + power(1.181);
  for (int i = 1; i < n; ++i) work += (i % 2 ? 4.0 : 2.0) * power(i * h);
  work *= h / 3.0;
  EXPECT_GT(std::abs(r.audit.work_hand), 1e-4);  // the hand does work on this motion
  EXPECT_NEAR(r.audit.work_hand, work, 1e-9);
  EXPECT_NEAR(r.audit.final - r.audit.initial, work, 1e-9);
}

// The throw of the air table: the disk rolls, slips, flies, bounces and is caught, with drag,
// angular drag and rolling resistance. The losses only take energy, the impacts only dissipate
// (restitution 0.4), and the balance holds through every mode and impact.
TEST(EnergyAudit, LossesAndImpactsOnlyTakeEnergy) {
  const RunResult r = simulate(throw_problem(), {}, hybrid_options(5.0));
  ASSERT_EQ(r.reason, StopReason::kEndTime);
  ASSERT_GE(r.stats.impacts, 2);
  EXPECT_GT(r.stats.mode_time[static_cast<int>(ContactMode::kFlight)], 0.0);
  EXPECT_GT(r.stats.mode_time[static_cast<int>(ContactMode::kSliding)], 0.0);
  EXPECT_LT(r.audit.work_losses, 0.0);
  EXPECT_LT(r.audit.impact_losses, 0.0);
  expect_holds(r.audit);
}

// The same throw with every impulse applied 2 % too strong: the state's velocities no longer
// follow the impact law the audit books, so the run stops at the first impact as a numerical
// failure, never a success. With the factor 1 (control) it runs to the end.
TEST(EnergyAudit, AWrongImpulseEndsTheRunAsANumericalFailure) {
  RunOptions o = hybrid_options(5.0);
  const RunResult good = simulate(throw_problem(), {}, o);
  ASSERT_EQ(good.reason, StopReason::kEndTime);
  double t_first_impact = NAN;
  for (const RecordedEvent& e : good.events)
    if (e.kind == EventKind::kImpact) {
      t_first_impact = e.t;
      break;
    }
  ASSERT_TRUE(std::isfinite(t_first_impact));

  o.testing_impulse_factor = 1.02;
  const RunResult bad = simulate(throw_problem(), {}, o);
  EXPECT_EQ(bad.reason, StopReason::kNumericalFailure);
  EXPECT_TRUE(bad.audit.broken);
  EXPECT_GT(std::abs(bad.audit.balance), bad.audit.bound());
  EXPECT_DOUBLE_EQ(bad.audit.t_broken, t_first_impact);
  EXPECT_DOUBLE_EQ(bad.final.t, t_first_impact);  // it stopped there
  bool recorded = false;
  for (const RecordedEvent& e : bad.events) recorded |= e.kind == EventKind::kNumericalFailure;
  EXPECT_TRUE(recorded);
}

// The paper's A x = b formulation balances as the reduced one does: an ellipse rolling the
// butterfly (rolling model), and the general formulation of a disk through the throw's slip,
// flight and catch.
TEST(EnergyAudit, TheGeneralFormulationBalancesToo) {
  auto ellipse = paper_problem(std::make_shared<ButterflyMotion>(1.181, -1.1393));
  ellipse->object = make_uniform_ellipse(0.06, 0.045);
  RunOptions o = options(0.5);
  o.events.stop_on_contact_loss = false;
  o.formulation = Formulation::kGeneral;
  InitialContact ic;
  ic.s_h = -1.0;
  const RunResult r = simulate(ellipse, ic, o);
  ASSERT_EQ(r.reason, StopReason::kEndTime);
  EXPECT_NE(r.audit.work_hand, 0.0);
  expect_holds(r.audit);

  RunOptions h = hybrid_options(5.0);
  h.formulation = Formulation::kGeneral;
  const RunResult g = simulate(throw_problem(), {}, h);
  ASSERT_EQ(g.reason, StopReason::kEndTime);
  EXPECT_GE(g.stats.impacts, 1);
  expect_holds(g.audit);
}

// The balance follows the tolerance: a hundred times tighter rtol, a smaller worst balance (the
// bound's premise), on the butterfly's recorded run.
TEST(EnergyAudit, TheBalanceShrinksWithTheTolerance) {
  auto pb = paper_problem(std::make_shared<ButterflyMotion>(1.181, -1.1393));
  RunOptions loose = options(1.181, 1e-7), tight = options(1.181, 1e-11);
  loose.events.stop_on_contact_loss = tight.events.stop_on_contact_loss = false;
  const RunResult a = simulate(pb, {}, loose), b = simulate(pb, {}, tight);
  expect_holds(a.audit);
  expect_holds(b.audit);
  EXPECT_LT(b.audit.worst, 0.1 * a.audit.worst);
}

// A solution's own run (the search's answer) is audited and holds.
TEST(EnergyAudit, TheSolutionOfASearchIsAudited) {
  SimulationSpec spec;
  const SolveReport rep = solve_k(spec, 1.181);
  expect_holds(rep.run.audit);
}

// A sweep never dies for one world: with a balance held to 1e-20 (below rounding: every run's
// audit breaks) a locus still returns every duration, each with its failure and no numbers, and a
// surface every point, NaN and listed.
TEST(EnergyAudit, ASweepRecordsThePointsThatFailAndGoesOn) {
  SimulationSpec spec;
  spec.run.integrator.energy_tolerance = 1e-20;
  const std::vector<SolveReport> points = locus(spec, 1.1, 1.3, 3);
  ASSERT_EQ(points.size(), 3u);
  for (const SolveReport& p : points) {
    EXPECT_TRUE(std::isnan(p.k));
    EXPECT_NE(p.failure.find("failed numerically"), std::string::npos) << p.failure;
  }
  EXPECT_DOUBLE_EQ(points[2].period, 1.3);
  const SurfaceResult s = surface(spec, -1.2, -1.1, 2, 1.1, 1.2, 2, 1);
  ASSERT_EQ(s.s_T.size(), 4u);
  for (double v : s.s_T) EXPECT_TRUE(std::isnan(v));
  EXPECT_EQ(s.numerical_failures.size(), 4u);
  // The same sweeps at the default tolerance have no failure.
  spec.run.integrator.energy_tolerance.reset();
  const SurfaceResult good = surface(spec, -1.2, -1.1, 2, 1.1, 1.2, 2, 1);
  EXPECT_TRUE(good.numerical_failures.empty());
  for (double v : good.s_T) EXPECT_TRUE(std::isfinite(v));
}
