// Objective 3 of the design (flatland/design/design.hpp): the largest robustness margin at a
// period and a friction coefficient, the smaller over [0, T] of (mu f_n - |f_t|) and f_n per
// in-plane weight. Checked against the searches' own evaluation of the design (a recorded,
// audited run that reports the friction margin and the normal force's minimum).
#include "flatland/design/design.hpp"

#include "flatland/sim/search.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

using namespace flatland;

namespace {

/// The robustness margin of a design, as the searches evaluate a motion (independent of the
/// design's sensitivities): the smaller of its friction margin at mu and its normal force's
/// minimum over [0, T].
double robustness_of(const design::Parameters& p, double mu) {
  sim::SimulationSpec s = design::spec_with(sim::SimulationSpec{}, p);
  s.contact.mu = mu;
  const sim::SolveReport r = sim::evaluate(s, p[5], p[4]);
  EXPECT_NEAR(r.s_T, 0.0, 1e-6) << "a solution";
  return std::min(r.friction_margin, r.fn_min_ratio);
}

design::DesignOptions robustness_at(double mu, bool shape_free) {
  design::DesignOptions o;
  o.objective = design::Objective::kRobustness;
  o.period = 1.181;
  o.mu = mu;
  o.shape_free = shape_free;
  return o;
}

}  // namespace

// With the hand held, k is fixed by s_h(T) = 0: the design is the paper's solution and its margin
// is the paper's (at mu = 0.306, the friction the paper's 1.181 s butterfly needs, almost none).
TEST(Robustness, WithTheShapeHeldIsThePapersSolutionsMargin) {
  const design::DesignResult r =
      design::optimise(sim::SimulationSpec{}, robustness_at(0.306, false));
  ASSERT_TRUE(r.best.feasible) << r.stop;
  EXPECT_NEAR(r.best.robustness, robustness_of(r.best.parameters, 0.306), 1e-6);
  EXPECT_NEAR(r.best.parameters[4], sim::solve_k(sim::SimulationSpec{}, 1.181).k, 1e-6);
  EXPECT_LT(r.best.robustness, 0.01);
}

// With the shape free the margin grows, and the design's margin is what its own run shows.
TEST(Robustness, WithTheShapeFreeTheMarginGrowsAndIsWhatTheRunShows) {
  for (const double mu : {0.306, 0.5}) {
    const design::DesignResult r = design::optimise(sim::SimulationSpec{}, robustness_at(mu, true));
    ASSERT_TRUE(r.best.feasible) << r.stop;
    EXPECT_GT(r.best.robustness, r.start_point.robustness + 0.1) << "mu " << mu;
    EXPECT_NEAR(r.best.robustness, robustness_of(r.best.parameters, mu), 1e-6) << "mu " << mu;
    EXPECT_NEAR(r.start_point.robustness, robustness_of(r.start, mu), 1e-6) << "mu " << mu;
  }
}

TEST(Robustness, NeedsAPositiveMu) {
  for (const double mu : {0.0, -0.3, std::nan("")}) {
    try {
      design::optimise(sim::SimulationSpec{}, robustness_at(mu, true));
      ADD_FAILURE() << "mu " << mu << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("mu"), std::string::npos) << e.what();
    }
  }
}
