// Objective 1 of the design (flatland/design/design.hpp): the least friction a butterfly of a
// given period needs, with the motion alone free (the paper's search, which it must reproduce)
// and with the hand's shape free too (which must do at least as well, and whose answer is checked
// by runs of its own, not by the optimiser's numbers).
#include "flatland/design/design.hpp"

#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

using namespace flatland;

namespace {

/// The paper's hand, disk and butterfly (sim::SimulationSpec's defaults), the disk at rest in the
/// palm's middle.
sim::SimulationSpec papers_spec() { return sim::SimulationSpec{}; }

/// The spec of a design's parameters.
sim::SimulationSpec spec_of(const design::Parameters& p) {
  return design::spec_with(papers_spec(), p);
}

}  // namespace

// With the hand held, the only free variable is k and s_h(T) = 0 fixes it: the design is the
// paper's solution for 2T = 1.181 s, the one `solve` finds, and needs the friction it reports.
TEST(LeastFriction, WithTheShapeHeldIsThePapersSolution) {
  design::DesignOptions o;
  o.period = 1.181;
  o.shape_free = false;
  const design::DesignResult r = design::optimise(papers_spec(), o);
  const sim::SolveReport paper = sim::solve_k(papers_spec(), 1.181);
  ASSERT_TRUE(r.best.feasible) << r.stop;
  EXPECT_NEAR(r.best.parameters[4], paper.k, 1e-6) << r.stop;
  EXPECT_NEAR(r.best.parameters[4], -1.1393, 1e-3);  // the paper's k (its section 4.3)
  EXPECT_NEAR(r.best.mu_required, paper.mu_required, 1e-6);
  EXPECT_NEAR(r.best.fn_min_ratio, paper.fn_min_ratio, 1e-6);
}

// With the shape free the friction needed falls, and the design, run on its own through the
// searches' evaluation (a recorded, audited run), is a solution that needs what it says.
TEST(LeastFriction, WithTheShapeFreeNeedsLessFrictionAndIsASolution) {
  design::DesignOptions o;
  o.period = 1.181;
  int progress_calls = 0;
  const design::DesignResult r =
      design::optimise(papers_spec(), o, [&](const design::Iterate&) { ++progress_calls; });
  std::fprintf(stderr, "[ design ] %s after %zu evaluations, %d runs: mu %.6f -> %.6f\n",
               r.stop.c_str(), r.iterates.size(), r.simulations, r.start_point.mu_required,
               r.best.mu_required);
  ASSERT_TRUE(r.best.feasible) << r.stop;
  EXPECT_EQ(progress_calls, static_cast<int>(r.iterates.size()));
  EXPECT_LT(r.best.mu_required, 0.95 * r.start_point.mu_required) << r.stop;
  const design::Parameters& p = r.best.parameters;
  for (int j = 0; j < 4; ++j)
    EXPECT_LE(std::abs(p[j] - r.start[j]), o.shape_range * std::abs(r.start[j]) * (1 + 1e-12));
  const sim::SolveReport check = sim::evaluate(spec_of(p), p[5], p[4]);
  EXPECT_NEAR(check.s_T, 0.0, 1e-6);
  EXPECT_NEAR(check.s_end, 1.0, 1e-3) << "a solution ends on the back";
  EXPECT_NEAR(check.mu_required, r.best.mu_required, 1e-6);
  EXPECT_GE(check.fn_min_ratio, o.fn_margin - 1e-6);
}

