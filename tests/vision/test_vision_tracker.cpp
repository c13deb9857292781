// The disk tracker on rendered butterfly sequences (the paper's air-table experiment at 5 deg,
// 2T = 4 s, 30 Hz camera with exposure blur): centre error against the renderer's exact truth for
// the edge fit, coverage-weighted moments and the HoughCircles baseline; lost/found states.
#include "flatland/render/renderer.hpp"
#include "flatland/sim/spec.hpp"
#include "flatland/vision/tracker.hpp"
#include "render_support.hpp"
#include "scene_support.hpp"

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>
#include <vector>

using namespace flatland;

namespace {

// The FLATLAND experiment: the butterfly at 5 deg tilt, 2T = 4 s (k solves it), the 640 x 480
// overhead camera at 1.2 m, 30 Hz with a full-frame exposure (blur over 8 sub-frames).
Scene experiment_scene(double noise_dn, bool blur) {
  return flatland_test::air_table_experiment(noise_dn, blur, 7);
}

struct Sequence {
  std::vector<render::Frame> frames;
  camera::CameraModel camera;
};

// Every 30 Hz frame of the 4 s run (121 frames), rendered once per configuration.
const Sequence& sequence(double noise_dn, bool blur) {
  static std::map<std::pair<double, bool>, Sequence> cache;
  auto it = cache.find({noise_dn, blur});
  if (it != cache.end()) return it->second;
  const Scene scene = experiment_scene(noise_dn, blur);
  sim::SimulationSpec spec = scene.sim;
  spec.run.record = true;
  const sim::RunResult run = sim::run_spec(spec);
  render::Renderer renderer(flatland_test::render_setup(scene));
  Sequence seq;
  seq.camera = renderer.camera();
  const double t_end = run.trajectory.t_end();
  for (int k = 0; k / 30.0 <= t_end + 1e-9; ++k)
    seq.frames.push_back(renderer.capture(run.trajectory, std::min(k / 30.0, t_end)));
  return cache.emplace(std::make_pair(noise_dn, blur), std::move(seq)).first->second;
}

struct RunStats {
  double rms = 0, max = 0;
  int lost = 0, frames = 0;
  double mean_sigma = 0, mean_quality = 0;
};

RunStats run_tracker(const Sequence& seq, vision::TrackMethod method,
                     double second_pass_shift_px = 0) {
  vision::TrackerConfig cfg;
  cfg.method = method;
  cfg.second_pass_shift_px = second_pass_shift_px;
  vision::Tracker tracker(cfg);
  RunStats st;
  double sum2 = 0;
  for (const render::Frame& f : seq.frames) {
    const vision::TrackResult r = tracker.track(f.image);
    ++st.frames;
    if (!r.ok()) {
      ++st.lost;
      continue;
    }
    const double e = cv::norm(r.center - f.truth.disk_center_px);
    sum2 += e * e;
    st.max = std::max(st.max, e);
    st.mean_sigma += r.sigma_px;
    st.mean_quality += r.quality;
  }
  const int found = st.frames - st.lost;
  st.rms = found > 0 ? std::sqrt(sum2 / found) : NAN;
  st.mean_sigma /= std::max(1, found);
  st.mean_quality /= std::max(1, found);
  return st;
}

void print(const char* what, vision::TrackMethod m, const RunStats& s) {
  std::printf(
      "[ vision   ] %-28s %-8s rms %.4f px  max %.4f px  lost %d/%d  sigma %.4f px  "
      "quality %.3f\n",
      what, vision::to_string(m).c_str(), s.rms, s.max, s.lost, s.frames, s.mean_sigma,
      s.mean_quality);
}

}  // namespace

