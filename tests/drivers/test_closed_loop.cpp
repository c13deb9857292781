// The closed loop through the whole synthetic pipeline: simulate -> render -> track -> estimate
// -> control -> joint (paper section 5), its replay from a recording, the estimator's consistency
// in the loop, and the safe stop on faults.
#include "drivers/loop_support.hpp"
#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/recorded.hpp"
#include "flatland/scene/scene.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <random>
#include <string>
#include <tuple>

using namespace flatland;
namespace fs = std::filesystem;

namespace {

using flatland_test::feedback_scene;
using flatland_test::mean_chi2_bounds;

/// Linear interpolation of a logged quantity at time t.
template <typename Field>
double at(const std::vector<drivers::TickLog>& log, double t, Field field) {
  for (std::size_t i = 0; i + 1 < log.size(); ++i)
    if (log[i].t <= t && log[i + 1].t > t) {
      const double w = (t - log[i].t) / (log[i + 1].t - log[i].t);
      return field(log[i]) + w * (field(log[i + 1]) - field(log[i]));
    }
  return std::numeric_limits<double>::quiet_NaN();
}

struct TempDir {
  fs::path path;
  TempDir() {
    path = fs::temp_directory_path() /
           ("flatland-loop-" + std::to_string(std::random_device{}()) + "-" +
            std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

/// The apex time (s_h rising through 0) and the worst asymmetry of theta and s_h about it over
/// +-1.5 s: theta(t_a + tau) + theta(t_a - tau) = 2 theta(t_a) and s_h(t_a + tau) = -s_h(t_a - tau)
/// for the planned motion.
struct Symmetry {
  double t_apex = NAN, theta_apex = NAN, theta = NAN, s = NAN;
};
Symmetry symmetry(const std::vector<drivers::TickLog>& log) {
  Symmetry out;
  for (std::size_t i = 1; i < log.size(); ++i)
    if (log[i - 1].s_true < 0 && log[i].s_true >= 0 && log[i].t > 0.5) {
      out.t_apex = log[i - 1].t + (0 - log[i - 1].s_true) / (log[i].s_true - log[i - 1].s_true) *
                                      (log[i].t - log[i - 1].t);
      break;
    }
  if (!std::isfinite(out.t_apex)) return out;
  const auto theta = [](const drivers::TickLog& row) { return row.theta_true; };
  const auto s = [](const drivers::TickLog& row) { return row.s_true; };
  out.theta_apex = at(log, out.t_apex, theta);
  out.theta = out.s = 0;
  for (double tau = 0.1; tau <= 1.5; tau += 0.1) {
    out.theta =
        std::max(out.theta, std::abs(at(log, out.t_apex + tau, theta) +
                                     at(log, out.t_apex - tau, theta) - 2 * out.theta_apex));
    out.s = std::max(out.s, std::abs(at(log, out.t_apex + tau, s) + at(log, out.t_apex - tau, s)));
  }
  return out;
}

}  // namespace

// The paper's run (Fig. 10): 5 deg, 2T = 4.0 s, k = -1.1393, 30 Hz camera with 33 ms latency and
// 2 DN noise, feedback at 1 kHz. The paper reports symmetric theta and s_h and about 4.23 s: its
// controller slowed stage 2 for the disk. In the lossless world the loop keeps the plan's time
// and is symmetric about the apex as the plan is; with the air table's losses (the scene's
// contact section) the disk lags the plan and the controller slows stage 2 beyond the plan's
// 4.0 s. The losses break the time symmetry, so the lossy run is only nearly symmetric.
TEST(ClosedLoop, PaperRunSucceedsWithFeedback) {
  const Scene scene = feedback_scene();
  ASSERT_EQ(scene.controller.mode, "feedback");
  ASSERT_NEAR(scene.sim.motion.period, 4.0, 1e-12);
  ASSERT_NEAR(scene.sim.motion.k, -1.1393, 1e-12);
  ASSERT_TRUE(scene.sim.contact.has_losses());
  const drivers::LoopSetup setup(flatland::model::compile(scene));
  Scene lossless = scene;
  lossless.sim.contact.rolling_resistance = lossless.sim.contact.drag =
      lossless.sim.contact.drag_angular = 0;
  for (const Scene* world : {static_cast<const Scene*>(&lossless), &scene}) {
    const bool losses = world == &scene;
    SCOPED_TRACE(losses ? "the air table's losses" : "lossless");
    const drivers::SyntheticResult r =
        drivers::run_synthetic(setup, flatland::model::compile(*world));
    ASSERT_TRUE(r.success) << r.failure;
    EXPECT_EQ(r.outcome, drivers::Outcome::kSuccess);
    EXPECT_FALSE(r.loop.safe_stop);
    EXPECT_GT(r.fn_min_ratio, 0.0);
    EXPECT_LE(r.mu_max, *scene.sim.contact.mu);
    EXPECT_EQ(r.loop.frames_lost, 0);
    EXPECT_GT(r.goal.energy_margin, 0.0);
    if (losses) {
      EXPECT_GT(r.loop.duration_s, 4.1);  // stage 2 slowed for a lagging disk
      EXPECT_LT(r.loop.duration_s, 4.5);
    } else {
      EXPECT_NEAR(r.loop.duration_s, 4.0, 0.1);
    }
    const Symmetry sym = symmetry(r.loop.log);
    ASSERT_TRUE(std::isfinite(sym.t_apex));
    EXPECT_NEAR(sym.theta_apex, 0.5 * std::numbers::pi, 0.1);
    EXPECT_LT(sym.theta, losses ? 0.15 : 0.1);
    EXPECT_LT(sym.s, losses ? 0.2 : 0.05);
    std::fprintf(stderr,
                 "[ closed loop ] %s: duration %.3f s (paper ~4.23), apex at %.3f s, symmetry: "
                 "theta %.4f rad, s_h %.4f; fn_min %.4f mg, mu_max %.3f, s_end %.4f, NEES %.2f "
                 "over %ld frames\n",
                 losses ? "losses" : "lossless", r.loop.duration_s, sym.t_apex, sym.theta, sym.s,
                 r.fn_min_ratio, r.mu_max, r.s_end, r.nees_mean, r.nees_samples);
  }
}

// The outcome says where the disk ended, in the hybrid world. On a slippery hand (mu = 0.05, far
// below the 0.3 the plan needs) the played plan makes the disk slide, and it leaves the hand for
// good; the friction it needed while rolling never exceeds mu (beyond, it slides), and the world
// counts the time it slid and flew.
TEST(ClosedLoop, OutcomeSaysWhereTheDiskEnded) {
  Scene scene = feedback_scene();
  scene.controller.mode = "open-loop";
  const drivers::LoopSetup setup(flatland::model::compile(scene));
  Scene slippery = scene;
  slippery.sim.contact.mu = 0.05;
  slippery.sim.contact.mu_kinetic = 0.04;
  slippery.sim.contact.rolling_resistance = 1e-5;  // below mu_k r
  const drivers::SyntheticResult r =
      drivers::run_synthetic(setup, flatland::model::compile(slippery));
  EXPECT_FALSE(r.success);
  EXPECT_TRUE(r.outcome == drivers::Outcome::kSlidOff || r.outcome == drivers::Outcome::kDropped)
      << drivers::to_string(r.outcome) << ": " << r.failure;
  EXPECT_LE(r.mu_max, 0.05);
  EXPECT_GT(r.mode_time[static_cast<int>(sim::ContactMode::kSliding)], 0.0);
  EXPECT_GT(r.mode_time[static_cast<int>(sim::ContactMode::kFlight)], 0.0);
  ASSERT_FALSE(r.contact_events.empty());
  EXPECT_EQ(r.contact_events.back().kind, sim::EventKind::kDropped);
  // The nominal world succeeds open loop, and the disk is trapped in the back well.
  const drivers::SyntheticResult ok =
      drivers::run_synthetic(setup, flatland::model::compile(scene));
  EXPECT_EQ(ok.outcome, drivers::Outcome::kSuccess) << ok.failure;
  EXPECT_TRUE(ok.goal.trapped);
  EXPECT_TRUE(ok.goal.well_faces_up);
  EXPECT_NEAR(ok.goal.well_bottom, 1.0, 0.1);
}

// Open-loop playback drives the joint along the plan: the joint model (reference integration,
// PD torque loop, friction, the disk's load) tracks it closely and ends on the plan's final angle.
TEST(ClosedLoop, OpenLoopPlaybackTracksThePlan) {
  Scene scene = feedback_scene();
  scene.controller.mode = "open-loop";
  const drivers::LoopSetup setup(flatland::model::compile(scene));
  const drivers::SyntheticResult r = drivers::run_synthetic(setup, flatland::model::compile(scene));
  ASSERT_TRUE(r.loop.finished) << r.failure;
  EXPECT_NEAR(r.loop.duration_s, 4.0, 1e-9);
  double worst = 0;
  for (const auto& row : r.loop.log)
    if (row.t >= 0 && row.t <= 4.0)
      worst = std::max(worst, std::abs(row.theta_true - setup.plan.plan->hand(row.t).angle));
  // A 1 mrad tracking error moves the contact by ~0.1 mm: far below what the rolling notices.
  EXPECT_LT(worst, 1e-3);
  EXPECT_NEAR(r.loop.log.back().theta_true, std::numbers::pi, 1e-3);
  std::fprintf(stderr, "[ open loop ] worst tracking error %.2e rad, success %d (%s)\n", worst,
               r.success, r.failure.c_str());
}

// A recorded run played back through the recorded camera and the log joint drives the same
// estimator and controller to the same commands, bit for bit.
TEST(ClosedLoop, ReplayGivesTheSameCommandsBitForBit) {
  const Scene scene = feedback_scene();
  const drivers::LoopSetup setup(flatland::model::compile(scene));
  TempDir tmp;
  const fs::path rec = tmp.path / "rec";
  drivers::SyntheticResult original;
  {
    drivers::RecordingMetadata meta;
    meta.rate_hz = scene.joint.rate;
    meta.camera = "synthetic";
    meta.joint = "simulated";
    meta.scene = scene.origin;
    drivers::Recorder recorder(rec, meta);
    drivers::SyntheticOptions opt;
    opt.recorder = &recorder;
    original = drivers::run_synthetic(setup, flatland::model::compile(scene), opt);
    recorder.finish();
  }
  ASSERT_TRUE(original.success) << original.failure;

  drivers::RecordedCamera camera(rec);
  drivers::LogJoint joint(rec);
  drivers::LoopOptions lo;
  drivers::SimClock clock(nullptr, lo.t_start);
  lo.max_ticks = joint.ticks();
  const drivers::LoopResult replay = drivers::run_loop(setup, clock, camera, joint, lo);

  EXPECT_EQ(joint.mismatches(), 0) << "first at tick " << joint.first_mismatch_tick();
  EXPECT_EQ(joint.commands(), joint.ticks());
  ASSERT_EQ(replay.log.size(), original.loop.log.size());
  for (std::size_t i = 0; i < replay.log.size(); ++i) {
    ASSERT_EQ(replay.log[i].t, original.loop.log[i].t) << i;
    ASSERT_EQ(replay.log[i].command, original.loop.log[i].command) << "tick " << i;
    ASSERT_EQ(replay.log[i].s_est, original.loop.log[i].s_est) << "tick " << i;
  }
  EXPECT_EQ(replay.frames, original.loop.frames);
  EXPECT_EQ(replay.measurements, original.loop.measurements);
}

// The estimator inside the loop: its normalised estimation error squared (against the world's
// truth, at the ticks where frames are folded in) averages within the 95 % chi-square bounds,
// with latency compensation, on worlds perturbed as in the Monte Carlo study; without latency
// compensation the filter is measurably inconsistent.
TEST(ClosedLoop, EstimatorIsConsistentInTheLoop) {
  const Scene nominal = feedback_scene();
  const auto run_all = [&](bool compensate, int worlds) {
    Scene assumed = nominal;
    assumed.estimator.latency_compensation = compensate;
    const drivers::LoopSetup setup(flatland::model::compile(assumed));
    double sum = 0;
    long n = 0;
    int failures = 0;
    for (std::uint64_t seed = 1; seed <= static_cast<std::uint64_t>(worlds); ++seed) {
      // The world differs from what the loop assumes as in the Monte Carlo study: table tilt
      // 5 deg +- 0.25 deg, disk radius +- 2 %, start +- 0.02 in s_h, 5 ms latency jitter.
      std::mt19937_64 rng(seed);
      std::uniform_real_distribution<double> u(-1.0, 1.0);
      Scene truth = nominal;
      truth.effects.seed = seed;
      truth.sim.tilt = (5.0 + 0.25 * u(rng)) * std::numbers::pi / 180.0;
      truth.sim.object.radius *= 1.0 + 0.02 * u(rng);
      truth.sim.initial.s_h += 0.02 * u(rng);
      truth.camera->latency_jitter = 0.005;
      const drivers::SyntheticResult r =
          drivers::run_synthetic(setup, flatland::model::compile(truth));
      // Only up to the end of the motion: afterwards the disk rests, the estimate is exact and
      // samples pile up where there is nothing to test.
      const double t_end =
          std::isfinite(r.loop.duration_s) ? r.loop.duration_s : r.loop.log.back().t;
      if (!r.success) ++failures;
      for (const auto& row : r.loop.log)
        if (row.measured && std::isfinite(row.nees) && row.t > 0 && row.t < t_end) {
          sum += row.nees;
          ++n;
        }
    }
    return std::make_tuple(sum / static_cast<double>(n), n, failures);
  };
  // Twelve worlds: the mismatch is dominated by each world's tilt, so fewer would test the draw
  // rather than the filter. Three suffice to show the uncompensated filter's inconsistency.
  // The sanitizer stage runs the same code paths on two worlds and one, without the statistics.
  const bool short_run = flatland::test::short_tests();
  const int worlds_with = short_run ? 2 : 12, worlds_without = short_run ? 1 : 3;
  const auto [with, n_with, failed_with] = run_all(true, worlds_with);
  const auto [without, n_without, failed_without] = run_all(false, worlds_without);
  const auto [lo, hi] = mean_chi2_bounds(n_with, 2);
  std::fprintf(stderr,
               "[ NEES ] latency-compensated %.3f over %ld (95 %% bounds [%.3f, %.3f]); "
               "uncompensated %.3f over %ld; failed runs %d of %d / %d of %d\n",
               with, n_with, lo, hi, without, n_without, failed_with, worlds_with,
               failed_without, worlds_without);
  EXPECT_EQ(failed_with, 0);
  EXPECT_GT(n_with, 0);
  if (short_run) return;
  EXPECT_GT(with, lo);
  EXPECT_LT(with, hi);
  EXPECT_GT(without, mean_chi2_bounds(n_without, 2).second);
}

// Faults stop the hand safely with the reason logged; nothing crashes.
class ClosedLoopFault
    : public ::testing::TestWithParam<std::tuple<const char*, const char*, control::StopCause>> {};

TEST_P(ClosedLoopFault, SafeStop) {
  const auto [fault, expected_reason, expected_cause] = GetParam();
  Scene scene = feedback_scene();
  const std::string f = fault;
  if (f == "camera_stop") scene.faults.camera_stop = 1.5;
  if (f == "camera_stall") scene.faults.camera_stall = 1.5;
  if (f == "occlusion") scene.faults.occlusion = 1.5;
  if (f == "encoder_glitch") scene.faults.encoder_glitch = 1.5;
  const drivers::LoopSetup setup(flatland::model::compile(scene));
  const drivers::SyntheticResult r = drivers::run_synthetic(setup, flatland::model::compile(scene));
  EXPECT_FALSE(r.success);
  EXPECT_TRUE(r.loop.safe_stop) << r.failure;
  ASSERT_TRUE(r.loop.stop_reason.has_value()) << r.failure;
  EXPECT_EQ(r.loop.stop_reason->cause, expected_cause) << r.loop.stop_reason->detail;
  EXPECT_NE(r.loop.stop_reason->detail.find(expected_reason), std::string::npos)
      << r.loop.stop_reason->detail;
  // The sentence starts with the cause's name, as the CLI and the logs print it.
  EXPECT_EQ(
      r.loop.stop_reason->detail.rfind(std::string(control::to_string(expected_cause)) + ":", 0),
      0u)
      << r.loop.stop_reason->detail;
  ASSERT_FALSE(r.loop.log.empty());
  const drivers::TickLog& last = r.loop.log.back();
  EXPECT_EQ(last.mode, "safe-stop");
  // The hand comes to rest; the disk, thrown by the stopping hand, may fall back on it later and
  // knock it (the drive holds it: it stays within a few mrad/s).
  bool rested = false;
  for (const auto& row : r.loop.log)
    rested = rested || (row.mode == "safe-stop" && std::abs(row.theta_dot) < 1e-3);
  EXPECT_TRUE(rested) << "the hand never came to rest";
  EXPECT_LT(std::abs(last.theta_dot), 0.05) << "the hand is not held";
  // Within the drive's limits: the safe stop decelerates at controller.stop_deceleration.
  double worst = 0;
  for (const auto& row : r.loop.log)
    if (row.mode == "safe-stop") worst = std::max(worst, std::abs(row.command));
  EXPECT_LE(worst, scene.controller.stop_deceleration + 1e-9);
  std::fprintf(stderr, "[ fault %s ] %s\n", fault, r.loop.stop_reason->detail.c_str());
}

INSTANTIATE_TEST_SUITE_P(
    Faults, ClosedLoopFault,
    ::testing::Values(std::make_tuple("camera_stop", "no frames", control::StopCause::kCamera),
                      std::make_tuple("camera_stall", "stalled", control::StopCause::kCamera),
                      std::make_tuple("occlusion", "disk lost", control::StopCause::kTracking),
                      std::make_tuple("encoder_glitch", "encoder glitch",
                                      control::StopCause::kJoint)),
    [](const auto& info) { return std::string(std::get<0>(info.param)); });
