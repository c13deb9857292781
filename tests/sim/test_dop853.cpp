// Dormand-Prince 8(5,3): order of the step and of the dense output, agreement with dopri5 on the
// paper's butterfly, work at tight tolerances, scene and CLI selection.
#include "flatland/scene/scene.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "sim/rolling_support.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace flatland;
using namespace flatland::sim;

namespace {

RunOptions options(Method m, double t_end, double rtol, Formulation f = Formulation::kReduced) {
  RunOptions o;
  o.t_end = t_end;
  o.formulation = f;
  o.integrator.method = m;
  o.integrator.rtol = rtol;
  o.integrator.atol = rtol * 1e-2;
  o.events.stop_on_contact_loss = false;
  return o;
}

// DOP853 at a constant step h: max_step = h and tolerances so loose (rtol = atol = 1 on a state
// of size ~1) that no step is rejected and the controller always asks for more than h. Only the
// first few steps, from the starting heuristic (the same for every h, growing 3x per step), are
// shorter; their error is far below that of the steps of size h, which set the order.
RunOptions fixed_dop853(double t_end, double h) {
  RunOptions o = options(Method::kDormandPrince853, t_end, 1.0);
  o.integrator.atol = 1.0;
  o.integrator.max_step = h;
  return o;
}

// A disk swinging with a large amplitude (1 rad) in a circular well of a fixed hand: one smooth
// piece, no junctions and strongly nonlinear, so every term of the error expansion is present.
constexpr double kSmoothEnd = 1.0;

std::shared_ptr<RollingProblem> circular_well() {
  auto pb = butterfly();
  pb->hand = std::make_shared<CircleCurve>(Vec2(0, 0.2), 0.2, CircleCurve::Side::kConcaveWell);
  pb->motion = std::make_shared<FixedHand>(0.0);
  return pb;
}

InitialContact released() {
  InitialContact ic;
  ic.s_h = 1.0;
  return ic;
}

}  // namespace

// Halving a constant step divides the global error of an 8th-order method by 2^8 = 256. The
// reference is dopri5 at rtol 1e-13 (a different method: a wrong DOP853 tableau cannot hide in
// it). Bounds: [128, 512] leaves room for the next term of the error expansion (h^9 relative
// to h^8 at these h is a few per cent per halving) but excludes orders 7 (128 is on the border
// only asymptotically; measured ratios for a 7th-order method would sit near 128) and 9 (512).
TEST(Dop853, FixedStepConvergesWithOrderEight) {
  auto pb = circular_well();
  const double ref =
      simulate(pb, released(), options(Method::kDormandPrince54, kSmoothEnd, 1e-13)).final.s_h;
  std::vector<double> err;
  for (int n : {5, 10, 20}) {
    const RunResult r = simulate(pb, released(), fixed_dop853(kSmoothEnd, kSmoothEnd / n));
    ASSERT_GE(r.stats.steps, n);
    ASSERT_LE(r.stats.steps, n + 4) << "the step was not held at h";
    ASSERT_EQ(r.stats.rejected, 0);
    err.push_back(std::abs(r.final.s_h - ref));
  }
  std::printf("[   info   ] errors %.3e %.3e %.3e\n", err[0], err[1], err[2]);
  // The smallest error must still be far above the reference's (~1e-13) for the ratio to mean
  // anything.
  ASSERT_GT(err.back(), 1e-11);
  for (std::size_t i = 1; i < err.size(); ++i) {
    const double ratio = err[i - 1] / err[i];
    EXPECT_GT(ratio, 150.0) << "halving " << i;
    EXPECT_LT(ratio, 450.0) << "halving " << i;
  }
}

// The 7th-order interpolant: its error between step ends shrinks like h^8 too (local error of a
// 7th-order interpolant is O(h^8)), checked at off-grid times against separate tight runs that
// end exactly there (no dense output involved in the reference).
TEST(Dop853, DenseOutputConvergesWithOrderEight) {
  auto pb = circular_well();
  const std::vector<double> times = {0.1234, 0.3111, 0.5555, 0.7071, 0.9377};
  std::vector<double> ref;
  for (double t : times)
    ref.push_back(simulate(pb, released(), options(Method::kDormandPrince54, t, 1e-13)).final.s_h);
  auto worst = [&](int n) {
    const RunResult r = simulate(pb, released(), fixed_dop853(kSmoothEnd, kSmoothEnd / n));
    EXPECT_LE(r.stats.steps, n + 4);
    double w = 0;
    for (std::size_t i = 0; i < times.size(); ++i)
      w = std::max(w, std::abs(r.trajectory.s_h(times[i]) - ref[i]));
    return w;
  };
  // h = 0.1 and 0.05 s are still pre-asymptotic for the interpolant (hω ~ 0.7); 0.05 -> 0.025 s
  // is not, and its error stays above the reference's ~1e-13.
  const double e1 = worst(20), e2 = worst(40);
  std::printf("[   info   ] dense output errors %.3e %.3e ratio %.1f\n", e1, e2, e1 / e2);
  ASSERT_GT(e2, 1e-12);
  EXPECT_GT(e1 / e2, 150.0);
  EXPECT_LT(e1 / e2, 450.0);
}

