// identify on rendered and tracked recordings: the rocking and the throw of test_identify.cpp drawn
// by flatland's renderer (the air-table camera, 640 x 480, 2 DN sensor noise), the disk found by
// the tracker in each frame and mapped to s_h through the camera, each sample weighted by the
// tracker's own sigma carried to s_h (vision::contact_sigma, as track and the closed loop do). The
// tracker's error is then what it really is, partly systematic (docs/VISION.md), and its sigma
// what it claims, not the Gaussian noise of the stated size the other tests draw.
//
// A seed is a session of the experiment repeated: what a researcher cannot hold fixed from one
// session to the next is drawn per seed (SessionDraw: where the disk is let go, when the hand
// starts after it, the camera as mounted again, when its frames fall, its sensor noise), and
// each seed's frames are captured by its own Renderer and tracked, so that the spread over seeds
// sees the tracker's whole error. The tracker's error on a frame depends on where the disk's edge
// falls on the pixels: with frames rendered once and only the sensor noise drawn per seed (this
// file's first version), most of it was the same in every seed and the spread saw a tenth of it.
// Measured (docs/IDENTIFY.md, "Acceptance"): the tracked s_h carries an offset per session (up to
// 1.1e-4, about one sigma, the same in both recordings of a session, which share only the
// camera's mounting) on top of errors independent from frame to frame; the truth is within 2 sigma
// in 10 of 10 sessions for each parameter, and each session's sigma is 0.89-1.64 times the spread
// over the sessions. (Session 4 is where a fit stopping short of its minimum fails the factor 2:
// before the continuation of docs/IDENTIFY.md, "Convergence", it stopped at chi^2 563 against the
// minimum's 155.7, its sigma scaled by 1.74.) A session costs about 1.2 s of CPU to render and
// track (197 frames) and 4 s to fit.
#include "flatland/identify/identify.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
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
#include <limits>
#include <map>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

using namespace flatland;

