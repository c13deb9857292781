// identify on rendered and tracked recordings: the rocking and the throw of test_identify.cpp drawn
// by flatland's renderer (the air-table camera, 640 x 480, 2 DN sensor noise), the disk found by
// the tracker in each frame and mapped to s_h through the camera, each sample weighted by the
// tracker's own sigma carried to s_h (vision::contact_sigma, as track and the closed loop do). The
// tracker's error is then what it really is, partly systematic (docs/VISION.md), and its sigma
// what it claims, not the Gaussian noise of the stated size the other tests draw.
//
// Each frame is rendered once; a seed's camera is the same frames with its own sensor noise drawn
// (the renderer's apply_noise and quantize, with the renderer's random stream), which is what
// Renderer::capture makes of them: the first test checks that bit for bit.
#include "flatland/identify/identify.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include "identify/identify_support.hpp"
#include "scene_support.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

using namespace flatland;

namespace {

constexpr double kMuKinetic = 0.6, kRestitution = 0.4, kRollingResistance = 2e-4, kDrag = 0.1;

/// The air-table camera (2 DN read noise, no blur) over the world of test_identify.cpp.
Scene rendered_scene(std::uint64_t seed) {
  Scene scene = flatland_test::air_table_experiment(2.0, false, seed);
  scene.sim =
      flatland_test::air_table_world(0.8, kMuKinetic, kRestitution, kRollingResistance, kDrag);
  return scene;
}

/// A recording's truth and its frames before the sensor: the run (as identify simulates it: the
/// joint log's spline, rtol 1e-12), the linear image (CV_32FC3, DN) and the hand angle at each of
/// the truth's sample times.
struct CleanFrames {
  identify::Recording truth;
  sim::RunResult run;
  std::vector<cv::Mat> linear;
  std::vector<double> theta;
};

sim::RunResult run_of(const sim::SimulationSpec& world, const flatland_test::JointLog& log,
                      double s0, double t_end) {
  auto pb = std::make_shared<sim::RollingProblem>(*sim::build_problem(world));
  pb->motion = std::make_shared<identify::JointLogMotion>(log.t, log.theta);
  sim::RunOptions o = sim::run_options(world);
  o.model = sim::ContactModel::kHybrid;
  o.t_end = t_end;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  o.integrator.energy_tolerance = 1e-7;
  sim::InitialContact init;
  init.s_h = s0;
  return sim::simulate(pb, init, o);
}

render::SceneState state_at(const sim::RunResult& run, double t) {
  const sim::Trajectory& tr = run.trajectory;
  return render::SceneState::from_sample(tr.sample(std::clamp(t, tr.t_begin(), tr.t_end())));
}

CleanFrames clean_frames(render::Renderer& renderer, const std::string& name,
                         const sim::SimulationSpec& world, const flatland_test::JointLog& log,
                         double s0, double t_end) {
  CleanFrames f;
  f.truth = flatland_test::record(name, world, log, s0, 0, t_end, 30, 1.0, nullptr);
  f.run = run_of(world, log, s0, t_end);
  EXPECT_EQ(f.run.reason, sim::StopReason::kEndTime) << name;
  for (const double t : f.truth.t) {
    const render::SceneState s = state_at(f.run, t);
    f.linear.push_back(renderer.render_linear(s));
    f.theta.push_back(renderer.truth(s).theta);
  }
  return f;
}

/// One frame as the camera of `effects` captures it from its linear image, drawing from `rng`.
cv::Mat captured(const cv::Mat& linear, const EffectsSpec& effects, render::EffectsRng& rng) {
  cv::Mat image = linear.clone();
  render::apply_noise(image, effects.noise_read_dn, effects.noise_shot_gain, rng);
  return render::quantize(image);
}

/// The recording a seed's camera gives: each frame captured, tracked and mapped to s_h with the
/// tracker's sigma carried through the mapping. Adds the squared errors against the truth to
/// `sum2` (and their count to `count`).
identify::Recording tracked(const CleanFrames& clean, const vision::HandMapping& mapping,
                            const EffectsSpec& effects, render::EffectsRng& rng, double& sum2,
                            int& count) {
  identify::Recording r = clean.truth;
  vision::Tracker tracker;
  double guess = r.s_h.front();
  for (std::size_t i = 0; i < r.t.size(); ++i) {
    const vision::TrackResult tr = tracker.track(captured(clean.linear[i], effects, rng));
    EXPECT_TRUE(tr.ok()) << r.name << " frame " << i;
    const auto c = vision::pixel_to_contact(mapping, tr.center, clean.theta[i], guess, 0.5);
    EXPECT_TRUE(c.has_value()) << r.name << " frame " << i;
    if (!tr.ok() || !c) continue;
    r.s_h[i] = c->s_h;
    r.sigma[i] = vision::contact_sigma(mapping, tr.center, tr.sigma_px, clean.theta[i], c->s_h);
    const double e = std::remainder(c->s_h - clean.truth.s_h[i], 4.0);
    sum2 += e * e;
    ++count;
    guess = c->s_h;
  }
  return r;
}

double truth_of(const std::string& name) {
  if (name == "mu_kinetic") return kMuKinetic;
  if (name == "restitution") return kRestitution;
  if (name == "rolling_resistance") return kRollingResistance;
  return kDrag;
}

}  // namespace

