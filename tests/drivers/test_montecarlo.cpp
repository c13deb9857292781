// Monte Carlo of the closed loop (drivers/montecarlo.hpp): the perturbed worlds stay within the
// stated bounds, are a function of (seed, run) alone, the Wilson interval matches values worked
// out by hand, and the results do not depend on the number of threads.
#include "flatland/drivers/montecarlo.hpp"
#include "flatland/scene/scene.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

using namespace flatland;

namespace {

Scene nominal() { return load_scene(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml"); }

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kZ = 1.959963984540054;  // the 97.5 % normal quantile

}  // namespace

TEST(MonteCarloPerturb, StaysWithinTheStatedBoundsAndCoversThem) {
  const Scene s0 = nominal();
  // The bundled scene is the nominal experiment; the bounds below are relative to it.
  ASSERT_DOUBLE_EQ(s0.sim.initial.s_h, -1.0);
  ASSERT_NEAR(s0.sim.tilt, 5 * kDeg, 1e-15);
  const drivers::Perturbations p;  // the defaults
  double lo[4] = {1e9, 1e9, 1e9, 1e9}, hi[4] = {-1e9, -1e9, -1e9, -1e9};
  for (int run = 0; run < 400; ++run) {
    drivers::DrawnPerturbation d;
    const Scene s = drivers::perturb(s0, p, 42, run, &d);
    const double rel[4] = {(s.sim.initial.s_h + 1.0) / 0.02, (s.sim.tilt / kDeg - 5.0) / 0.25,
                           (s.sim.object.radius / 0.051 - 1.0) / 0.02,
                           (s.joint.viscous / s0.joint.viscous - 1.0) / 0.2};
    for (int i = 0; i < 4; ++i) {
      EXPECT_LE(std::abs(rel[i]), 1.0 + 1e-12) << "quantity " << i << " run " << run;
      lo[i] = std::min(lo[i], rel[i]);
      hi[i] = std::max(hi[i], rel[i]);
    }
    // Viscous and Coulomb friction share one factor.
    EXPECT_NEAR(s.joint.coulomb / s0.joint.coulomb, s.joint.viscous / s0.joint.viscous, 1e-12);
    // The sensor settings are set, not drawn.
    EXPECT_EQ(s.effects.noise_read_dn, 2.0);
    EXPECT_EQ(s.effects.drop_probability, 0.02);
    ASSERT_TRUE(s.camera);
    EXPECT_EQ(s.camera->latency, 0.033);
    EXPECT_EQ(s.camera->latency_jitter, 0.005);
    // What perturb reports is what it did.
    EXPECT_EQ(d.s_h0, s.sim.initial.s_h);
    EXPECT_EQ(d.radius, s.sim.object.radius);
    EXPECT_EQ(d.effects_seed, s.effects.seed);
    // Nothing else moves: the hand, the motion, the camera's pose.
    EXPECT_EQ(s.sim.hand.a, s0.sim.hand.a);
    EXPECT_EQ(s.sim.hand.d, s0.sim.hand.d);
    EXPECT_EQ(s.sim.motion.period, s0.sim.motion.period);
    EXPECT_EQ(s.sim.motion.k, s0.sim.motion.k);
    EXPECT_EQ(s.sim.object.mass, s0.sim.object.mass);
    EXPECT_EQ(s.joint.inertia, s0.joint.inertia);
    EXPECT_EQ(s.camera->fx, s0.camera->fx);
    EXPECT_EQ(s.controller.mode, s0.controller.mode);
  }
  // 400 uniform draws reach within 5 % of both ends (a miss has probability 2 * 0.975^400).
  for (int i = 0; i < 4; ++i) {
    EXPECT_LT(lo[i], -0.95) << "quantity " << i << " never drawn near its lower bound";
    EXPECT_GT(hi[i], 0.95) << "quantity " << i << " never drawn near its upper bound";
  }
}

TEST(MonteCarloPerturb, DeterministicPerSeedAndRunAndDifferentBetweenRuns) {
  const Scene s0 = nominal();
  const drivers::Perturbations p;
  const auto key = [&](std::uint64_t seed, int run) {
    const Scene s = drivers::perturb(s0, p, seed, run);
    return std::vector<double>{s.sim.initial.s_h,   s.sim.tilt,
                               s.sim.object.radius, s.joint.viscous,
                               s.joint.coulomb,     static_cast<double>(s.effects.seed)};
  };
  EXPECT_EQ(key(7, 3), key(7, 3));
  // The same run does not depend on what was drawn before (no shared generator).
  key(7, 2);
  EXPECT_EQ(key(7, 3), key(7, 3));
  std::set<std::vector<double>> distinct;
  std::set<std::uint64_t> seeds;
  for (int run = 0; run < 20; ++run) {
    distinct.insert(key(7, run));
    seeds.insert(drivers::perturb(s0, p, 7, run).effects.seed);
  }
  EXPECT_EQ(distinct.size(), 20u) << "runs share a world";
  EXPECT_EQ(seeds.size(), 20u) << "runs share the camera's noise and drops";
  EXPECT_NE(key(7, 3), key(8, 3)) << "the seed does not matter";
  // Seeds that differ only in their upper 32 bits are different experiments too.
  EXPECT_NE(key(1, 0), key(1 + (std::uint64_t{1} << 32), 0));
}

TEST(MonteCarloPerturb, ZeroHalfWidthsKeepTheNominalWorld) {
  const Scene s0 = nominal();
  drivers::Perturbations p;
  p.s_h = p.tilt_deg = p.radius_rel = p.friction_rel = 0;
  const Scene s = drivers::perturb(s0, p, 1, 5);
  EXPECT_EQ(s.sim.initial.s_h, s0.sim.initial.s_h);
  EXPECT_NEAR(s.sim.tilt, s0.sim.tilt, 1e-15);
  EXPECT_EQ(s.sim.object.radius, s0.sim.object.radius);
  EXPECT_EQ(s.joint.viscous, s0.joint.viscous);
}

TEST(MonteCarloPerturb, RejectsInvalidPerturbations) {
  const Scene s0 = nominal();
  const auto bad = [&](auto edit, const std::string& field) {
    drivers::Perturbations p;
    edit(p);
    try {
      drivers::perturb(s0, p, 1, 0);
      ADD_FAILURE() << field << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("perturbations." + field), std::string::npos)
          << e.what();
    }
  };
  bad([](auto& p) { p.s_h = -0.1; }, "s_h");
  bad([](auto& p) { p.tilt_deg = std::nan(""); }, "tilt_deg");
  bad([](auto& p) { p.radius_rel = 1.0; }, "radius_rel");
  bad([](auto& p) { p.drop = 1.0; }, "drop");
  bad([](auto& p) { p.latency_jitter = 0.05; }, "latency_jitter");  // > latency 0.033
  bad([](auto& p) { p.friction_rel = 1.5; }, "friction_rel");
  Scene no_camera = s0;
  no_camera.camera.reset();
  EXPECT_THROW(drivers::perturb(no_camera, {}, 1, 0), std::invalid_argument);
}

TEST(MonteCarloWilson, MatchesHandComputedIntervals) {
  const double z2 = kZ * kZ;
  // k = 0: the interval is [0, z^2 / (n + z^2)]; k = n mirrors it.
  auto i = drivers::wilson_interval(0, 10);
  EXPECT_NEAR(i.lo, 0.0, 1e-12);
  EXPECT_NEAR(i.hi, z2 / (10 + z2), 1e-12);
  EXPECT_NEAR(i.hi, 0.27753, 1e-5);
  i = drivers::wilson_interval(10, 10);
  EXPECT_NEAR(i.lo, 10 / (10 + z2), 1e-12);
  EXPECT_NEAR(i.lo, 0.72247, 1e-5);
  EXPECT_NEAR(i.hi, 1.0, 1e-12);
  // k = 5 of 10: centred on 1/2, half-width z sqrt(1/40 + z^2/400) / (1 + z^2/10).
  i = drivers::wilson_interval(5, 10);
  const double half = kZ * std::sqrt(0.025 + z2 / 400) / (1 + z2 / 10);
  EXPECT_NEAR(i.lo, 0.5 - half, 1e-12);
  EXPECT_NEAR(i.hi, 0.5 + half, 1e-12);
  EXPECT_NEAR(i.lo, 0.23659, 1e-5);
  EXPECT_NEAR(i.hi, 0.76341, 1e-5);
  // Asymmetric cases, worked out to 5 digits on paper from the same formula.
  i = drivers::wilson_interval(1, 20);
  EXPECT_NEAR(i.lo, 0.00888, 1e-5);
  EXPECT_NEAR(i.hi, 0.23613, 1e-5);
  i = drivers::wilson_interval(17, 20);
  EXPECT_NEAR(i.lo, 0.63958, 1e-5);
  EXPECT_NEAR(i.hi, 0.94763, 1e-5);
  // No trials: no information.
  i = drivers::wilson_interval(0, 0);
  EXPECT_EQ(i.lo, 0.0);
  EXPECT_EQ(i.hi, 1.0);
  EXPECT_THROW(drivers::wilson_interval(3, 2), std::invalid_argument);
}

TEST(MonteCarloRun, RejectsBadArguments) {
  const Scene s0 = nominal();
  EXPECT_THROW(drivers::run_montecarlo(*flatland::model::compile(s0), {}, 0, 1, {"feedback"}),
               std::invalid_argument);
  EXPECT_THROW(drivers::run_montecarlo(*flatland::model::compile(s0), {}, 1, 1, {"closed"}),
               std::invalid_argument);
  EXPECT_THROW(
      drivers::run_montecarlo(*flatland::model::compile(s0), {}, 1, 1, {"feedback", "feedback"}),
      std::invalid_argument);
  EXPECT_THROW(drivers::run_montecarlo(*flatland::model::compile(s0), {}, 1, 1,
                                       std::vector<drivers::MonteCarloController>{}),
               std::invalid_argument);
}

TEST(MonteCarloRun, ResultsDoNotDependOnTheThreadCount) {
  const Scene s0 = nominal();
  const drivers::Perturbations p;
  const std::vector<drivers::MonteCarloController> controllers = {"open-loop", "feedback"};
  // Four worlds (two in the sanitizer stage), each run by both controllers.
  const int runs = flatland::test::short_tests() ? 2 : 4;
  const long records = 2L * runs;
  long calls = 0, last_done = 0, last_total = 0;
  const auto one = drivers::run_montecarlo(*flatland::model::compile(s0), p, runs, 2024,
                                           controllers, 1, [&](long done, long total) {
                                             ++calls;
                                             EXPECT_EQ(done, last_done + 1);
                                             last_done = done;
                                             last_total = total;
                                           });
  EXPECT_EQ(calls, records);
  EXPECT_EQ(last_total, records);
  const auto two =
      drivers::run_montecarlo(*flatland::model::compile(s0), p, runs, 2024, controllers, 2);
  ASSERT_EQ(one.records.size(), static_cast<std::size_t>(records));
  ASSERT_EQ(two.records.size(), static_cast<std::size_t>(records));
  EXPECT_EQ(one.runs, runs);
  int ok_open = 0, ok_feedback = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(records); ++i) {
    const auto& a = one.records[i];
    const auto& b = two.records[i];
    SCOPED_TRACE("record " + std::to_string(i));
    // Ordered by run, then controller, whoever ran it.
    EXPECT_EQ(a.run, static_cast<int>(i / 2));
    EXPECT_EQ(a.controller, controllers[i % 2].name);
    EXPECT_EQ(b.run, a.run);
    EXPECT_EQ(b.controller, a.controller);
    EXPECT_EQ(b.success, a.success);
    EXPECT_EQ(b.failure, a.failure);
    // Bit-identical: the same world, the same noise, the same loop.
    EXPECT_TRUE(b.duration_s == a.duration_s ||
                (std::isnan(a.duration_s) && std::isnan(b.duration_s)));
    EXPECT_EQ(b.s_end, a.s_end);
    EXPECT_EQ(b.fn_min_ratio, a.fn_min_ratio);
    EXPECT_EQ(b.frames, a.frames);
    EXPECT_EQ(b.drawn.effects_seed, a.drawn.effects_seed);
    // Both controllers of a run face the same world.
    if (i % 2) {
      EXPECT_EQ(a.drawn.s_h0, one.records[i - 1].drawn.s_h0);
      EXPECT_EQ(a.drawn.tilt_deg, one.records[i - 1].drawn.tilt_deg);
    }
    if (a.success) (a.controller == "open-loop" ? ok_open : ok_feedback)++;
    EXPECT_EQ(a.success, a.failure.empty());
  }
  // The counts are the records' counts, the same for both thread counts.
  EXPECT_EQ(one.success_open_loop, ok_open);
  EXPECT_EQ(one.success_feedback, ok_feedback);
  EXPECT_EQ(two.success_open_loop, ok_open);
  EXPECT_EQ(two.success_feedback, ok_feedback);
  const auto ci = drivers::wilson_interval(ok_feedback, runs);
  EXPECT_EQ(one.ci_feedback.lo, ci.lo);
  EXPECT_EQ(one.ci_feedback.hi, ci.hi);
}