namespace {

using flatland_test::kDrag;
using flatland_test::kMuKinetic;
using flatland_test::kRestitution;
using flatland_test::kRollingResistance;
constexpr double kRockingEnd = 4.0, kThrowEnd = 2.5, kThrowPeriod = 3.2, kThrowDip = -1.155794;
constexpr double kFrameRate = 30.0;

/// What changes from one session of the experiment to the next, drawn per seed, uniformly within
/// a careful researcher's ranges: the disk placed by hand (rocking from s_h -0.7 +- 0.05, about
/// +- 1.3 cm of arc; the throw from -1 +- 0.02, +- 4 mm), the hand started 0-20 ms after the disk
/// is let go, the camera's shutter free-running against both (the first frame 0-33 ms after the
/// release), and the camera mounted again: its centre within +- 1 cm of the nominal in each axis
/// (at 1.2 m, 1 cm is 7.5 px), its aim within +- 1 cm on the table, turned about its axis by up to
/// +- 2 degrees. The camera is known exactly (as if calibrated without error): the tracker's
/// error is the only measurement error.
struct SessionDraw {
  double rocking_s0 = 0, throw_s0 = 0;        ///< where the disk is let go (s_h)
  double throw_delay = 0;                     ///< s, the hand's start after the release
  double rocking_phase = 0, throw_phase = 0;  ///< s, the first frame after the release
  CameraSpec camera;
};

/// The air-table camera (2 DN read noise, no blur) over the world of test_identify.cpp, with the
/// renderer's random stream seeded by `seed`.
Scene rendered_scene(std::uint64_t seed) {
  Scene scene = flatland_test::air_table_experiment(2.0, false, seed);
  scene.sim =
      flatland_test::air_table_world(0.8, kMuKinetic, kRestitution, kRollingResistance, kDrag);
  return scene;
}

SessionDraw draw_session(int seed, const CameraSpec& nominal) {
  // Not the renderer's stream (seeded by `seed` too): an offset keeps the two independent.
  std::mt19937_64 rng(0x5eed0000ULL + static_cast<std::uint64_t>(seed));
  const auto uniform = [&rng](double lo, double hi) {
    return std::uniform_real_distribution<double>(lo, hi)(rng);
  };
  SessionDraw d;
  d.rocking_s0 = uniform(-0.75, -0.65);
  d.throw_s0 = uniform(-1.02, -0.98);
  d.throw_delay = uniform(0.0, 0.02);
  d.rocking_phase = uniform(0.0, 1.0 / kFrameRate);
  d.throw_phase = uniform(0.0, 1.0 / kFrameRate);
  d.camera = nominal;
  for (double& x : d.camera.position) x += uniform(-0.01, 0.01);
  d.camera.look_at[0] += uniform(-0.01, 0.01);
  d.camera.look_at[1] += uniform(-0.01, 0.01);
  const double roll = uniform(-2.0, 2.0) * std::numbers::pi / 180.0;
  d.camera.up = {std::sin(roll), std::cos(roll), 0.0};
  return d;
}

/// The joint's log of the throw: the paper's motion too fast (2T = 3.2 s), started `delay` after
/// the release, palm up before that, logged at 1 kHz over [-0.5, t_end + 0.5].
flatland_test::JointLog throw_hand(double delay) {
  const sim::ButterflyMotion m(kThrowPeriod, kThrowDip);
  return flatland_test::joint_log(-0.5, kThrowEnd + 0.5, 1e-3,
                                  [&](double t) { return m.at(t - delay).angle; });
}

/// The world's run from rest at s0, the hand driven by the log's spline (as identify simulates
/// it), rtol 1e-12.
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

/// The squared errors of tracked s_h against the truth, and the sigma given, over recordings.
struct TrackedError {
  double sum2 = 0, sigma_sum = 0;
  int count = 0;
};

/// One recording of a session: the run captured by `renderer` at phase + i / 30 s up to t_end,
/// each frame tracked and mapped to s_h with the tracker's sigma carried through the mapping.
identify::Recording tracked_recording(const std::string& name, render::Renderer& renderer,
                                      const vision::HandMapping& mapping,
                                      const sim::SimulationSpec& world,
                                      const flatland_test::JointLog& log, double s0, double t_end,
                                      double phase, TrackedError& error) {
  const sim::RunResult run = run_of(world, log, s0, t_end);
  EXPECT_EQ(run.reason, sim::StopReason::kEndTime) << name;
  identify::Recording r;
  r.name = name;
  r.joint_t = log.t;
  r.joint_theta = log.theta;
  vision::Tracker tracker;
  double guess = std::numeric_limits<double>::quiet_NaN();
  for (int i = 0; phase + i / kFrameRate <= t_end; ++i) {
    const double t = phase + i / kFrameRate;
    const render::Frame frame = renderer.capture(run.trajectory, t);
    const vision::TrackResult tr = tracker.track(frame.image);
    EXPECT_TRUE(tr.ok()) << name << " t " << t;
    if (!tr.ok()) continue;
    const auto c = vision::follow_contact(mapping, tr.center, frame.truth.theta, guess);
    EXPECT_TRUE(c.has_value()) << name << " t " << t;
    if (!c) continue;
    r.t.push_back(t);
    r.s_h.push_back(c->s_h);
    r.sigma.push_back(
        vision::contact_sigma(mapping, tr.center, tr.sigma_px, frame.truth.theta, c->s_h));
    const double e = std::remainder(c->s_h - run.trajectory.s_h(t), 4.0);
    error.sum2 += e * e;
    error.sigma_sum += r.sigma.back();
    ++error.count;
    guess = c->s_h;
  }
  return r;
}

/// A session's two recordings, rendered with its own camera and noise, tracked.
std::vector<identify::Recording> session_recordings(int seed, TrackedError& error) {
  Scene scene = rendered_scene(static_cast<std::uint64_t>(seed));
  const SessionDraw d = draw_session(seed, *scene.camera);
  scene.camera = d.camera;
  const auto model = model::compile(scene);
  render::Renderer renderer(model::render_setup(*model));
  const vision::HandMapping mapping = model::hand_mapping(*model, renderer.camera());
  return {tracked_recording("rocking", renderer, mapping, scene.sim,
                            flatland_test::still_hand(kRockingEnd), d.rocking_s0, kRockingEnd,
                            d.rocking_phase, error),
          tracked_recording("throw", renderer, mapping, scene.sim, throw_hand(d.throw_delay),
                            d.throw_s0, kThrowEnd, d.throw_phase, error)};
}

double truth_of_parameter(const std::string& name) {
  if (name == "mu_kinetic") return kMuKinetic;
  if (name == "restitution") return kRestitution;
  if (name == "rolling_resistance") return kRollingResistance;
  return kDrag;
}

int count_events(const sim::RunResult& run, sim::EventKind kind) {
  return static_cast<int>(
      std::count_if(run.events.begin(), run.events.end(),
                    [kind](const sim::RecordedEvent& e) { return e.kind == kind; }));
}

}  // namespace

