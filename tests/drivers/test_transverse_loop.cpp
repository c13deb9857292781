// The transverse-linearisation controller in the whole synthetic loop (simulate -> render ->
// track -> estimate -> control -> joint) on the paper's default experiment scene, chosen by name
// (controller.type: transverse) as a user's scene would.
#include "flatland/drivers/experiment.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

using namespace flatland;

namespace {

Scene transverse_scene() {
  Scene scene = load_scene(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml");
  scene.controller.type = "transverse";
  return scene;
}

}  // namespace

// The paper's run (air table at 5 deg, its losses, 30 Hz camera with one frame of latency):
// the transverse law carries the disk to the back well, with the hand on the plan indexed by the
// disk's phase all through stage 2.
TEST(TransverseLoop, PapersRunSucceeds) {
  const Scene scene = transverse_scene();
  const auto model = model::compile(scene);
  ASSERT_EQ(model->controller.type, "transverse");
  const drivers::LoopSetup setup(model);
  const drivers::SyntheticResult r = drivers::run_synthetic(setup, model);
  EXPECT_EQ(r.loop.controller, "transverse");
  ASSERT_TRUE(r.success) << r.failure;
  EXPECT_FALSE(r.loop.safe_stop);
  EXPECT_TRUE(r.loop.finished);
  EXPECT_GT(r.fn_min_ratio, 0.0);
  EXPECT_LE(r.mu_max, *scene.sim.contact.mu);
  ASSERT_TRUE(r.loop.t_stage2 && r.loop.t_stage3);
  // Stage 2 ran the transverse law: in it the hand stays near the plan at the disk's phase (the
  // logged reference), well inside the joint's glitch bound.
  double worst = 0;
  long servo_ticks = 0;
  for (const drivers::TickLog& row : r.loop.log)
    if (row.mode == "servo") {
      ++servo_ticks;
      worst = std::max(worst, std::abs(row.theta - row.theta_plan));
    }
  EXPECT_GT(servo_ticks, 1000);
  EXPECT_LT(worst, 0.05);
  std::fprintf(stderr,
               "[ transverse loop ] duration %.3f s, stage 2 %.3f..%.3f s, |theta - theta_plan| "
               "<= %.4f rad in stage 2, fn_min %.4f mg, mu_max %.3f, s_end %.4f\n",
               r.loop.duration_s, *r.loop.t_stage2, *r.loop.t_stage3, worst, r.fn_min_ratio,
               r.mu_max, r.s_end);
}