TEST(MonteCarloRun, OneControllerLeavesTheOtherUncounted) {
  const Scene s0 = nominal();
  const auto r = drivers::run_montecarlo(*flatland::model::compile(s0), {}, 1, 3, {"feedback"}, 1);
  EXPECT_EQ(r.success_open_loop, -1);
  EXPECT_GE(r.success_feedback, 0);
  ASSERT_EQ(r.records.size(), 1u);
  EXPECT_EQ(r.records[0].controller, "feedback");
}

// One world made to fail numerically (a step budget of one step per servo period: its
// integrator gives up in the first period): the study finishes, the world is recorded as
// numerical_failure with the seed and run that rebuild it, its rate leaves it out, and runs.csv
// says so; the other worlds are untouched (the same records as without the fault).
TEST(MonteCarloRun, AWorldThatFailsNumericallyIsRecordedAndTheStudyGoesOn) {
  const Scene s0 = nominal();
  const auto model = flatland::model::compile(s0);
  const int runs = flatland::test::short_tests() ? 2 : 3;
  const drivers::WorldEdit fault = [](Scene& world, int run) {
    if (run == 1) world.sim.run.integrator.max_steps = 1;
  };
  const auto clean = drivers::run_montecarlo(*model, {}, runs, 77, {"open-loop"}, 2);
  const auto r = drivers::run_montecarlo(*model, {}, runs, 77, {"open-loop"}, 2, {}, fault);
  ASSERT_EQ(r.records.size(), static_cast<std::size_t>(runs));
  const drivers::RunRecord& bad = r.records[1];
  EXPECT_EQ(bad.run, 1);
  EXPECT_EQ(bad.seed, 77u);
  EXPECT_EQ(bad.outcome, drivers::Outcome::kNumericalFailure);
  EXPECT_FALSE(bad.success);
  EXPECT_NE(bad.failure.find("step budget"), std::string::npos) << bad.failure;
  EXPECT_EQ(r.numerical_failures_open_loop, 1);
  EXPECT_EQ(clean.numerical_failures_open_loop, 0);
  for (int i = 0; i < runs; ++i) {
    if (i == 1) continue;
    EXPECT_EQ(r.records[i].outcome, clean.records[i].outcome) << "run " << i;
    EXPECT_EQ(r.records[i].s_end, clean.records[i].s_end) << "run " << i;
  }
  int ok = 0;
  for (const auto& rec : r.records) ok += rec.success;
  EXPECT_EQ(r.success_open_loop, ok);
  const auto ci = drivers::wilson_interval(ok, runs - 1);  // over the worlds that did not fail
  EXPECT_EQ(r.ci_open_loop.lo, ci.lo);
  EXPECT_EQ(r.ci_open_loop.hi, ci.hi);
  const std::string csv = drivers::runs_csv(r);
  EXPECT_NE(csv.find(",numerical_failure,"), std::string::npos) << csv;
  // The columns of before keep their places (seed was the last); new ones come after it.
  EXPECT_NE(csv.find(",loss_scale,seed,mu,stop_cause\n"), std::string::npos) << csv;
  // The failed world's mu is the world's contact.mu, drawn: nominal mu times its factor.
  const Scene world = drivers::perturb(s0, {}, 77, 1);
  ASSERT_TRUE(world.sim.contact.mu);
  EXPECT_EQ(bad.mu, *world.sim.contact.mu);
}

