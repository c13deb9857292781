// Sensitivities of a butterfly's run (flatland/sim/sensitivity.hpp) against central differences
// of runs integrated far more tightly than the differences' step, on the paper's butterfly, which
// crosses the hand's junctions (s_h = -1 on its first dip, s_h = +1 near its end), and through the
// motion's end 2T, whose time moves with the period.
#include "flatland/sim/sensitivity.hpp"
#include "rolling_support.hpp"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

using namespace flatland::sim;

namespace {

using Parameters = std::array<double, 6>;  // a, b, c, d, k, period
constexpr Parameters kPaper = {0.18, -0.18, -0.252, 0.216, -1.1393, 1.181};

std::shared_ptr<RollingProblem> butterfly_of(const Parameters& p) {
  return problem(std::make_shared<PolynomialHand>(p[0], p[1], p[2], p[3]), make_uniform_disk(0.051),
                 std::make_shared<ButterflyMotion>(p[5], p[4]));
}

InitialContact palm_middle() {
  InitialContact init;
  init.s_h = -1.0;
  init.sdot_h = 0.0;
  init.t0 = 0.0;
  return init;
}

RunOptions options_until(double t_end, double rtol) {
  RunOptions o;
  o.t_end = t_end;
  o.record = false;
  o.integrator.method = Method::kDormandPrince853;
  o.integrator.rtol = rtol;
  o.integrator.atol = 1e-3 * rtol;
  o.events.time_tolerance = 1e-14;
  return o;
}

/// (s_h, sdot_h) at the end of a run of `p` (at its own 2T when t_end is not given).
Eigen::Vector2d outcome(const Parameters& p, std::optional<double> t_end) {
  const RunResult r =
      simulate(butterfly_of(p), palm_middle(), options_until(t_end.value_or(p[5]), 1e-14));
  EXPECT_EQ(r.reason, StopReason::kEndTime);
  return {r.final.s_h, r.final.sdot_h};
}

/// Central differences of outcome() in each parameter, step 1e-7 of its size. The run is strongly
/// nonlinear in its parameters: with steps of 1e-5 the differences' own truncation error reaches
/// 3.5e-4 of the derivative (k's), and it falls as the step squared (measured: 8e-5, 8e-7 and
/// 1.4e-8 for d s_h/dk at steps of 1e-5, 1e-6 and 1e-7). The runs' error, rtol 1e-14, divided by
/// the step stays near 1e-7 of the state.
ButterflyJacobian central_differences(const Parameters& p, std::optional<double> t_end) {
  ButterflyJacobian fd;
  for (int j = 0; j < 6; ++j) {
    const double h = 1e-7 * std::abs(p[j]);
    Parameters up = p, down = p;
    up[j] += h;
    down[j] -= h;
    fd.col(j) = (outcome(up, t_end) - outcome(down, t_end)) / (2 * h);
  }
  return fd;
}

void expect_agree(const ButterflyJacobian& exact, const ButterflyJacobian& fd, double rel) {
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 6; ++j) {
      EXPECT_NEAR(exact(i, j), fd(i, j), rel * std::abs(fd(i, j)))
          << (i == 0 ? "d s_h/d" : "d sdot_h/d") << kButterflyParameters[j];
      std::fprintf(stderr, "[ sensitivity ] %s/d%s: exact %.10g, differences %.10g (%.1e)\n",
                   i == 0 ? "d s_h" : "d sdot_h", std::string(kButterflyParameters[j]).c_str(),
                   exact(i, j), fd(i, j), std::abs(exact(i, j) / fd(i, j) - 1));
    }
}

}  // namespace

TEST(Sensitivity, PapersButterflyAtItsEndMatchesCentralDifferences) {
  const RunSensitivities s =
      simulate_with_sensitivities(butterfly_of(kPaper), palm_middle(), options_until(1.181, 1e-12));
  ASSERT_EQ(s.run.reason, StopReason::kEndTime);
  ASSERT_TRUE(s.motion_end);
  EXPECT_GE(s.junction_jumps, 2) << "the paper's butterfly crosses s_h = -1 and s_h = +1";
  const ButterflyJacobian fd = central_differences(kPaper, std::nullopt);
  expect_agree(*s.motion_end, fd, 1e-6);
}