// Acceptance: noise sigma = 2 DN with 30 Hz exposure blur, RMS <= 0.1 px and no lost frame; the
// baselines measured on the same frames.
TEST(VisionTracker, NoisyBlurredSequenceAccuracy) {
  const Sequence& seq = sequence(2.0, true);
  ASSERT_GE(seq.frames.size(), 120u);
  const RunStats edge = run_tracker(seq, vision::TrackMethod::kEdge);
  const RunStats moments = run_tracker(seq, vision::TrackMethod::kMoments);
  const RunStats hough = run_tracker(seq, vision::TrackMethod::kHough);
  print("noise 2 DN + blur", vision::TrackMethod::kEdge, edge);
  print("noise 2 DN + blur", vision::TrackMethod::kMoments, moments);
  print("noise 2 DN + blur", vision::TrackMethod::kHough, hough);
  EXPECT_EQ(edge.lost, 0);
  EXPECT_LE(edge.rms, 0.1);
  // The reported uncertainty is of the size of the actual error (not wildly optimistic).
  EXPECT_GT(edge.mean_sigma, 0.0);
  EXPECT_GT(edge.mean_quality, 0.5);
  // Sanity only for the baseline: it should at least find the disk within a few px.
  EXPECT_LT(hough.rms, 5.0);
}

// Acceptance: without noise (blur kept), RMS <= 0.02 px.
TEST(VisionTracker, NoiseFreeSequenceAccuracy) {
  const Sequence& seq = sequence(0.0, true);
  const RunStats edge = run_tracker(seq, vision::TrackMethod::kEdge);
  const RunStats moments = run_tracker(seq, vision::TrackMethod::kMoments);
  const RunStats hough = run_tracker(seq, vision::TrackMethod::kHough);
  print("no noise + blur", vision::TrackMethod::kEdge, edge);
  print("no noise + blur", vision::TrackMethod::kMoments, moments);
  print("no noise + blur", vision::TrackMethod::kHough, hough);
  EXPECT_EQ(edge.lost, 0);
  EXPECT_LE(edge.rms, 0.02);
  // And without blur: the sharpest edge, the systematic floor of each method.
  const Sequence& sharp = sequence(0.0, false);
  const RunStats edge_sharp = run_tracker(sharp, vision::TrackMethod::kEdge);
  print("no noise, no blur", vision::TrackMethod::kEdge, edge_sharp);
  print("no noise, no blur", vision::TrackMethod::kMoments,
        run_tracker(sharp, vision::TrackMethod::kMoments));
  print("no noise, no blur", vision::TrackMethod::kHough,
        run_tracker(sharp, vision::TrackMethod::kHough));
  EXPECT_EQ(edge_sharp.lost, 0);
  EXPECT_LE(edge_sharp.rms, 0.02);
}

