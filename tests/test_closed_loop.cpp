// The closed loop through the whole synthetic pipeline: simulate -> render -> track -> estimate
// -> control -> joint (paper section 5).
#include "flatland/drivers/experiment.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

using namespace flatland;

namespace {
Scene feedback_scene() { return load_scene(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml"); }
}  // namespace

TEST(ClosedLoop, PaperRunSucceedsWithFeedback) {
  const Scene scene = feedback_scene();
  const drivers::LoopSetup setup(scene);
  std::vector<std::pair<double, double>> zs;
  double sig = 0;
  drivers::SyntheticOptions so;
  so.on_frame = [&](const drivers::CameraFrame& f, const vision::TrackResult&,
                    const std::optional<control::Measurement>& z) {
    if (z) { zs.push_back({f.t_capture, z->s_h}); sig += z->sigma; }
  };
  const drivers::SyntheticResult r = drivers::run_synthetic(setup, scene, so);
  {
    double sum = 0, sum2 = 0;
    int n = 0;
    for (auto [tc, sz] : zs) {
      for (std::size_t i = 0; i + 1 < r.loop.log.size(); ++i)
        if (r.loop.log[i].t <= tc && r.loop.log[i + 1].t > tc) {
          const auto& a = r.loop.log[i];
          const auto& b = r.loop.log[i + 1];
          const double st = a.s_true + (tc - a.t) / (b.t - a.t) * (b.s_true - a.s_true);
          sum += sz - st;
          sum2 += (sz - st) * (sz - st);
          ++n;
          if (n % 10 == 0) std::fprintf(stderr, "tc %.4f err %.2e\n", tc, sz - st);
        }
    }
    std::fprintf(stderr, "meas bias %.3e rms %.3e n %d mean sigma %.3e\n", sum / n, std::sqrt(sum2 / n), n, sig / n);
  }
  std::fprintf(stderr, "success %d failure '%s' duration %.4f s_end %.4f fn_min %.4f mu %.4f frames %ld lost %ld nees %.3f (%ld) t2 %.3f t3 %.3f\n",
               r.success, r.failure.c_str(), r.loop.duration_s, r.s_end, r.fn_min_ratio, r.mu_max,
               r.loop.frames, r.loop.frames_lost, r.nees_mean, r.nees_samples,
               r.loop.t_stage2.value_or(NAN), r.loop.t_stage3.value_or(NAN));
  if (std::FILE* f = std::fopen("/tmp/cl.csv", "w")) {
    for (const auto& row : r.loop.log)
      std::fprintf(f, "%.4f %.5f %.5f %.4f %d %.5f %.5f %.5f %.5f %.5f %.4f %d %.3f\n", row.t, row.theta,
                   row.theta_dot, row.command, (int)row.stage, row.s_est, row.sdot_est, row.s_true,
                   row.sdot_true, row.theta_plan, row.fn_ratio, row.measured, row.nees);
    std::fclose(f);
  }
  EXPECT_TRUE(r.success) << r.failure;
}