TEST(Sensitivity, ThroughTheMotionsEndAtAFixedTimeMatchesCentralDifferences) {
  const double t_end = 1.3;
  const RunSensitivities s =
      simulate_with_sensitivities(butterfly_of(kPaper), palm_middle(), options_until(t_end, 1e-12));
  ASSERT_EQ(s.run.reason, StopReason::kEndTime);
  EXPECT_FALSE(s.motion_end);
  EXPECT_EQ(s.breakpoint_jumps, 1);
  const ButterflyJacobian fd = central_differences(kPaper, t_end);
  expect_agree(s.end, fd, 1e-6);
}

// The run beside the sensitivities is the run simulate() gives: the same steps, events and final
// state to the bit, recorded or not (the step-size control measures the state alone by default).
TEST(Sensitivity, TheRunIsSimulatesRunBitForBit) {
  for (const bool record : {false, true}) {
    RunOptions o = options_until(1.181, 1e-10);
    o.integrator.method = Method::kDormandPrince54;
    o.record = record;
    const RunResult plain = simulate(butterfly_of(kPaper), palm_middle(), o);
    const RunSensitivities s = simulate_with_sensitivities(butterfly_of(kPaper), palm_middle(), o);
    EXPECT_EQ(s.run.stats.steps, plain.stats.steps) << "record " << record;
    EXPECT_EQ(s.run.events.size(), plain.events.size());
    EXPECT_EQ(s.run.final.s_h, plain.final.s_h);
    EXPECT_EQ(s.run.final.sdot_h, plain.final.sdot_h);
    EXPECT_EQ(s.run.final.force_normal, plain.final.force_normal);
    // The normal force's minimum over the run (NaN for both when nothing is recorded).
    EXPECT_TRUE(s.run.fn_min_ratio == plain.fn_min_ratio ||
                (std::isnan(s.run.fn_min_ratio) && std::isnan(plain.fn_min_ratio)))
        << s.run.fn_min_ratio << " against " << plain.fn_min_ratio;
    if (record) {
      EXPECT_FALSE(std::isnan(s.run.fn_min_ratio));
    }
    EXPECT_EQ(s.run.trajectory.empty(), !record);
  }
}

// What the sensitivities do not cover is refused with one line naming it, before any integration.
TEST(Sensitivity, RefusesWhatItDoesNotCoverNamingIt) {
  const auto refused = [](std::shared_ptr<RollingProblem> pb, RunOptions o, const char* field) {
    try {
      simulate_with_sensitivities(pb, palm_middle(), o);
      ADD_FAILURE() << "accepted; expected a refusal naming " << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  };
  const RunOptions ok = options_until(1.181, 1e-10);
  auto line = butterfly_of(kPaper);
  line->hand = std::make_shared<LineCurve>(Vec2(0, 0), Vec2(1, 0));
  refused(line, ok, "hand");
  auto fixed = butterfly_of(kPaper);
  fixed->motion = std::make_shared<FixedHand>(0.0);
  refused(fixed, ok, "motion");
  RunOptions hybrid = ok;
  hybrid.model = ContactModel::kHybrid;
  refused(butterfly_of(kPaper), hybrid, "contact.model");
  RunOptions general = ok;
  general.formulation = Formulation::kGeneral;
  refused(butterfly_of(kPaper), general, "integrator.formulation");
  RunOptions rk4 = ok;
  rk4.integrator.method = Method::kRungeKutta4;
  rk4.integrator.fixed_step = 1e-3;
  refused(butterfly_of(kPaper), rk4, "integrator.method");
  auto lossy = butterfly_of(kPaper);
  lossy->contact.drag = 0.1;
  refused(lossy, ok, "contact");
}