// A frame without the disk is "lost"; the next frame with it is re-acquired ("found") from the
// whole frame and then tracked.
TEST(VisionTracker, LostAndReacquired) {
  // Only the few frames this test needs (ctest runs each test in its own process).
  const Scene scene = experiment_scene(2.0, true);
  sim::SimulationSpec spec = scene.sim;
  spec.run.record = true;
  const sim::RunResult run = sim::run_spec(spec);
  render::Renderer renderer(flatland_test::render_setup(scene));
  std::map<int, render::Frame> frames;
  for (int k : {10, 11, 60, 61}) frames[k] = renderer.capture(run.trajectory, k / 30.0);
  render::SceneState away;
  away.hand_angle = 0.3;
  away.disk_center = {3.0, 3.0};  // far outside the view: only the table and the hand
  const cv::Mat empty = renderer.render_8u(away);

  vision::Tracker tracker;
  const render::Frame& a = frames[10];
  const render::Frame& b = frames[60];
  const render::Frame& c = frames[61];
  vision::TrackResult r = tracker.track(a.image);
  EXPECT_EQ(r.state, vision::TrackState::kFound);
  r = tracker.track(frames[11].image);
  EXPECT_EQ(r.state, vision::TrackState::kTracking);
  r = tracker.track(empty);
  EXPECT_EQ(r.state, vision::TrackState::kLost);
  EXPECT_EQ(r.quality, 0.0);
  r = tracker.track(empty);
  EXPECT_EQ(r.state, vision::TrackState::kLost);
  // Re-acquired far from where it was lost.
  r = tracker.track(b.image);
  ASSERT_EQ(r.state, vision::TrackState::kFound);
  EXPECT_LT(cv::norm(r.center - b.truth.disk_center_px), 0.2);
  r = tracker.track(c.image);
  ASSERT_EQ(r.state, vision::TrackState::kTracking);
  EXPECT_LT(cv::norm(r.center - c.truth.disk_center_px), 0.2);
  // A jump the ROI cannot follow (frame 10 after frame 61) falls back to whole-frame search in
  // the same frame.
  r = tracker.track(a.image);
  ASSERT_TRUE(r.ok());
  EXPECT_LT(cv::norm(r.center - a.truth.disk_center_px), 0.2);
  // Gray and float frames are accepted too.
  cv::Mat gray;
  cv::cvtColor(a.image, gray, cv::COLOR_BGR2GRAY);
  vision::Tracker t2;
  r = t2.track(gray);
  ASSERT_TRUE(r.ok());
  EXPECT_LT(cv::norm(r.center - a.truth.disk_center_px), 0.2);
  // A blank frame is lost, not an error; an empty one is bad input.
  EXPECT_EQ(t2.track(cv::Mat(480, 640, CV_8UC3, cv::Scalar::all(50))).state,
            vision::TrackState::kLost);
  EXPECT_THROW(t2.track(cv::Mat()), std::invalid_argument);
}

// The time-stamp correction over a frame that never reached the tracker: skip() steps the
// prediction over it (the next frame is still tracked in its window) and restarts the
// acceleration, so the two frames after the gap are left as the image shows them and the third
// is corrected by the second difference of the three centres after the gap (computed here from
// an uncorrected tracker's centres on the same frames), not by one that spans the gap.
TEST(VisionTracker, SkippedFrameRestartsTheTimeStampCorrection) {
  const Scene scene = experiment_scene(0.0, false);
  sim::SimulationSpec spec = scene.sim;
  spec.run.record = true;
  const sim::RunResult run = sim::run_spec(spec);
  render::Renderer renderer(flatland_test::render_setup(scene));
  vision::TrackerConfig with_variance;
  with_variance.image_time_variance_frames2 = 0.1;
  vision::Tracker plain, corrected(with_variance);
  std::map<int, vision::TrackResult> p, c;
  for (int k = 55; k <= 63; ++k) {
    if (k == 59) {  // the dropped frame
      plain.skip();
      corrected.skip();
      continue;
    }
    const cv::Mat image = renderer.capture(run.trajectory, k / 30.0).image;
    p[k] = plain.track(image);
    c[k] = corrected.track(image);
    ASSERT_TRUE(p[k].ok() && c[k].ok()) << k;
  }
  const auto expect_correction = [&](int k, int k1, int k2) {
    const cv::Point2d a = p[k].center - 2 * p[k1].center + p[k2].center;
    const cv::Point2d d = c[k].center - p[k].center;
    EXPECT_NEAR(d.x, -0.05 * a.x, 1e-9) << k;
    EXPECT_NEAR(d.y, -0.05 * a.y, 1e-9) << k;
  };
  expect_correction(57, 56, 55);  // before the gap: the last three centres
  expect_correction(58, 57, 56);
  EXPECT_EQ(p[60].state, vision::TrackState::kTracking);  // the prediction stepped over frame 59
  for (int k : {60, 61}) {
    EXPECT_EQ(c[k].center, p[k].center) << k;
    EXPECT_EQ(c[k].sigma_px, p[k].sigma_px) << k;
  }
  expect_correction(62, 61, 60);
  EXPECT_EQ(c[62].sigma_px, p[62].sigma_px);  // no acceleration before it to have changed from
  expect_correction(63, 62, 61);
  // A curve is there to correct: the second differences are not zero.
  EXPECT_GT(cv::norm(p[62].center - 2 * p[61].center + p[60].center), 1e-3);
}