// Every session drawn is the same experiment: the rocking only rolls (its decay is what
// separates drag from rolling resistance), the throw slides before the tip (mu_k), flies over it
// and bounces on the back (restitution). A draw beyond these would test another experiment.
TEST(IdentifyRendered, EverySessionDrawnRocksAndThrowsAlike) {
  const Scene scene = rendered_scene(1);
  for (int seed = 1; seed <= 10; ++seed) {
    const SessionDraw d = draw_session(seed, *scene.camera);
    const sim::RunResult rocking =
        run_of(scene.sim, flatland_test::still_hand(kRockingEnd), d.rocking_s0, kRockingEnd);
    ASSERT_EQ(rocking.reason, sim::StopReason::kEndTime) << seed;
    EXPECT_EQ(count_events(rocking, sim::EventKind::kSlipStart), 0) << seed;
    EXPECT_EQ(count_events(rocking, sim::EventKind::kLiftOff), 0) << seed;
    EXPECT_EQ(count_events(rocking, sim::EventKind::kRest), 0) << seed;
    const sim::RunResult thrown =
        run_of(scene.sim, throw_hand(d.throw_delay), d.throw_s0, kThrowEnd);
    ASSERT_EQ(thrown.reason, sim::StopReason::kEndTime) << seed;
    EXPECT_GE(count_events(thrown, sim::EventKind::kSlipStart), 1) << seed;
    EXPECT_GE(count_events(thrown, sim::EventKind::kLiftOff), 1) << seed;
    EXPECT_GE(count_events(thrown, sim::EventKind::kImpact), 3) << seed;
    EXPECT_GT(thrown.final.s_h, 0.0) << seed << ": the disk did not land on the back";
    std::printf(
        "[ identify ] session %2d: rocking from %.3f (phase %.1f ms), throw from %.3f "
        "(hand %.1f ms late, phase %.1f ms): %d impacts, ends at s_h %.3f\n",
        seed, d.rocking_s0, 1e3 * d.rocking_phase, d.throw_s0, 1e3 * d.throw_delay,
        1e3 * d.throw_phase, count_events(thrown, sim::EventKind::kImpact), thrown.final.s_h);
  }
}

/// The sessions' tracked recordings, each rendered once for all the tests below.
class IdentifyRenderedSeeds : public ::testing::Test {
 protected:
  static void TearDownTestSuite() { sessions_.clear(); }
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
  struct Session {
    std::vector<identify::Recording> recordings;
    TrackedError error;
  };
  /// Seed `seed`'s session: its two recordings, tracked.
  static const Session& session(int seed) {
    auto it = sessions_.find(seed);
    if (it == sessions_.end()) {
      Session s;
      s.recordings = session_recordings(seed, s.error);
      it = sessions_.emplace(seed, std::move(s)).first;
    }
    return it->second;
  }
  static const sim::SimulationSpec& world() {
    static const Scene scene = rendered_scene(1);
    return scene.sim;
  }
  static std::map<int, Session> sessions_;
};
std::map<int, IdentifyRenderedSeeds::Session> IdentifyRenderedSeeds::sessions_;

