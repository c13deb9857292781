// identify against worlds whose parameters are known: the joint log's spline against a cubic it
// must reproduce, the fit of a noise-free recording (the truth to rounding of the integrator),
// the acceptance over ten noise seeds (truth within 2 sigma in >= 9 of 10, each sigma within a
// factor 2 of the spread), a recording that cannot separate drag from rolling resistance, the
// prediction check, and bad input.
#include "flatland/identify/identify.hpp"

#include "identify/identify_support.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>

using namespace flatland;
using flatland_test::kDrag;
using flatland_test::kMuKinetic;
using flatland_test::kRestitution;
using flatland_test::kRollingResistance;
using flatland_test::kTrackerSigmaSh;

namespace {

// The truth of the synthetic world: the scene's friction (the rest of the truth, shared with
// test_identify_rendered.cpp, is in identify_support.hpp).
constexpr double kMu = 0.8;

sim::SimulationSpec truth_world() {
  return flatland_test::air_table_world(kMu, kMuKinetic, kRestitution, kRollingResistance, kDrag);
}

/// The disk let go on the palm well's side with the hand still: it rocks and the losses damp it
/// (rolling resistance by a fixed decrement per swing, drag in proportion to the speed).
identify::Recording rocking(const sim::SimulationSpec& w, double s0, double t_end, double sigma,
                            std::mt19937_64* rng) {
  return flatland_test::record("rocking", w, flatland_test::still_hand(t_end), s0, 0, t_end, 30,
                               sigma, rng);
}

/// The butterfly played too fast (2T = 3.2 s at 5 degrees): the disk slides before the tip
/// (mu_kinetic), flies over it, lands on the back and bounces six times (restitution), then rolls
/// into the back well (the losses).
identify::Recording throw_and_catch(const sim::SimulationSpec& w, double sigma,
                                    std::mt19937_64* rng) {
  return flatland_test::record("throw", w, flatland_test::butterfly_hand(3.2, -1.155794, 2.5), -1,
                               0, 2.5, 30, sigma, rng);
}

identify::IdentifyOptions four_unknowns() {
  identify::IdentifyOptions o;
  o.unknowns = {"mu_kinetic", "restitution", "rolling_resistance", "drag"};
  // Started 8-25 % off the truth.
  o.initial = {
      {"mu_kinetic", 0.55}, {"restitution", 0.35}, {"rolling_resistance", 1.5e-4}, {"drag", 0.08}};
  // The throw is one segment (a boundary at 2 s would fall in its flight), the rocking two.
  o.segment_duration = 3.0;
  o.threads = 2;
  return o;
}

double truth_of(const std::string& name) {
  if (name == "mu_kinetic") return kMuKinetic;
  if (name == "restitution") return kRestitution;
  if (name == "rolling_resistance") return kRollingResistance;
  if (name == "drag") return kDrag;
  throw std::logic_error(name);
}

}  // namespace

// The not-a-knot spline reproduces a cubic exactly (angle, rate and acceleration), at uneven
// knots, and applies the offsets as documented.
TEST(JointLogMotion, ReproducesACubicAndItsDerivatives) {
  const auto theta = [](double t) { return 0.3 - 0.5 * t + 0.8 * t * t - 0.25 * t * t * t; };
  std::vector<double> t{0.0, 0.13, 0.2, 0.5, 0.61, 0.9, 1.3, 1.31, 2.0}, th;
  for (double x : t) th.push_back(theta(x));
  const identify::JointLogMotion m(t, th, 0.05, 0.01);
  for (double x : {0.0, 0.07, 0.33, 0.6, 1.0, 1.305, 1.9, 2.0}) {
    const double u = x + 0.05;
    const sim::HandKinematics k = m.at(x);
    EXPECT_NEAR(k.angle, theta(u) + 0.01, 1e-12) << x;
    EXPECT_NEAR(k.angular_velocity, -0.5 + 1.6 * u - 0.75 * u * u, 1e-11) << x;
    EXPECT_NEAR(k.angular_acceleration, 1.6 - 1.5 * u, 1e-10) << x;
  }
}