TEST(VisionTracker, MethodNames) {
  EXPECT_EQ(vision::parse_track_method("edge"), vision::TrackMethod::kEdge);
  EXPECT_EQ(vision::parse_track_method("moments"), vision::TrackMethod::kMoments);
  EXPECT_EQ(vision::parse_track_method("hough"), vision::TrackMethod::kHough);
  EXPECT_EQ(vision::parse_track_method("contour"), vision::TrackMethod::kContour);
  EXPECT_EQ(vision::to_string(vision::TrackMethod::kContour), "contour");
  EXPECT_THROW(vision::parse_track_method("sift"), std::invalid_argument);
  EXPECT_EQ(vision::to_string(vision::TrackState::kTracking), "tracking");
}

// An oblique camera (1.0 m up, 0.5 m off to the side) with strong barrel distortion: the image of
// the edge circle is not a circle and its centre is not the image of the disk's centre. With the
// camera known, the fit on the table plane removes that bias; the plain pixel fit is measured
// alongside.
TEST(VisionTracker, ObliqueCameraPlaneFit) {
  Scene s = experiment_scene(0.0, false);
  s.camera->position = {0.3, -0.4, 1.0};
  s.camera->distortion = {-0.25, 0.08, 0, 0, 0};
  sim::SimulationSpec spec = s.sim;
  spec.run.record = true;
  const sim::RunResult run = sim::run_spec(spec);
  render::Renderer renderer(flatland_test::render_setup(s));
  Sequence seq;
  seq.camera = renderer.camera();
  for (int k = 0; k <= 120; k += 4)
    seq.frames.push_back(
        renderer.capture(run.trajectory, std::min(k / 30.0, run.trajectory.t_end())));
  const RunStats pixel = run_tracker(seq, vision::TrackMethod::kEdge);
  vision::TrackerConfig cfg;
  cfg.camera = seq.camera;
  cfg.plane_z = s.render.disk_thickness;
  vision::Tracker tracker(cfg);
  double sum2 = 0;
  int lost = 0;
  for (const render::Frame& f : seq.frames) {
    const vision::TrackResult r = tracker.track(f.image);
    if (!r.ok()) {
      ++lost;
      continue;
    }
    const double e = cv::norm(r.center - f.truth.disk_center_px);
    sum2 += e * e;
  }
  const double plane_rms = std::sqrt(sum2 / std::max<std::size_t>(1, seq.frames.size() - lost));
  std::printf(
      "[ vision   ] oblique camera: pixel circle fit rms %.4f px, table-plane fit rms %.4f "
      "px (%zu frames)\n",
      pixel.rms, plane_rms, seq.frames.size());
  EXPECT_EQ(lost, 0);
  EXPECT_EQ(pixel.lost, 0);
  EXPECT_LE(plane_rms, 0.1);
  EXPECT_LT(plane_rms, pixel.rms);
}