// The acceptance of issue 26 on the real thing: ten sessions, each rendered, tracked and fitted
// for mu_kinetic, restitution, rolling resistance and drag (started 8-25 % off, as in
// test_identify.cpp), weighted by the tracker's sigma. Both halves, per parameter:
// - the truth within 2 sigma (each session's own sigma) in at least 9 of 10 sessions;
// - every session's sigma within a factor 2 of the spread over the sessions (the sample standard
//   deviation of the ten values about their mean). Each session's, not their median: a user has
//   one fit and its one sigma, which must be the scale of that fit's error; the spread over
//   independent sessions is that error's scale measured. (Ten values give the spread to about
//   +- 25 %; for a right sigma its 95 % range is 0.69-1.8 times the spread.)
// And the RMS error from the truth within 2 sigma: a bias common to all sessions would show there
// and not in the spread.
TEST_F(IdentifyRenderedSeeds, TruthWithinTwoSigmaInNineOfTenSessionsAndSigmaMatchesTheSpread) {
  // Under the sanitizers (FLATLAND_TEST_SHORT) not run: one session took 90 s there, and its code
  // paths (Renderer::capture, the tracker, identify on tracked recordings) are run there by
  // CliIdentify.ARenderedAndTrackedVideoIsFittedToItsWorld and the closed-loop tests.
  if (flatland::test::short_tests())
    GTEST_SKIP() << "a statistic of ten sessions: the Release stage";
  const int seeds = 10;
  const identify::IdentifyOptions opt = four_unknowns();
  const std::size_t K = opt.unknowns.size();
  std::vector<std::vector<double>> values(K), sigmas(K);
  TrackedError tracked;
  double mean_ratio = 0;
  int scaled = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const Session& s = session(seed);
    tracked.sum2 += s.error.sum2;
    tracked.sigma_sum += s.error.sigma_sum;
    tracked.count += s.error.count;
    const identify::IdentifyResult r = identify::identify(world(), s.recordings, opt);
    EXPECT_TRUE(r.converged) << seed << ": " << r.termination;
    const double ratio = r.chi2 / r.degrees_of_freedom;
    std::printf(
        "[ identify ] seed %2d: tracked s_h rms error %.3g, mean sigma %.3g; chi^2/dof "
        "%.2f (limit %.2f), sigma scale %.3g\n",
        seed, std::sqrt(s.error.sum2 / s.error.count), s.error.sigma_sum / s.error.count, ratio,
        r.chi2_limit / r.degrees_of_freedom, r.sigma_scale);
    mean_ratio += ratio / seeds;
    scaled += r.sigma_scale > 1;
    for (std::size_t j = 0; j < K; ++j) {
      const identify::ParameterEstimate& p = r.parameters[j];
      ASSERT_TRUE(p.sigma) << seed << " " << p.name << ": " << p.not_determined;
      values[j].push_back(p.value);
      sigmas[j].push_back(*p.sigma);
      std::printf("[ identify ]   %-18s %.6g +- %.3g (%+.2f sigma)\n", p.name.c_str(), p.value,
                  *p.sigma, (p.value - truth_of_parameter(p.name)) / *p.sigma);
    }
  }
  const double rms = std::sqrt(tracked.sum2 / tracked.count);
  const double mean_given = tracked.sigma_sum / tracked.count;
  std::printf(
      "[ identify ] tracked s_h: rms error %.3g, mean sigma given %.3g (error / sigma %.2f); "
      "mean chi^2/dof %.2f, sigma scaled in %d/%d seeds\n",
      rms, mean_given, rms / mean_given, mean_ratio, scaled, seeds);
  for (std::size_t j = 0; j < K; ++j) {
    const double truth = truth_of_parameter(opt.unknowns[j]);
    int within = 0;
    double mean = 0, spread = 0, error2 = 0;
    for (int i = 0; i < seeds; ++i) {
      within += std::abs(values[j][i] - truth) <= 2 * sigmas[j][i];
      mean += values[j][i] / seeds;
      error2 += std::pow(values[j][i] - truth, 2) / seeds;
    }
    for (int i = 0; i < seeds; ++i) spread += std::pow(values[j][i] - mean, 2);
    spread = std::sqrt(spread / (seeds - 1));
    const double error = std::sqrt(error2);
    std::vector<double> sorted = sigmas[j];
    std::sort(sorted.begin(), sorted.end());
    const double median = 0.5 * (sorted[(seeds - 1) / 2] + sorted[seeds / 2]);
    std::printf(
        "[ identify ] %-18s truth %.6g: within 2 sigma %d/%d, mean %.6g (%+.2f spreads / sqrt(n) "
        "from the truth), spread %.3g, rms error %.3g, sigma %.3g..%.3g median %.3g (sigma / "
        "spread %.2f..%.2f, median %.2f; sigma / rms error %.2f..%.2f)\n",
        opt.unknowns[j].c_str(), truth, within, seeds, mean,
        (mean - truth) / (spread / std::sqrt(seeds)), spread, error, sorted.front(), sorted.back(),
        median, sorted.front() / spread, sorted.back() / spread, median / spread,
        sorted.front() / error, sorted.back() / error);
    EXPECT_GE(within, 9) << opt.unknowns[j];
    EXPECT_LE(error, 2 * sorted.front()) << opt.unknowns[j];
    for (int i = 0; i < seeds; ++i) {
      EXPECT_LE(sigmas[j][i], 2 * spread) << opt.unknowns[j] << " seed " << i + 1;
      EXPECT_GE(sigmas[j][i], spread / 2) << opt.unknowns[j] << " seed " << i + 1;
    }
  }
}