// The design's friction, tested in the world that can slip: the hybrid model with a mu between the
// design's need (0.115) and the paper's hand's (0.303). The design rolls from the palm to rest on
// the back without a slip or a flight over the whole 2T (the design constrained [0, T] and
// relied on the symmetry for the rest); the paper's butterfly, in the same world, slips.
TEST(LeastFriction, TheDesignRollsWithoutSlippingInTheHybridWorldWhereThePapersSlips) {
  design::DesignOptions o;
  o.period = 1.181;
  const design::DesignResult r = design::optimise(papers_spec(), o);
  ASSERT_TRUE(r.best.feasible) << r.stop;
  const double mu = 0.15;
  ASSERT_LT(r.best.mu_required, mu);
  ASSERT_GT(r.start_point.mu_required, mu);
  auto hybrid = [mu](sim::SimulationSpec s) {
    s.contact.mu = mu;
    s.run.model = sim::ContactModel::kHybrid;
    return sim::run_spec(s);
  };
  const sim::RunResult designed = hybrid(spec_of(r.best.parameters));
  EXPECT_EQ(designed.stats.mode_changes, 0);
  EXPECT_EQ(designed.stats.impacts, 0);
  EXPECT_NEAR(designed.final.t, 1.181, 1e-9);
  EXPECT_NEAR(designed.final.s_h, 1.0, 1e-3) << "at rest on the back";
  EXPECT_NEAR(designed.final.sdot_h, 0.0, 1e-2);
  const sim::RunResult papers = hybrid(spec_of(r.start));
  EXPECT_GT(papers.stats.mode_changes, 0) << "the paper's butterfly needs mu 0.303";
}

// At 2T = 0.9 s the paper's hand has no butterfly: its motion-only solution loses contact (the
// paper's fastest is 1.095 s). With the shape free, the margin is restored first, and the design
// is a solution that keeps contact, checked by a run of its own.
TEST(LeastFriction, WithTheShapeFreeIsFasterThanThePapersHandCanBe) {
  design::DesignOptions o;
  o.period = 0.9;
  const design::DesignResult r = design::optimise(papers_spec(), o);
  EXPECT_LT(r.start_point.fn_min_ratio, 0.0) << "the paper's hand loses contact at 0.9 s";
  EXPECT_FALSE(r.start_point.feasible);
  EXPECT_TRUE(r.restored) << r.restore_stop;
  ASSERT_TRUE(r.best.feasible) << r.stop;
  const design::Parameters& p = r.best.parameters;
  const sim::SolveReport check = sim::evaluate(spec_of(p), p[5], p[4]);
  EXPECT_NEAR(check.s_T, 0.0, 1e-6);
  EXPECT_NEAR(check.s_end, 1.0, 1e-3);
  EXPECT_GE(check.fn_min_ratio, o.fn_margin - 1e-6);
  EXPECT_NEAR(check.mu_required, r.best.mu_required, 1e-6);
  EXPECT_TRUE(std::isfinite(check.mu_required));
}

// With the hand held at 0.9 s, k alone cannot keep contact: no design is feasible, and the result
// says so instead of reporting the start as a design.
TEST(LeastFriction, WithTheShapeHeldAtAPeriodTooShortNothingIsFeasible) {
  design::DesignOptions o;
  o.period = 0.9;
  o.shape_free = false;
  const design::DesignResult r = design::optimise(papers_spec(), o);
  EXPECT_FALSE(r.best.feasible);
  EXPECT_FALSE(r.restored);
  EXPECT_NE(r.stop.find("no feasible start"), std::string::npos) << r.stop;
  EXPECT_TRUE(r.active.empty());
}

TEST(LeastFriction, RefusesBadOptionsWithOneLine) {
  const auto refused = [](design::DesignOptions o, sim::SimulationSpec s, const char* what) {
    try {
      design::optimise(s, o);
      ADD_FAILURE() << "accepted; expected a refusal naming " << what;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  };
  design::DesignOptions ok;
  ok.period = 1.181;
  auto with = [&](auto change) {
    design::DesignOptions o = ok;
    change(o);
    return o;
  };
  refused(with([](auto& o) { o.period = 0; }), papers_spec(), "period");
  refused(with([](auto& o) { o.period = std::nan(""); }), papers_spec(), "period");
  refused(with([](auto& o) { o.shape_range = 1.5; }), papers_spec(), "shape_range");
  refused(with([](auto& o) { o.fn_margin = -0.1; }), papers_spec(), "fn_margin");
  refused(with([](auto& o) { o.k_min = -2.5; }), papers_spec(), "k bounds");
  refused(with([](auto& o) { o.k_max = -1.5; }), papers_spec(), "k bounds");  // excludes the start
  refused(with([](auto& o) { o.max_evaluations = 0; }), papers_spec(), "max_evaluations");
  refused(with([](auto& o) { o.pieces = 0; }), papers_spec(), "pieces");
  sim::SimulationSpec circle = papers_spec();
  circle.hand.shape = sim::HandSpec::Shape::kCircle;
  refused(ok, circle, "hand.shape");
}