// Whole-frame re-acquisition searches a grey copy four times smaller and then fits the edge at
// full resolution in a window about the blob. On every other frame of the noisy, blurred run it
// must be as accurate as the edge fit run on the whole frame's full-resolution float grey from the
// true centre with both passes (an independent path: no blob search, no window, no 8-bit grey).
TEST(VisionTracker, DownsampledReacquisitionMatchesFullResolution) {
  const Sequence& seq = sequence(2.0, true);
  vision::TrackerConfig two_passes;
  two_passes.second_pass_shift_px = 0;
  double sum2_found = 0, sum2_full = 0, worst_blob = 0;
  int n = 0;
  for (std::size_t k = 0; k < seq.frames.size(); k += 2) {
    const render::Frame& f = seq.frames[k];
    const cv::Point2d truth = f.truth.disk_center_px;
    const vision::TrackResult blob = vision::acquire(f.image, 0);
    ASSERT_TRUE(blob.ok()) << "frame " << k;
    worst_blob = std::max(worst_blob, cv::norm(blob.center - truth));
    vision::Tracker tracker;  // a fresh tracker: the frame is searched whole
    const vision::TrackResult found = tracker.track(f.image);
    ASSERT_EQ(found.state, vision::TrackState::kFound) << "frame " << k;
    const vision::TrackResult full =
        vision::refine_edge(vision::to_gray_f32(f.image), truth, found.radius_px, two_passes);
    ASSERT_TRUE(full.ok()) << "frame " << k;
    sum2_found += std::pow(cv::norm(found.center - truth), 2);
    sum2_full += std::pow(cv::norm(full.center - truth), 2);
    ++n;
  }
  const double rms_found = std::sqrt(sum2_found / n), rms_full = std::sqrt(sum2_full / n);
  std::printf(
      "[ vision   ] re-acquisition on %d frames: downsampled + window rms %.4f px, full "
      "resolution from the truth rms %.4f px, blob centre within %.2f px\n",
      n, rms_found, rms_full, worst_blob);
  // The blob is found on a grid of 4 px pixels: within one of them.
  EXPECT_LT(worst_blob, 4.0);
  EXPECT_LE(rms_found, rms_full + 0.002);
  EXPECT_LE(rms_found, 0.02);
}

// The edge fit reads an 8-bit frame's grey window as 8-bit: the same samples as its float copy,
// so the same fit to the last bit.
TEST(VisionTracker, EightBitWindowEqualsItsFloatCopy) {
  const Sequence& seq = sequence(2.0, true);
  const render::Frame& f = seq.frames[60];
  const cv::Mat u8 = vision::to_gray_for_edge(f.image);
  ASSERT_EQ(u8.type(), CV_8UC1);
  cv::Mat f32;
  u8.convertTo(f32, CV_32F);
  const vision::TrackerConfig cfg;
  const cv::Point2d guess = f.truth.disk_center_px + cv::Point2d(0.7, -0.4);
  const vision::TrackResult a = vision::refine_edge(u8, guess, 35, cfg);
  const vision::TrackResult b = vision::refine_edge(f32, guess, 35, cfg);
  ASSERT_TRUE(a.ok());
  EXPECT_EQ(a.center.x, b.center.x);
  EXPECT_EQ(a.center.y, b.center.y);
  EXPECT_EQ(a.sigma_px, b.sigma_px);
  EXPECT_EQ(a.edge_points, b.edge_points);
}

// One refinement pass from a close guess (second_pass_shift_px 1 px) against two passes on every
// frame (the default): the second pass may gain a little, never more than a few thousandths of a
// pixel, and both keep every frame.
TEST(VisionTracker, OnePassFromACloseGuessSuffices) {
  const Sequence& seq = sequence(2.0, true);
  const RunStats one = run_tracker(seq, vision::TrackMethod::kEdge, 1.0);
  vision::TrackerConfig cfg;
  ASSERT_EQ(cfg.second_pass_shift_px, 0.0) << "two passes are the default";
  vision::Tracker tracker(cfg);
  double sum2 = 0;
  int lost = 0;
  for (const render::Frame& f : seq.frames) {
    const vision::TrackResult r = tracker.track(f.image);
    if (!r.ok()) {
      ++lost;
      continue;
    }
    sum2 += std::pow(cv::norm(r.center - f.truth.disk_center_px), 2);
  }
  const double two_rms = std::sqrt(sum2 / static_cast<double>(seq.frames.size() - lost));
  std::printf("[ vision   ] one pass rms %.4f px, two passes rms %.4f px\n", one.rms, two_rms);
  EXPECT_EQ(one.lost, 0);
  EXPECT_EQ(lost, 0);
  EXPECT_LE(one.rms, two_rms + 0.003);
}