// Without noise the fit lands on the truth to the integrator's accuracy, and chi^2 is ~0.
TEST(Identify, NoiseFreeRecordingGivesTheTruth) {
  const sim::SimulationSpec w = truth_world();
  const identify::IdentifyResult r =
      identify::identify(w, {throw_and_catch(w, kTrackerSigmaSh, nullptr)}, four_unknowns());
  for (const identify::ParameterEstimate& p : r.parameters) {
    ASSERT_TRUE(p.sigma.has_value()) << p.name << ": " << p.not_determined;
    EXPECT_NEAR(p.value, truth_of(p.name), 1e-4 * truth_of(p.name)) << p.name;
  }
  EXPECT_LT(r.chi2, 1e-2);
  EXPECT_EQ(r.degrees_of_freedom, 76 - 4 - 2);
}

// The acceptance of issue 26: ten noise seeds of the same two recordings (rocking, throw).
TEST(Identify, TruthWithinTwoSigmaInNineOfTenSeedsAndSigmaMatchesTheSpread) {
  // Under the sanitizers (FLATLAND_TEST_SHORT) a statistic of ten fits is not run: one fit of a
  // noisy recording there took 86 s, and its code paths are run by NoiseFreeRecordingGivesTheTruth
  // (the same fit) and SigmaIsScaledByTheBirgeRatioOnlyWhenChiSquaredExceedsItsQuantile (noise,
  // sigma scaled).
  if (flatland::test::short_tests()) GTEST_SKIP() << "a statistic of ten fits: the Release stage";
  const sim::SimulationSpec w = truth_world();
  const int seeds = 10;
  const std::vector<std::string> names = four_unknowns().unknowns;
  std::vector<std::vector<double>> values(names.size()), sigmas(names.size());
  double chi2_per_dof = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    std::mt19937_64 rng(static_cast<std::uint64_t>(seed));
    const identify::IdentifyResult r = identify::identify(
        w,
        {rocking(w, -0.7, 4.0, kTrackerSigmaSh, &rng), throw_and_catch(w, kTrackerSigmaSh, &rng)},
        four_unknowns());
    EXPECT_TRUE(r.warnings.empty()) << r.warnings.front();
    chi2_per_dof += r.chi2 / r.degrees_of_freedom / seeds;
    for (std::size_t j = 0; j < names.size(); ++j) {
      ASSERT_TRUE(r.parameters[j].sigma) << names[j] << ": " << r.parameters[j].not_determined;
      values[j].push_back(r.parameters[j].value);
      sigmas[j].push_back(*r.parameters[j].sigma);
    }
  }
  for (std::size_t j = 0; j < names.size(); ++j) {
    int within = 0;
    double mean = 0, spread = 0;
    for (int i = 0; i < seeds; ++i) {
      within += std::abs(values[j][i] - truth_of(names[j])) <= 2 * sigmas[j][i];
      mean += values[j][i] / seeds;
    }
    for (int i = 0; i < seeds; ++i) spread += std::pow(values[j][i] - mean, 2) / (seeds - 1);
    spread = std::sqrt(spread);
    double sigma_lo = sigmas[j][0], sigma_hi = sigmas[j][0];
    for (double s : sigmas[j]) sigma_lo = std::min(sigma_lo, s), sigma_hi = std::max(sigma_hi, s);
    std::printf(
        "[ identify ] %-18s truth %.6g: within 2 sigma %d/%d, spread %.3g, sigma %.3g..%.3g\n",
        names[j].c_str(), truth_of(names[j]), within, seeds, spread, sigma_lo, sigma_hi);
    EXPECT_GE(within, 9) << names[j];
    EXPECT_LE(sigma_hi, 2 * spread) << names[j];
    EXPECT_GE(sigma_lo, 0.5 * spread) << names[j];
  }
  std::printf("[ identify ] mean chi^2/dof %.3f\n", chi2_per_dof);
}