// A world the draw makes impossible (here an inertia its body cannot hold, set by an edit as a
// radius draw below the given inertia's would) is recorded with its (seed, run), left out of the
// rates like a numerical failure, and the other worlds are what they are without it.
TEST(MonteCarloRun, AWorldThatCannotExistIsRecordedAndTheStudyGoesOn) {
  const Scene s0 = nominal();
  const auto model = flatland::model::compile(s0);
  const int runs = flatland::test::short_tests() ? 2 : 3;
  const drivers::WorldEdit impossible = [](Scene& world, int run) {
    if (run == 1) {
      const double R = world.sim.object.radius;
      world.sim.object.inertia = 1.01 * world.sim.object.mass * R * R;  // above m R^2
    }
  };
  const auto clean = drivers::run_montecarlo(*model, {}, runs, 77, {"open-loop"}, 2);
  const auto r = drivers::run_montecarlo(*model, {}, runs, 77, {"open-loop"}, 2, {}, impossible);
  ASSERT_EQ(r.records.size(), static_cast<std::size_t>(runs));
  const drivers::RunRecord& bad = r.records[1];
  EXPECT_EQ(bad.outcome, drivers::Outcome::kInvalidWorld);
  EXPECT_FALSE(bad.success);
  EXPECT_NE(bad.failure.find("seed 77, run 1"), std::string::npos) << bad.failure;
  EXPECT_NE(bad.failure.find("object.inertia"), std::string::npos) << bad.failure;
  EXPECT_TRUE(std::isnan(bad.mu));  // never compiled
  ASSERT_EQ(r.summaries.size(), 1u);
  EXPECT_EQ(r.summaries[0].invalid_worlds, 1);
  EXPECT_EQ(r.summaries[0].numerical_failures, 0);
  for (int i = 0; i < runs; ++i) {
    if (i == 1) continue;
    EXPECT_EQ(r.records[i].outcome, clean.records[i].outcome) << "run " << i;
    EXPECT_EQ(r.records[i].s_end, clean.records[i].s_end) << "run " << i;
  }
  int ok = 0;
  for (const auto& rec : r.records) ok += rec.success;
  const auto ci = drivers::wilson_interval(ok, runs - 1);  // over the worlds that could exist
  EXPECT_EQ(r.ci_open_loop.lo, ci.lo);
  EXPECT_EQ(r.ci_open_loop.hi, ci.hi);
  const drivers::ControllerComparison cmp = drivers::compare_controllers(r);
  ASSERT_EQ(cmp.controllers.size(), 1u);
  EXPECT_EQ(cmp.controllers[0].invalid_worlds, 1);
  EXPECT_EQ(cmp.controllers[0].outcomes.at("invalid_world"), 1);
  EXPECT_NE(drivers::runs_csv(r).find(",invalid_world,"), std::string::npos);
}