// The paper's butterfly solved with both methods at tight tolerances: the same k (to the search
// tolerance plus what rtol 1e-12 leaves), and that k is the model's -1.13957 for 2T = 1.181 s.
TEST(Dop853, SolvesTheButterflyLikeDopri5) {
  SimulationSpec spec;
  spec.run.integrator.rtol = 1e-12;
  spec.run.integrator.atol = 1e-14;
  SearchSettings set;
  set.tolerance = 1e-12;
  const SolveReport a = solve_k(spec, 1.181, set);
  spec.run.integrator.method = Method::kDormandPrince853;
  const SolveReport b = solve_k(spec, 1.181, set);
  EXPECT_EQ(b.run.method, Method::kDormandPrince853);
  EXPECT_NEAR(a.k, b.k, 1e-10);
  EXPECT_NEAR(b.k, -1.13957, 1e-5);
  EXPECT_NEAR(b.s_end, 1.0, 1e-6);
  EXPECT_NEAR(a.mu_required, b.mu_required, 1e-8);
  EXPECT_NEAR(a.fn_apex_ratio, b.fn_apex_ratio, 1e-8);
}

// Whole trajectories (dense output, both formulations, through both junction crossings) agree
// with dopri5 at rtol 1e-12; each is within ~1e-11 of the truth (test_dynamics), so 1e-9 is loose.
TEST(Dop853, AgreesWithDopri5OverTheWholeRollInBothFormulations) {
  auto pb = butterfly();
  for (Formulation f : {Formulation::kReduced, Formulation::kGeneral}) {
    const RunResult a = simulate(pb, {}, options(Method::kDormandPrince54, 1.181, 1e-12, f));
    const RunResult b = simulate(pb, {}, options(Method::kDormandPrince853, 1.181, 1e-12, f));
    EXPECT_EQ(b.stats.junction_crossings, a.stats.junction_crossings);
    EXPECT_GE(b.stats.junction_crossings, 2);
    double worst = 0, worst_fn = 0;
    for (double t = 0; t <= 1.181; t += 0.0005) {
      const Sample sa = a.trajectory.sample(t), sb = b.trajectory.sample(t);
      worst = std::max(worst, std::abs(sa.s_h - sb.s_h));
      worst_fn = std::max(worst_fn, std::abs(sa.fn_ratio - sb.fn_ratio));
    }
    EXPECT_LE(worst, 1e-9) << to_string(f);
    EXPECT_LE(worst_fn, 1e-7) << to_string(f);
    for (const RecordedEvent& e : b.events) {
      if (e.kind == EventKind::kJunction) {
        EXPECT_NEAR(std::abs(e.s_h), 1.0, 1e-9);
      }
    }
    if (f == Formulation::kGeneral) {
      EXPECT_LE(b.stats.max_constraint_residual, 1e-12);
    }
  }
}

// At rtol 1e-12 the 8th-order method takes far fewer steps: dopri5's steps grow like
// tol^(-1/5), DOP853's like tol^(-1/8); at the same accuracy that is several times fewer steps
// (and fewer right-hand-side evaluations despite 12 stages instead of 6).
TEST(Dop853, FewerStepsThanDopri5AtTightTolerance) {
  auto pb = butterfly();
  RunOptions o5 = options(Method::kDormandPrince54, 1.181, 1e-12);
  RunOptions o8 = options(Method::kDormandPrince853, 1.181, 1e-12);
  o5.record = o8.record = false;
  const RunResult a = simulate(pb, {}, o5), b = simulate(pb, {}, o8);
  EXPECT_LT(3 * b.stats.steps, a.stats.steps);
  EXPECT_LT(b.stats.rhs_evals, a.stats.rhs_evals);
  // ... and it is at least as accurate (reference: dopri5 at 1e-13 with the other formulation).
  const double ref =
      simulate(pb, {}, options(Method::kDormandPrince54, 1.181, 1e-13, Formulation::kGeneral))
          .final.s_h;
  EXPECT_LT(std::abs(b.final.s_h - ref), 1e-9);
}

TEST(Dop853, SelectedByTheScene) {
  const std::string base =
      "gravity: {g: 9.8, tilt_deg: 90}\nhand: {shape: polynomial, a: 0.18, b: -0.18, c: -0.252, "
      "d: 0.216}\nobject: {type: disk, radius: 0.051}\nmotion: {type: butterfly, period: 1.181, "
      "k: -1.1393}\n";
  const Scene s = parse_scene(base + "integrator:\n  method: dop853\n  rtol: 1e-11\n");
  EXPECT_EQ(s.sim.run.integrator.method, Method::kDormandPrince853);
  EXPECT_EQ(to_string(Method::kDormandPrince853), "dop853");
  EXPECT_THROW(parse_scene(base + "integrator:\n  method: dop85\n"), std::invalid_argument);
}
