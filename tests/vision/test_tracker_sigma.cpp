// Is the edge tracker right about its own error? Over 240 frames of the FLATLAND run per
// condition (a lamp with highlights and shadows or the plain light; sharp, smeared by 1.5 px of
// exposure, interlaced or rolling; 0-8 DN of read noise) the error of each centre against the
// renderer's exact truth, divided by the sigma the tracker reports for that frame, must look like
// what a right sigma gives. sigma is per coordinate, so for a right sigma |error| / sigma is
// Rayleigh distributed: median sqrt(2 ln 2) = 1.18, exp(-4.5) = 1.1 % beyond 3. Accepted (issue
// 27): the median within [0.5, 1.5], at most 2 % beyond 3 sigma, and RMS <= 0.05 px on the lit
// frames without blur. The smeared and interlaced frames' tracker knows the variance of the times
// its images average (TrackerConfig::image_time_variance_frames2), as the scene's camera gives it.
//
// Not yet met, so not asserted (docs/ACCURACY.md, "Is each frame's sigma right?"): the lamp's
// smeared frames (4.6 % beyond 3 sigma) and rolling-shutter frames (2.9 %). The area refinement
// of the edge points counts the lit O-ring's shading beside the edge as the face's, unevenly round
// the rim, which moves the centre by about 0.018 px without a sign in the residuals.
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/spec.hpp"
#include "flatland/vision/tracker.hpp"
#include "render_support.hpp"
#include "scene_support.hpp"
#include "test_scale.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

using namespace flatland;