// A small swing (0.05 in s_h) over half a second: the speed hardly changes, so drag (force ~ speed)
// and rolling resistance (a couple ~ the normal force) damp it the same way and the fit cannot tell
// them apart. Both are refused, each naming the other.
TEST(Identify, SmallSwingCannotSeparateDragFromRollingResistance) {
  const sim::SimulationSpec w = truth_world();
  std::mt19937_64 rng(7);
  identify::IdentifyOptions o;
  o.unknowns = {"rolling_resistance", "drag"};
  o.segment_duration = 2.0;
  const identify::IdentifyResult r =
      identify::identify(w, {rocking(w, -0.95, 0.5, kTrackerSigmaSh, &rng)}, o);
  for (const identify::ParameterEstimate& p : r.parameters) {
    std::printf("[ identify ] %s = %.4g +- %.3g: %s\n", p.name.c_str(), p.value,
                p.sigma.value_or(0), p.not_determined.c_str());
    EXPECT_FALSE(p.sigma.has_value()) << p.name;
    const std::string other = p.name == "drag" ? "rolling_resistance" : "drag";
    EXPECT_NE(p.not_determined.find(other), std::string::npos) << p.not_determined;
  }
  EXPECT_TRUE(std::isnan(r.correlation(0, 1)));
}

// The prediction check: the true world predicts a held-out recording to a few sigma (the
// initial state fitted to its first 0.5 s carries its own error forward); a world with twice the
// drag is ten times further off and leaves 3 sigma early.
TEST(Identify, ValidatePredictsAHeldOutRecording) {
  const sim::SimulationSpec w = truth_world();
  std::mt19937_64 rng(3);
  const identify::Recording held_out = rocking(w, -1.25, 4.0, kTrackerSigmaSh, &rng);
  const identify::PredictionCheck good = identify::validate(w, held_out);
  EXPECT_TRUE(good.stopped.empty()) << good.stopped;
  EXPECT_EQ(good.t.size(), held_out.t.size());
  EXPECT_NEAR(good.s_h0, -1.25, 5 * kTrackerSigmaSh);
  EXPECT_LT(good.rms_error, 3 * kTrackerSigmaSh);
  sim::SimulationSpec wrong = w;
  wrong.contact.drag = 2 * kDrag;
  const identify::PredictionCheck bad = identify::validate(wrong, held_out);
  EXPECT_GT(bad.rms_error, 10 * good.rms_error);
  ASSERT_TRUE(bad.time_to_3_sigma.has_value());
  if (good.time_to_3_sigma) {
    EXPECT_GT(*good.time_to_3_sigma, *bad.time_to_3_sigma);
  }
  std::printf(
      "[ identify ] held out: rms %.2g (true world), %.2g (drag x 2, 3 sigma after %.2f s)\n",
      good.rms_error, bad.rms_error, *bad.time_to_3_sigma);
}