// A ring is drawn larger or smaller as a whole: its inner radius keeps its ratio to the drawn
// outer one (so a draw never puts the hole outside the ring); a ball's rail gap, the hand's, stays.
TEST(MonteCarloPerturb, ARingKeepsItsProportionsAndTheRailsTheirGap) {
  Scene ring = nominal();
  ring.sim.object.kind = sim::ObjectSpec::Kind::kRing;
  ring.sim.object.inner_radius = 0.05;  // 0.98 of the outer 0.051: a 2 % draw would cross it
  Scene ball = nominal();
  ball.sim.object.kind = sim::ObjectSpec::Kind::kBall;
  ball.sim.object.rail_gap = 0.08;
  drivers::Perturbations p;
  p.radius_rel = 0.05;
  for (int run = 0; run < 50; ++run) {
    const Scene s = drivers::perturb(ring, p, 5, run);
    EXPECT_NEAR(s.sim.object.inner_radius / s.sim.object.radius, 0.05 / 0.051, 1e-15);
    EXPECT_LT(s.sim.object.inner_radius, s.sim.object.radius);
    const Scene b = drivers::perturb(ball, p, 5, run);
    EXPECT_EQ(b.sim.object.radius, s.sim.object.radius);  // the same draw
    EXPECT_EQ(*b.sim.object.rail_gap, 0.08);
  }
}