// The frames this file's seeds are made of are the renderer's own: its linear image plus its
// sensor noise drawn from its seeded stream equals Renderer::capture to the bit.
TEST(IdentifyRendered, NoiseOnTheCleanFramesIsWhatTheRendererCaptures) {
  const Scene scene = rendered_scene(7);
  const auto model = model::compile(scene);
  render::Renderer renderer(model::render_setup(*model));
  const flatland_test::JointLog log = flatland_test::butterfly_hand(3.2, -1.155794, 2.5);
  const sim::RunResult run = run_of(scene.sim, log, -1, 2.5);
  ASSERT_EQ(run.reason, sim::StopReason::kEndTime);
  render::EffectsRng rng(scene.effects.seed);
  for (const double t : {0.0, 1.0 / 30, 2.0 / 30, 1.5}) {
    const render::Frame frame = renderer.capture(run.trajectory, t);
    const cv::Mat ours = captured(renderer.render_linear(state_at(run, t)), scene.effects, rng);
    ASSERT_EQ(frame.image.type(), ours.type());
    EXPECT_EQ(cv::norm(frame.image, ours, cv::NORM_INF), 0.0) << t;
  }
}

/// The rendered rocking and throw, each frame drawn once for all the tests below.
class IdentifyRenderedSeeds : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scene_ = new Scene(rendered_scene(1));
    const auto model = model::compile(*scene_);
    render::Renderer renderer(model::render_setup(*model));
    mapping_ = new vision::HandMapping(model::hand_mapping(*model, renderer.camera()));
    rocking_ = new CleanFrames(
        clean_frames(renderer, "rocking", scene_->sim, flatland_test::still_hand(4.0), -0.7, 4.0));
    throw_ =
        new CleanFrames(clean_frames(renderer, "throw", scene_->sim,
                                     flatland_test::butterfly_hand(3.2, -1.155794, 2.5), -1, 2.5));
  }
  static void TearDownTestSuite() {
    delete scene_;
    delete mapping_;
    delete rocking_;
    delete throw_;
  }
  static identify::IdentifyOptions four_unknowns() {
    identify::IdentifyOptions opt;
    opt.unknowns = {"mu_kinetic", "restitution", "rolling_resistance", "drag"};
    opt.initial = {{"mu_kinetic", 0.55},
                   {"restitution", 0.35},
                   {"rolling_resistance", 1.5e-4},
                   {"drag", 0.08}};
    opt.segment_duration = 3.0;
    opt.threads = 2;
    return opt;
  }
  /// Seed `seed`'s two recordings, tracked.
  static std::vector<identify::Recording> recordings(int seed, double& sum2, int& count) {
    render::EffectsRng rng(static_cast<std::uint64_t>(seed));
    identify::Recording a = tracked(*rocking_, *mapping_, scene_->effects, rng, sum2, count);
    identify::Recording b = tracked(*throw_, *mapping_, scene_->effects, rng, sum2, count);
    return {a, b};
  }
  static Scene* scene_;
  static vision::HandMapping* mapping_;
  static CleanFrames *rocking_, *throw_;
};
Scene* IdentifyRenderedSeeds::scene_ = nullptr;
vision::HandMapping* IdentifyRenderedSeeds::mapping_ = nullptr;
CleanFrames* IdentifyRenderedSeeds::rocking_ = nullptr;
CleanFrames* IdentifyRenderedSeeds::throw_ = nullptr;

