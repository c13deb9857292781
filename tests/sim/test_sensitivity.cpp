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

/// (s_h, sdot_h) at the end of a run of `p`: at t_end, or at `of_period` times its own period.
struct End {
  std::optional<double> t_end;
  double of_period = 1.0;
  double step = 1e-7;  ///< the differences' step, of each parameter's size (see below)
  double at(const Parameters& p) const { return t_end.value_or(of_period * p[5]); }
};

Eigen::Vector2d outcome(const Parameters& p, End end) {
  const RunResult r = simulate(butterfly_of(p), palm_middle(), options_until(end.at(p), 1e-14));
  EXPECT_EQ(r.reason, StopReason::kEndTime);
  return {r.final.s_h, r.final.sdot_h};
}

/// Central differences of outcome() in each parameter, step end.step of its size. The run is
/// strongly nonlinear in its parameters: with steps of 1e-5 the differences' own truncation error
/// reaches 3.5e-4 of the derivative (k's), and it falls as the step squared (measured: 8e-5, 8e-7
/// and 1.4e-8 for d s_h/dk at steps of 1e-5, 1e-6 and 1e-7). The runs' error, rtol 1e-14, divided
/// by the step stays near 1e-7 of the state.
ButterflyJacobian central_differences(const Parameters& p, End end) {
  ButterflyJacobian fd;
  for (int j = 0; j < 6; ++j) {
    const double h = end.step * std::abs(p[j]);
    Parameters up = p, down = p;
    up[j] += h;
    down[j] -= h;
    fd.col(j) = (outcome(up, end) - outcome(down, end)) / (2 * h);
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
  ASSERT_TRUE(s.scaled_end);
  EXPECT_GE(s.junction_jumps, 2) << "the paper's butterfly crosses s_h = -1 and s_h = +1";
  const ButterflyJacobian fd = central_differences(kPaper, End{std::nullopt, 1.0});
  expect_agree(*s.scaled_end, fd, 1e-6);
}

// At T, which moves with half the period: a symmetric solution's s_h(T) = 0, the condition the
// searches solve and a design keeps. Half the motion is far less nonlinear in the parameters than
// the whole: a step of 1e-6 agrees to 1.1e-7 at most, where 1e-7 leaves the differences' own
// rounding (the runs' error over the step) at 7e-7.
TEST(Sensitivity, PapersButterflyAtItsHalfPeriodMatchesCentralDifferences) {
  const RunSensitivities s = simulate_with_sensitivities(butterfly_of(kPaper), palm_middle(),
                                                         options_until(0.5 * 1.181, 1e-12));
  ASSERT_EQ(s.run.reason, StopReason::kEndTime);
  ASSERT_TRUE(s.scaled_end);
  const ButterflyJacobian fd = central_differences(kPaper, End{std::nullopt, 0.5, 1e-6});
  expect_agree(*s.scaled_end, fd, 1e-6);
}

TEST(Sensitivity, ThroughTheMotionsEndAtAFixedTimeMatchesCentralDifferences) {
  const double t_end = 1.3;
  const RunSensitivities s =
      simulate_with_sensitivities(butterfly_of(kPaper), palm_middle(), options_until(t_end, 1e-12));
  ASSERT_EQ(s.run.reason, StopReason::kEndTime);
  EXPECT_EQ(s.breakpoint_jumps, 1);
  const ButterflyJacobian fd = central_differences(kPaper, End{t_end});
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

namespace {

using Margins = Eigen::Vector3d;  // fn_min_ratio, mu_required, friction_margin

/// The force margins over [from, to] of a tightly integrated, recorded run of `p` (find_extrema's,
/// independent of the sensitivities' code), the window's ends held fixed.
Margins margins(const Parameters& p, double from, double to, double mu, double run_to) {
  RunOptions o = options_until(run_to, 1e-14);
  o.record = true;
  const RunResult r = simulate(butterfly_of(p), palm_middle(), o);
  EXPECT_EQ(r.reason, StopReason::kEndTime);
  const Extrema x = find_extrema(r, from, to, o.events.time_tolerance, mu);
  return {x.fn_min_ratio, x.mu_required, x.friction_margin};
}

/// Each margin's gradient against central differences, normwise: every entry to `rel` of the
/// gradient's largest. An extremum's time is located by Brent's method to about 1e-8 s (the square
/// root of the rounding error: the extremum is flat there), which moves the gradient, evaluated
/// there, by its rate times that; an entry that is small against the others because its parts
/// cancel (d friction_margin/dd over the whole motion: 0.0137, the difference of terms near 2.6)
/// carries that error relative to its parts.
void expect_window_agrees(const std::array<const MarginSensitivity*, 3>& exact, double from,
                          double to, double mu, double run_to, double rel) {
  const Margins at = margins(kPaper, from, to, mu, run_to);
  const char* names[3] = {"fn_min_ratio", "mu_required", "friction_margin"};
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(exact[i]->value, at[i], 1e-9) << names[i];
  Eigen::Matrix<double, 3, 6> fd;
  for (int j = 0; j < 6; ++j) {
    const double h = 1e-6 * std::abs(kPaper[j]);
    Parameters up = kPaper, down = kPaper;
    up[j] += h;
    down[j] -= h;
    fd.col(j) = (margins(up, from, to, mu, run_to) - margins(down, from, to, mu, run_to)) / (2 * h);
  }
  for (int i = 0; i < 3; ++i) {
    const double scale = fd.row(i).cwiseAbs().maxCoeff();
    for (int j = 0; j < 6; ++j) {
      EXPECT_NEAR(exact[i]->gradient[j], fd(i, j), rel * scale)
          << names[i] << "/d" << kButterflyParameters[j] << " over [" << from << ", " << to << "]";
      std::fprintf(stderr,
                   "[ margin ] d %s/d%s at t = %.6f: exact %.10g, differences %.10g (%.1e of the "
                   "gradient's largest, %.1e of itself)\n",
                   names[i], std::string(kButterflyParameters[j]).c_str(), exact[i]->t,
                   exact[i]->gradient[j], fd(i, j),
                   std::abs(exact[i]->gradient[j] - fd(i, j)) / scale,
                   std::abs(exact[i]->gradient[j] / fd(i, j) - 1));
    }
  }
}

void expect_margins_agree(double from, double to, double mu, double rel) {
  const ForceMarginSensitivities m = force_margin_sensitivities(
      butterfly_of(kPaper), palm_middle(), options_until(to, 1e-12), from, to, mu);
  EXPECT_GE(m.runs, 2);
  expect_window_agrees({&m.fn_min_ratio, &m.mu_required, &m.friction_margin}, from, to, mu, to,
                       rel);
}

}  // namespace

TEST(Sensitivity, ForceMarginsOverTheFirstHalfMatchCentralDifferences) {
  expect_margins_agree(0.0, 0.5 * 1.181, 0.5, 1e-6);
}

TEST(Sensitivity, ForceMarginsOverTheWholeMotionMatchCentralDifferences) {
  expect_margins_agree(0.0, 1.181, 0.5, 1e-6);
}

// Each part's own extrema (the friction needed peaks twice before T: the parts see both), and
// the whole window's from the parts equal the whole window's found at once.
TEST(Sensitivity, ForceMarginsOfEachPartMatchCentralDifferences) {
  const double T = 0.5 * 1.181, mu = 0.5;
  const ForceMarginSensitivities whole = force_margin_sensitivities(
      butterfly_of(kPaper), palm_middle(), options_until(T, 1e-12), 0.0, T, mu);
  const ForceMarginSensitivities parts = force_margin_sensitivities(
      butterfly_of(kPaper), palm_middle(), options_until(T, 1e-12), 0.0, T, mu, 3);
  ASSERT_EQ(parts.windows.size(), 3u);
  EXPECT_EQ(parts.windows.front().t_from, 0.0);
  EXPECT_EQ(parts.windows.back().t_to, T);
  for (auto field :
       {&ForceMarginSensitivities::fn_min_ratio, &ForceMarginSensitivities::mu_required,
        &ForceMarginSensitivities::friction_margin}) {
    EXPECT_NEAR((parts.*field).value, (whole.*field).value, 1e-12);
    EXPECT_LT(((parts.*field).gradient - (whole.*field).gradient).cwiseAbs().maxCoeff(), 1e-9);
  }
  for (const WindowMargins& w : parts.windows)
    expect_window_agrees({&w.fn_min_ratio, &w.mu_required, &w.friction_margin}, w.t_from, w.t_to,
                         mu, T, 1e-6);
}

TEST(Sensitivity, ForceMarginsRefuseABadWindowOrMuWithOneLine) {
  const auto refused = [](double from, double to, std::optional<double> mu, const char* what) {
    try {
      force_margin_sensitivities(butterfly_of(kPaper), palm_middle(), options_until(1.181, 1e-10),
                                 from, to, mu);
      ADD_FAILURE() << "accepted; expected a refusal naming " << what;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    }
  };
  refused(0.5, 0.5, std::nullopt, "not empty");
  refused(0.0, std::nan(""), std::nullopt, "finite");
  refused(-0.1, 0.5, std::nullopt, "not inside the run");
  refused(0.0, 1.5, std::nullopt, "not inside the run");
  refused(0.0, 0.5, 0.0, "mu must be positive");
  refused(0.0, 0.5, -1.0, "mu must be positive");
  try {
    force_margin_sensitivities(butterfly_of(kPaper), palm_middle(), options_until(1.181, 1e-10),
                               0.0, 0.5, std::nullopt, 0);
    ADD_FAILURE() << "pieces = 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pieces"), std::string::npos) << e.what();
  }
}