// Bad input: one line naming the field.
TEST(Identify, RefusesBadInputNamingTheField) {
  const sim::SimulationSpec w = truth_world();
  identify::Recording r = rocking(w, -0.8, 1.0, kTrackerSigmaSh, nullptr);
  const auto message = [&](const identify::Recording& rec, const identify::IdentifyOptions& o) {
    try {
      identify::identify(w, {rec}, o);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  identify::IdentifyOptions o;
  o.unknowns = {"drag"};
  identify::Recording bad = r;
  bad.t[5] = bad.t[4];
  EXPECT_NE(message(bad, o).find("rocking: t[5]: times must increase strictly"), std::string::npos)
      << message(bad, o);
  bad = r;
  bad.sigma[2] = 0;
  EXPECT_NE(message(bad, o).find("sigma[2]"), std::string::npos);
  bad = r;
  bad.joint_theta.pop_back();
  EXPECT_NE(message(bad, o).find("joint_theta"), std::string::npos);
  identify::IdentifyOptions unknown = o;
  unknown.unknowns = {"drag", "viscosity"};
  EXPECT_NE(message(r, unknown).find("unknowns: unknown parameter 'viscosity'"), std::string::npos);
  unknown.unknowns = {"drag", "drag"};
  EXPECT_NE(message(r, unknown).find("listed twice"), std::string::npos);
  identify::IdentifyOptions outside = o;
  outside.initial = {{"drag", -1.0}};
  EXPECT_NE(message(r, outside).find("initial.drag"), std::string::npos);
  identify::IdentifyOptions offset = o;
  offset.unknowns = {"drag", "time_offset"};  // the log covers 0.5 s either side; the bound is 0.2
  offset.bounds = {{"time_offset", {-0.2, 0.2}}};
  EXPECT_EQ(message(r, offset), "(accepted)");
  bad = r;
  bad.joint_t.resize(bad.joint_t.size() - 400);  // ends 0.1 s after the last sample
  bad.joint_theta.resize(bad.joint_t.size());
  EXPECT_NE(message(bad, offset).find("rocking: joint_t: the joint's log covers"),
            std::string::npos)
      << message(bad, offset);
  identify::IdentifyOptions segment = o;
  segment.segment_duration = 0;
  EXPECT_NE(message(r, segment).find("segment_duration"), std::string::npos);
  for (const std::string& m : {message(bad, o), message(r, unknown), message(r, outside)})
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
}

// chi^2 beyond what its degrees of freedom allow: noise three times the sigma given makes chi^2/dof
// about 9, and every sigma is scaled by sqrt(chi^2/dof) (the Birge ratio), the unscaled beside it,
// with a warning; noise of the sigma given leaves sigma unscaled. The limit is the chi^2
// distribution's 99 % quantile, checked against the Wilson-Hilferty approximation (within 0.5 %
// at these dof).
TEST(Identify, SigmaIsScaledByTheBirgeRatioOnlyWhenChiSquaredExceedsItsQuantile) {
  const sim::SimulationSpec w = truth_world();
  identify::IdentifyOptions o;
  o.unknowns = {"rolling_resistance", "drag"};
  o.segment_duration = 5.0;
  o.threads = 2;
  const auto wilson_hilferty_99 = [](double dof) {
    const double z = 2.3263478740408408;  // the standard normal's 99 % quantile
    return dof * std::pow(1 - 2 / (9 * dof) + z * std::sqrt(2 / (9 * dof)), 3);
  };
  for (const double noise_factor : {1.0, 3.0}) {
    std::mt19937_64 rng(11);
    identify::Recording r = rocking(w, -0.7, 4.0, noise_factor * kTrackerSigmaSh, &rng);
    std::fill(r.sigma.begin(), r.sigma.end(), kTrackerSigmaSh);  // the sigma given
    const identify::IdentifyResult fit = identify::identify(w, {r}, o);
    const double dof = fit.degrees_of_freedom, ratio = fit.chi2 / dof;
    EXPECT_EQ(fit.degrees_of_freedom, static_cast<int>(r.t.size()) - 2 - 2);
    EXPECT_NEAR(fit.chi2_limit, wilson_hilferty_99(dof), 5e-3 * fit.chi2_limit);
    std::printf("[ identify ] noise %.0f x sigma: chi^2/dof %.2f, limit %.1f, sigma scale %.3g\n",
                noise_factor, ratio, fit.chi2_limit, fit.sigma_scale);
    const bool beyond = fit.chi2 > fit.chi2_limit;
    EXPECT_EQ(beyond, noise_factor > 1) << fit.chi2;
    EXPECT_DOUBLE_EQ(fit.sigma_scale, beyond ? std::sqrt(ratio) : 1.0);
    const bool warned = std::any_of(fit.warnings.begin(), fit.warnings.end(), [](const auto& m) {
      return m.find("every sigma is scaled by sqrt(chi^2/dof)") != std::string::npos;
    });
    EXPECT_EQ(warned, beyond);
    for (const identify::ParameterEstimate& p : fit.parameters) {
      ASSERT_TRUE(p.sigma && p.sigma_unscaled) << p.name << ": " << p.not_determined;
      EXPECT_NEAR(*p.sigma, fit.sigma_scale * *p.sigma_unscaled, 1e-12 * *p.sigma) << p.name;
      EXPECT_LE(std::abs(p.value - truth_of(p.name)), 3 * *p.sigma) << p.name;
    }
  }
}

// A parameter the data do not depend on (the rocking disk never slides nor leaves the hand, so
// neither mu_kinetic nor restitution acts) is held at its starting value, reported as not
// determined with that said, and the rest fitted as if it were not there: the same drag and
// rolling resistance, sigma and chi^2 as the fit without it, to a small fraction of sigma.
TEST(Identify, AParameterTheDataDoNotDetermineIsHeldAndTheRestFittedWithout) {
  const sim::SimulationSpec w = truth_world();
  std::mt19937_64 rng(5);
  const identify::Recording r = rocking(w, -0.7, 4.0, kTrackerSigmaSh, &rng);
  identify::IdentifyOptions two;
  two.unknowns = {"rolling_resistance", "drag"};
  two.initial = {{"rolling_resistance", 1.5e-4}, {"drag", 0.08}};
  two.segment_duration = 5.0;
  two.threads = 2;
  identify::IdentifyOptions four = two;
  four.unknowns = {"mu_kinetic", "rolling_resistance", "restitution", "drag"};
  four.initial["mu_kinetic"] = 0.55;
  const identify::IdentifyResult a = identify::identify(w, {r}, two);
  const identify::IdentifyResult b = identify::identify(w, {r}, four);
  for (const std::size_t j : {0u, 2u}) {
    const identify::ParameterEstimate& p = b.parameters[j];
    EXPECT_TRUE(p.held) << p.name;
    EXPECT_FALSE(p.sigma.has_value()) << p.name;
    EXPECT_EQ(p.value, p.initial) << p.name;
    EXPECT_NE(p.not_determined.find("held at its starting value"), std::string::npos)
        << p.not_determined;
    EXPECT_TRUE(std::isnan(b.correlation(static_cast<Eigen::Index>(j), 1)));
  }
  EXPECT_EQ(b.world.contact.mu_kinetic, 0.55);
  for (const auto& [ja, jb] : {std::pair<std::size_t, std::size_t>{0, 1}, {1, 3}}) {
    const identify::ParameterEstimate &p = a.parameters[ja], &q = b.parameters[jb];
    ASSERT_EQ(p.name, q.name);
    ASSERT_TRUE(p.sigma && q.sigma) << q.name << ": " << q.not_determined;
    EXPECT_FALSE(q.held);
    EXPECT_LE(std::abs(p.value - q.value), 0.05 * *p.sigma) << p.name;
    EXPECT_NEAR(*q.sigma, *p.sigma, 0.01 * *p.sigma) << p.name;
  }
  EXPECT_EQ(b.degrees_of_freedom, a.degrees_of_freedom);
  EXPECT_NEAR(b.chi2, a.chi2, 0.05);
}

// A fit stopped by max_iterations says so: not converged, Ceres' termination type, a warning.
TEST(Identify, AFitThatDidNotConvergeSaysSo) {
  const sim::SimulationSpec w = truth_world();
  std::mt19937_64 rng(2);
  identify::IdentifyOptions o;
  o.unknowns = {"rolling_resistance", "drag"};
  o.initial = {{"rolling_resistance", 1e-4}, {"drag", 0.05}};
  o.segment_duration = 5.0;
  o.max_iterations = 1;
  const identify::IdentifyResult r =
      identify::identify(w, {rocking(w, -0.7, 2.0, kTrackerSigmaSh, &rng)}, o);
  EXPECT_FALSE(r.converged);
  EXPECT_EQ(r.termination_type, "NO_CONVERGENCE");
  const bool warned = std::any_of(r.warnings.begin(), r.warnings.end(), [](const auto& m) {
    return m.find("the fit did not converge") != std::string::npos &&
           m.find("raise max_iterations") != std::string::npos;
  });
  EXPECT_TRUE(warned);
}