// The acceptance of issue 26 on the real thing: ten seeds of the camera's noise over the rendered
// rocking and throw, each tracked and fitted for mu_kinetic, restitution, rolling resistance and
// drag (started 8-25 % off, as in test_identify.cpp), weighted by the tracker's sigma. The truth
// is within 2 sigma in at least 9 of 10 seeds, and the RMS error from the truth over the seeds is
// within 2 sigma. The spread over the seeds is printed but not compared with sigma: the seeds
// share every frame but the sensor noise, and most of the tracker's error on them is the
// rendering's edge, the same in every seed, which a spread does not see (docs/IDENTIFY.md).
TEST_F(IdentifyRenderedSeeds, TenSeedsGiveTheWorldWithinTwoSigma) {
  const bool short_run = flatland::test::short_tests();
  const int seeds = short_run ? 2 : 10;
  const identify::IdentifyOptions opt = four_unknowns();
  const std::size_t K = opt.unknowns.size();
  std::vector<std::vector<double>> values(K), sigmas(K);
  double sum2 = 0, mean_ratio = 0, mean_given = 0;
  int count = 0, scaled = 0, given = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const std::vector<identify::Recording> recs = recordings(seed, sum2, count);
    for (const identify::Recording& r : recs)
      for (const double s : r.sigma) mean_given += s, ++given;
    const identify::IdentifyResult r = identify::identify(scene_->sim, recs, opt);
    EXPECT_TRUE(r.converged) << seed << ": " << r.termination;
    const double ratio = r.chi2 / r.degrees_of_freedom;
    std::printf("[ identify ] seed %2d: chi^2/dof %.2f (limit %.2f), sigma scale %.3g\n", seed,
                ratio, r.chi2_limit / r.degrees_of_freedom, r.sigma_scale);
    mean_ratio += ratio / seeds;
    scaled += r.sigma_scale > 1;
    for (std::size_t j = 0; j < K; ++j) {
      const identify::ParameterEstimate& p = r.parameters[j];
      ASSERT_TRUE(p.sigma) << seed << " " << p.name << ": " << p.not_determined;
      values[j].push_back(p.value);
      sigmas[j].push_back(*p.sigma);
    }
  }
  const double rms = std::sqrt(sum2 / count);
  mean_given /= given;
  std::printf(
      "[ identify ] tracked s_h: rms error %.3g, mean sigma given %.3g (error / sigma %.2f); "
      "mean chi^2/dof %.2f, sigma scaled in %d/%d seeds\n",
      rms, mean_given, rms / mean_given, mean_ratio, scaled, seeds);
  for (std::size_t j = 0; j < K; ++j) {
    const double truth = truth_of(opt.unknowns[j]);
    int within = 0;
    double mean = 0, spread = 0, error2 = 0;
    for (int i = 0; i < seeds; ++i) {
      within += std::abs(values[j][i] - truth) <= 2 * sigmas[j][i];
      mean += values[j][i] / seeds;
      error2 += std::pow(values[j][i] - truth, 2) / seeds;
    }
    for (int i = 0; i < seeds; ++i) spread += std::pow(values[j][i] - mean, 2) / (seeds - 1);
    spread = std::sqrt(spread);
    const double error = std::sqrt(error2);
    const auto [lo, hi] = std::minmax_element(sigmas[j].begin(), sigmas[j].end());
    std::printf(
        "[ identify ] %-18s truth %.6g: within 2 sigma %d/%d, mean %.6g, spread %.3g, rms error "
        "%.3g, sigma %.3g..%.3g (sigma / error %.2f, sigma / spread %.1f)\n",
        opt.unknowns[j].c_str(), truth, within, seeds, mean, spread, error, *lo, *hi, *lo / error,
        *lo / spread);
    EXPECT_GE(within, short_run ? seeds - 1 : 9) << opt.unknowns[j];
    EXPECT_LE(error, 2 * *lo) << opt.unknowns[j];
  }
}

// The rule of docs/IDENTIFY.md, "Covariance", on rendered data: the same tracked recordings
// weighted by a sigma that is too small (4e-5, the noise model's of test_identify.cpp, about half
// the tracked s_h's real error here) make chi^2 exceed its 99 % quantile; identify then scales
// every sigma by sqrt(chi^2/dof), says so, and with the scaled sigma the truth is within 2 sigma.
TEST_F(IdentifyRenderedSeeds, SigmaGivenTooSmallIsScaledToCoverTheError) {
  const int seeds = flatland::test::short_tests() ? 1 : 2;
  const identify::IdentifyOptions opt = four_unknowns();
  double sum2 = 0;
  int count = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    std::vector<identify::Recording> recs = recordings(seed, sum2, count);
    for (identify::Recording& r : recs)
      std::fill(r.sigma.begin(), r.sigma.end(), flatland_test::kTrackerSigmaSh);
    const identify::IdentifyResult r = identify::identify(scene_->sim, recs, opt);
    std::printf("[ identify ] sigma 4e-5, seed %d: chi^2/dof %.2f, sigma scale %.3g\n", seed,
                r.chi2 / r.degrees_of_freedom, r.sigma_scale);
    ASSERT_GT(r.chi2, r.chi2_limit);
    EXPECT_DOUBLE_EQ(r.sigma_scale, std::sqrt(r.chi2 / r.degrees_of_freedom));
    EXPECT_TRUE(std::any_of(r.warnings.begin(), r.warnings.end(), [](const std::string& w) {
      return w.find("sigma is scaled") != std::string::npos;
    }));
    for (const identify::ParameterEstimate& p : r.parameters) {
      ASSERT_TRUE(p.sigma && p.sigma_unscaled) << p.name << ": " << p.not_determined;
      std::printf("[ identify ]   %-18s %.6g +- %.2g (unscaled %.2g), truth %.6g\n", p.name.c_str(),
                  p.value, *p.sigma, *p.sigma_unscaled, truth_of(p.name));
      EXPECT_LE(std::abs(p.value - truth_of(p.name)), 2 * *p.sigma) << p.name;
    }
  }
}