namespace {

// A record travels from the rank that ran it to rank 0 as bytes (docs/CLUSTER.md): every field
// must come back exactly, or the outputs of an MPI run would differ from one process's.
TEST(MonteCarloRecords, EveryFieldComesBackFromItsBytes) {
  using flatland::drivers::RunRecord;
  std::vector<RunRecord> sent(2);
  RunRecord& r = sent[1];
  r.run = 17;
  r.seed = 0xfedcba9876543210ULL;
  r.controller = "feedback";
  r.success = true;
  r.outcome = flatland::drivers::Outcome::kSafeStop;
  r.failure = "lost the disk\nat 1.2 s";
  r.slide_s = 0.125;
  r.flight_s = 1.0 / 3.0;
  r.impacts = 4;
  r.duration_s = 4.2378;
  r.s_end = 0.9123456789;
  r.fn_min_ratio = -0.0;
  r.mu_max = NAN;
  r.safe_stop = true;
  r.frames = 123456789012L;
  r.frames_lost = 7;
  r.drawn = {0.01, 5.1, 0.0254, 1.05, 99, 0.97, 1.2};
  r.stop_cause = flatland::control::StopCause::kTracking;
  r.mu = 0.4;
  std::string bytes;
  flatland::sim::ByteWriter w(bytes);
  flatland::drivers::records_codec(sent).pack(1, w);

  std::vector<RunRecord> got(2);
  flatland::sim::ByteReader in(bytes);
  flatland::drivers::records_codec(got).unpack(1, in);
  EXPECT_TRUE(in.at_end());
  const RunRecord& g = got[1];
  EXPECT_EQ(g.run, r.run);
  EXPECT_EQ(g.seed, r.seed);
  EXPECT_EQ(g.controller, r.controller);
  EXPECT_EQ(g.success, r.success);
  EXPECT_EQ(g.outcome, r.outcome);
  EXPECT_EQ(g.failure, r.failure);
  EXPECT_EQ(g.slide_s, r.slide_s);
  EXPECT_EQ(g.flight_s, r.flight_s);
  EXPECT_EQ(g.impacts, r.impacts);
  EXPECT_EQ(g.duration_s, r.duration_s);
  EXPECT_EQ(g.s_end, r.s_end);
  EXPECT_TRUE(std::signbit(g.fn_min_ratio));
  EXPECT_TRUE(std::isnan(g.mu_max));
  EXPECT_EQ(g.safe_stop, r.safe_stop);
  EXPECT_EQ(g.frames, r.frames);
  EXPECT_EQ(g.frames_lost, r.frames_lost);
  EXPECT_TRUE(g.drawn == r.drawn);
  EXPECT_EQ(g.stop_cause, r.stop_cause);
  EXPECT_EQ(g.mu, r.mu);
  // Slot 0 was not sent: untouched.
  EXPECT_EQ(got[0].controller, "");
}

}  // namespace