// A disk near the image's border: its window is clipped by the frame and the rays that leave the
// frame are dropped; re-acquisition and tracking still find it against the projected truth. A
// frame without the disk is refused by every method, the contour peer included.
TEST(VisionTracker, DiskNearTheBorderAndNoDisk) {
  const Scene scene = experiment_scene(2.0, false);
  render::Renderer renderer(flatland_test::render_setup(scene));
  const camera::CameraModel& cam = renderer.camera();
  const double z = scene.render.disk_thickness;
  // Metres per pixel at the table, from the camera's own projection.
  const cv::Point2d p0 = cam.project(cv::Point3d(0, 0, z));
  const double px_per_m = cv::norm(cam.project(cv::Point3d(0.01, 0, z)) - p0) / 0.01;
  const double rim_px = scene.sim.object.radius * px_per_m;
  for (const cv::Point2d& offset_px :
       {cv::Point2d(320 - rim_px - 3, 0), cv::Point2d(0, -(240 - rim_px - 3)),
        cv::Point2d(-(320 - rim_px - 1.5), 240 - rim_px - 1.5)}) {
    render::SceneState state;
    state.hand_angle = 0.3;
    // The table's x and y as the image's u and v (overhead camera): found by projection below.
    state.disk_center = {offset_px.x / px_per_m, offset_px.y / px_per_m};
    const cv::Point2d truth = cam.project(cv::Point3d(state.disk_center.x, state.disk_center.y, z));
    const double margin = std::min({truth.x, truth.y, 639 - truth.x, 479 - truth.y});
    ASSERT_LT(margin, rim_px + 4) << "the disk is not near a border";
    ASSERT_GT(margin, rim_px) << "the disk leaves the image";
    const cv::Mat image = renderer.render_8u(state);
    for (const vision::TrackMethod m :
         {vision::TrackMethod::kEdge, vision::TrackMethod::kContour}) {
      vision::TrackerConfig cfg;
      cfg.method = m;
      vision::Tracker tracker(cfg);
      vision::TrackResult r = tracker.track(image);
      ASSERT_EQ(r.state, vision::TrackState::kFound) << vision::to_string(m) << " at " << truth;
      EXPECT_LT(cv::norm(r.center - truth), 0.1) << vision::to_string(m) << " at " << truth;
      r = tracker.track(image);
      ASSERT_EQ(r.state, vision::TrackState::kTracking) << vision::to_string(m);
      EXPECT_LT(cv::norm(r.center - truth), 0.1) << vision::to_string(m) << " at " << truth;
    }
  }
  render::SceneState away;
  away.hand_angle = 0.3;
  away.disk_center = {3.0, 3.0};  // far outside the view: only the table and the hand
  const cv::Mat empty = renderer.render_8u(away);
  EXPECT_FALSE(vision::acquire(empty, 0).ok());
  EXPECT_FALSE(vision::acquire(empty, 35).ok());
  for (const vision::TrackMethod m : {vision::TrackMethod::kEdge, vision::TrackMethod::kMoments,
                                      vision::TrackMethod::kHough, vision::TrackMethod::kContour}) {
    vision::TrackerConfig cfg;
    cfg.method = m;
    vision::Tracker tracker(cfg);
    EXPECT_EQ(tracker.track(empty).state, vision::TrackState::kLost) << vision::to_string(m);
  }
}

// The contour peer on the run's frames: it keeps every frame, to a few hundredths of a pixel (its
// outline is the blob's boundary pixels); the edge fit is measured alongside on the same frames.
TEST(VisionTracker, ContourPeerOnTheRun) {
  const Sequence& seq = sequence(2.0, true);
  const RunStats contour = run_tracker(seq, vision::TrackMethod::kContour);
  const RunStats edge = run_tracker(seq, vision::TrackMethod::kEdge);
  print("noise 2 DN + blur", vision::TrackMethod::kContour, contour);
  EXPECT_EQ(contour.lost, 0);
  EXPECT_LT(contour.rms, 0.2);
  EXPECT_LE(edge.rms, contour.rms);
}