// The rule of docs/IDENTIFY.md, "Covariance", on rendered data: the same tracked recordings
// weighted by a sigma that is too small (4e-5, the noise model's of test_identify.cpp, under the
// tracked s_h's real error here) make chi^2 exceed its 99 % quantile; identify then scales every
// sigma by sqrt(chi^2/dof), says so, and the scaled sigma covers the error: every value of two
// seeds within 3 scaled sigma of the truth. (3, not 2: eight values at once are all within 2 of a
// right sigma only two times in three, within 3 in 98 of 100; unscaled, seed 1's rolling
// resistance is 3.2 sigma off.)
TEST_F(IdentifyRenderedSeeds, SigmaGivenTooSmallIsScaledToCoverTheError) {
  // Under the sanitizers (FLATLAND_TEST_SHORT) not run: 113 s there for one session, whose code
  // paths the test above (a rendered session fitted) and test_identify.cpp's
  // SigmaIsScaledByTheBirgeRatioOnlyWhenChiSquaredExceedsItsQuantile (sigma scaled) run.
  if (flatland::test::short_tests())
    GTEST_SKIP() << "a second fit of rendered sessions: the Release stage";
  const int seeds = 2;
  const identify::IdentifyOptions opt = four_unknowns();
  for (int seed = 1; seed <= seeds; ++seed) {
    std::vector<identify::Recording> recs = session(seed).recordings;
    for (identify::Recording& r : recs)
      std::fill(r.sigma.begin(), r.sigma.end(), flatland_test::kTrackerSigmaSh);
    const identify::IdentifyResult r = identify::identify(world(), recs, opt);
    std::printf("[ identify ] sigma 4e-5, seed %d: chi^2/dof %.2f, sigma scale %.3g\n", seed,
                r.chi2 / r.degrees_of_freedom, r.sigma_scale);
    ASSERT_GT(r.chi2, r.chi2_limit);
    EXPECT_DOUBLE_EQ(r.sigma_scale, std::sqrt(r.chi2 / r.degrees_of_freedom));
    EXPECT_TRUE(std::any_of(r.warnings.begin(), r.warnings.end(), [](const std::string& w) {
      return w.find("sigma is scaled") != std::string::npos;
    }));
    for (const identify::ParameterEstimate& p : r.parameters) {
      ASSERT_TRUE(p.sigma && p.sigma_unscaled) << p.name << ": " << p.not_determined;
      const double off = p.value - truth_of_parameter(p.name);
      std::printf(
          "[ identify ]   %-18s %.6g +- %.2g (unscaled %.2g), truth %.6g: %+.2f sigma "
          "(unscaled %+.2f)\n",
          p.name.c_str(), p.value, *p.sigma, *p.sigma_unscaled, truth_of_parameter(p.name),
          off / *p.sigma, off / *p.sigma_unscaled);
      EXPECT_LE(std::abs(off), 3 * *p.sigma) << p.name;
    }
  }
}