namespace {

constexpr int kFullFrames = 240;
// The sanitizer stage tracks a quarter of them, at one noise level, for the code paths.
int frame_count() { return flatland::test::short_tests() ? kFullFrames / 4 : kFullFrames; }

enum class Readout { kSharp, kSmear, kInterlaced, kRolling };

const char* name_of(Readout r) {
  switch (r) {
    case Readout::kSharp:
      return "sharp";
    case Readout::kSmear:
      return "smeared";
    case Readout::kInterlaced:
      return "interlaced";
    case Readout::kRolling:
      return "rolling";
  }
  return "?";
}

struct Run {
  sim::RunResult run;
  Scene scene;
};

const Run& butterfly_run() {
  static const Run r = [] {
    Run out;
    out.scene = flatland_test::air_table_experiment(0.0, false, 7);
    sim::SimulationSpec spec = out.scene.sim;
    spec.run.record = true;
    out.run = sim::run_spec(spec);
    return out;
  }();
  return r;
}

// The exposure that smears the disk's centre by `px` at the run's median speed (from the truth:
// the camera's projection of the centre 1 ms either side of each frame's time).
double exposure_for_smear(const camera::CameraModel& cam, const sim::Trajectory& tr, double z,
                          double px) {
  std::vector<double> speed;  // px/s
  const double dt = 1e-3;
  for (int k = 0; k < kFullFrames; ++k) {
    const double t = tr.t_begin() + (k + 0.5) * (tr.t_end() - tr.t_begin()) / kFullFrames;
    const double a = std::max(tr.t_begin(), t - dt), b = std::min(tr.t_end(), t + dt);
    const auto ca = tr.sample(a).object_position, cb = tr.sample(b).object_position;
    const cv::Point2d pa = cam.project(cv::Point3d(ca.x(), ca.y(), z));
    const cv::Point2d pb = cam.project(cv::Point3d(cb.x(), cb.y(), z));
    speed.push_back(cv::norm(pb - pa) / (b - a));
  }
  std::nth_element(speed.begin(), speed.begin() + kFullFrames / 2, speed.end());
  return px / speed[kFullFrames / 2];
}

struct Frames {
  std::vector<render::Frame> frames;
  /// The variance of the times each image averages, in the frames' intervals squared (what
  /// TrackerConfig::image_time_variance_frames2 takes).
  double time_variance = 0;
};

// frame_count() float frames of the run, evenly over it, at the readout's settings.
Frames frames_of(bool lit, Readout readout) {
  const Run& r = butterfly_run();
  const sim::Trajectory& tr = r.run.trajectory;
  Scene s = r.scene;
  s.effects.quantize = false;
  if (lit) s.lighting = LightingSpec{};
  CameraSpec& cam = *s.camera;
  // The readouts' later rows are rendered after t: keep them within the run.
  const double span = tr.t_end() - tr.t_begin() - 1.0 / cam.fps;
  const int count = frame_count();
  const double interval = span / count;
  Frames out;
  switch (readout) {
    case Readout::kSharp:
      break;
    case Readout::kSmear: {
      const camera::CameraModel model = render::Renderer(flatland_test::render_setup(s)).camera();
      cam.exposure =
          std::min(1.0 / cam.fps, exposure_for_smear(model, tr, s.render.disk_thickness, 1.5));
      s.effects.blur_subframes = 4;
      out.time_variance = std::pow(cam.exposure / interval, 2) / 12;
      break;
    }
    case Readout::kInterlaced:
      cam.readout.mode = "interlaced";
      out.time_variance = std::pow(0.25 / cam.fps / interval, 2);
      break;
    case Readout::kRolling:
      cam.readout.mode = "rolling";
      cam.readout.time = 0.8 / cam.fps;
      cam.readout.band_rows = 8;
      break;
  }
  render::Renderer renderer(flatland_test::render_setup(s));
  for (int k = 0; k < count; ++k)
    out.frames.push_back(renderer.capture(tr, tr.t_begin() + (k + 0.5) * interval));
  return out;
}

struct Honesty {
  double median_z = 0, beyond_3 = 0, rms_px = 0, median_sigma = 0;
  int tracked = 0;
};

Honesty honesty(const Frames& frames, double noise_dn, std::uint64_t seed) {
  vision::TrackerConfig config;
  config.image_time_variance_frames2 = frames.time_variance;
  vision::Tracker tracker(config);
  render::EffectsRng rng(seed);
  std::vector<double> z, sigma;
  double sum2 = 0;
  Honesty h;
  for (const render::Frame& f : frames.frames) {
    cv::Mat noisy = f.image.clone();
    render::apply_noise(noisy, noise_dn, 0, rng);
    const vision::TrackResult r = tracker.track(render::quantize(noisy));
    if (!r.ok()) continue;
    const double e = cv::norm(r.center - f.truth.disk_center_px);
    z.push_back(e / r.sigma_px);
    sigma.push_back(r.sigma_px);
    sum2 += e * e;
  }
  h.tracked = static_cast<int>(z.size());
  if (z.empty()) return h;
  h.rms_px = std::sqrt(sum2 / static_cast<double>(z.size()));
  h.beyond_3 =
      static_cast<double>(std::count_if(z.begin(), z.end(), [](double v) { return v > 3; })) /
      static_cast<double>(z.size());
  std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
  h.median_z = z[z.size() / 2];
  std::nth_element(sigma.begin(), sigma.begin() + sigma.size() / 2, sigma.end());
  h.median_sigma = sigma[sigma.size() / 2];
  return h;
}

void expect_honest(bool lit, Readout readout, const std::vector<double>& noises) {
  // The sanitizer stage runs the code paths once (the lamp's sharp frames), not the statistics
  // of every condition.
  const bool short_run = flatland::test::short_tests();
  if (short_run && !(lit && readout == Readout::kSharp))
    GTEST_SKIP() << "the statistics of every condition: Release only";
  const Frames frames = frames_of(lit, readout);
  for (const double noise : short_run ? std::vector<double>{noises.back()} : noises) {
    const Honesty h = honesty(frames, noise, 11);
    std::printf(
        "[ sigma    ] %-5s %-10s %2.0f DN: rms %.4f px, sigma median %.4f px, |e|/sigma median "
        "%.2f, beyond 3 sigma %.1f %%\n",
        lit ? "lit" : "plain", name_of(readout), noise, h.rms_px, h.median_sigma, h.median_z,
        100 * h.beyond_3);
    SCOPED_TRACE(std::string(lit ? "lit " : "plain ") + name_of(readout) + ", " +
                 std::to_string(noise) + " DN");
    EXPECT_EQ(h.tracked, frame_count());
    if (short_run) continue;
    EXPECT_GE(h.median_z, 0.5);
    EXPECT_LE(h.median_z, 1.5);
    EXPECT_LE(h.beyond_3, 0.02);
    if (readout == Readout::kSharp) {
      EXPECT_LE(h.rms_px, 0.05);
    }
  }
}

}  // namespace

TEST(TrackerSigma, IsRightOnLitSharpFrames) { expect_honest(true, Readout::kSharp, {0, 2, 8}); }
TEST(TrackerSigma, IsRightOnLitInterlacedFrames) { expect_honest(true, Readout::kInterlaced, {2}); }
TEST(TrackerSigma, IsRightOnPlainSharpFrames) { expect_honest(false, Readout::kSharp, {0, 2, 8}); }
TEST(TrackerSigma, IsRightOnPlainSmearedFrames) { expect_honest(false, Readout::kSmear, {2}); }
TEST(TrackerSigma, IsRightOnPlainInterlacedFrames) {
  expect_honest(false, Readout::kInterlaced, {2});
}
TEST(TrackerSigma, IsRightOnPlainRollingShutterFrames) {
  expect_honest(false, Readout::kRolling, {2});
}
