// Tracker latency per 640 x 480 frame (docs/VISION.md): following the disk in its region of
// interest, and whole-frame re-acquisition, for each method, on one rendered frame of the
// air-table butterfly (noise 2 DN, 30 Hz exposure blur). Medians over repetitions are reported.
// The edge fit against its peer, the OpenCV contour tracker (TrackMethod::kContour: Otsu,
// findContours, fitEllipse), is timed interleaved on the same 31 consecutive frames in the same
// run and reported as the ratio flatland / contour (docs/BENCHMARKS.md).
// Run: build/bin/flatland_vision_bench
#include <benchmark/benchmark.h>
#include "flatland/model/compile.hpp"

#include "flatland/model/model.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/render/video_writer.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"
#include "flatland/vision/video_reader.hpp"

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <filesystem>
#include <numbers>
#include <vector>

using namespace flatland;

namespace {

// The air-table experiment's scene: the butterfly at 5 deg, 2T = 4 s, the 640 x 480 overhead
// camera with a 1/30 s exposure, supersample 2, 2 DN read noise.
Scene bench_scene() {
  Scene s;
  s.sim.tilt = 5.0 * std::numbers::pi / 180.0;
  s.sim.motion.period = 4.0;
  s.sim.motion.k = -1.1395840;
  s.sim.duration = 4.0;
  s.sim.run.record = true;
  CameraSpec cam;
  cam.fx = cam.fy = 900;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.position = {0.0, 0.0, 1.2};
  cam.look_at = {0.0, 0.0, 0.0};
  cam.exposure = 1.0 / 30.0;
  s.camera = cam;
  s.effects.supersample = 2;
  s.effects.blur_subframes = 8;
  s.effects.noise_read_dn = 2;
  return s;
}

// Mid-roll (t = 2 s: the disk near the fingertip, the hand touching it, moving fast).
const cv::Mat& frame() {
  static const cv::Mat image = [] {
    const Scene s = bench_scene();
    const sim::RunResult run = sim::run_spec(s.sim);
    render::Renderer renderer(flatland::model::render_setup(*flatland::model::compile(s)));
    return renderer.capture(run.trajectory, 2.0).image;
  }();
  return image;
}

// 31 consecutive 30 Hz frames, t = 1.5 .. 2.5 s (the disk rolling over the fingertip).
const std::vector<cv::Mat>& sequence() {
  static const std::vector<cv::Mat> images = [] {
    const Scene s = bench_scene();
    const sim::RunResult run = sim::run_spec(s.sim);
    render::Renderer renderer(flatland::model::render_setup(*flatland::model::compile(s)));
    std::vector<cv::Mat> out;
    for (int k = 45; k <= 75; ++k) out.push_back(renderer.capture(run.trajectory, k / 30.0).image);
    return out;
  }();
  return images;
}

vision::TrackMethod method_of(int64_t i) { return static_cast<vision::TrackMethod>(i); }

// The disk found once, then followed in its ROI (the state of every frame of a normal run).
void TrackRoi(benchmark::State& state) {
  vision::TrackerConfig cfg;
  cfg.method = method_of(state.range(0));
  vision::Tracker tracker(cfg);
  const cv::Mat& image = frame();
  if (!tracker.track(image).ok()) state.SkipWithError("disk not found");
  for (auto _ : state) {
    const vision::TrackResult r = tracker.track(image);
    benchmark::DoNotOptimize(r.center);
    if (r.state != vision::TrackState::kTracking) state.SkipWithError("ROI tracking failed");
  }
  state.SetLabel(vision::to_string(cfg.method));
}

// The same with the camera known: the edge points are also back-projected and fitted on the
// table plane (TrackerConfig::camera).
void TrackRoiTablePlane(benchmark::State& state) {
  vision::TrackerConfig cfg;
  CameraSpec cam;
  cam.fx = cam.fy = 900;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.position = {0.0, 0.0, 1.2};
  cfg.camera = flatland::model::compile_camera(cam);
  cfg.plane_z = 0.006;
  if (state.range(0)) cfg.camera->dist = {-0.25, 0.08, 0, 0, 0};  // cost of undistortPoints
  vision::Tracker tracker(cfg);
  const cv::Mat& image = frame();
  if (!tracker.track(image).ok()) state.SkipWithError("disk not found");
  for (auto _ : state) {
    const vision::TrackResult r = tracker.track(image);
    benchmark::DoNotOptimize(r.center);
  }
  state.SetLabel(state.range(0) ? "edge, table plane, distorted" : "edge, table plane");
}

// Every frame searched whole (the first frame, and each frame after a loss).
void TrackFullFrame(benchmark::State& state) {
  vision::TrackerConfig cfg;
  cfg.method = method_of(state.range(0));
  vision::Tracker tracker(cfg);
  const cv::Mat& image = frame();
  for (auto _ : state) {
    tracker.reset();
    const vision::TrackResult r = tracker.track(image);
    benchmark::DoNotOptimize(r.center);
    if (r.state != vision::TrackState::kFound) state.SkipWithError("re-acquisition failed");
  }
  state.SetLabel(vision::to_string(cfg.method));
}

// The mapping of one tracked centre to s_h (undistortion, plane, hand frame, Brent).
void PixelToContact(benchmark::State& state) {
  vision::HandMapping m;
  CameraSpec cam;
  cam.fx = cam.fy = 900;
  cam.cx = 319.5;
  cam.cy = 239.5;
  cam.position = {0.0, 0.0, 1.2};
  cam.distortion = {-0.1, 0.02, 0, 0, 0};
  m.camera = flatland::model::compile_camera(cam);
  m.plane_z = 0.006;
  m.disk_radius = 0.051;
  for (auto _ : state) {
    const auto c = vision::pixel_to_contact(m, {330.2, 180.7}, 0.4, -0.5, 0.5);
    benchmark::DoNotOptimize(c);
  }
}

// A 3 s, 30 fps MP4 of the rendered frame with the disk region moving (a key frame a second,
// as flatland writes them), read whole per iteration: flatland's reader (two single-threaded
// decoding passes: the integrity scan, then the frames) against OpenCV's capture (one pass, frame
// threads, no integrity). Counter: frames per second of wall time.
const std::string& test_video() {
  static const std::string path = [] {
    const std::string p =
        (std::filesystem::temp_directory_path() / "flatland_vision_bench_read.mp4").string();
    render::Mp4Writer w;
    render::open_mp4(w, p, 30.0, frame().size(), "");
    cv::Mat moving;
    for (int i = 0; i < 90; ++i) {
      moving = frame().clone();
      cv::circle(moving, {200 + 2 * i, 240}, 30, cv::Scalar(250, 250, 250), -1);
      w.write(moving);
    }
    w.release();
    return p;
  }();
  return path;
}

void ReadVideo(benchmark::State& state) {
  const bool opencv = state.range(0) != 0;
  long frames = 0;
  for (auto _ : state) {
    if (opencv) {
      cv::VideoCapture cap(test_video(), cv::CAP_FFMPEG);
      for (cv::Mat f; cap.read(f);) ++frames;
    } else {
      vision::VideoReader reader(test_video());
      for (vision::VideoReader::Frame f; reader.read(f);) ++frames;
    }
  }
  state.counters["frames_per_s"] =
      benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
  state.SetLabel(opencv ? "opencv" : "flatland");
}

// The edge fit and the contour peer on the same frames, interleaved frame by frame so that both
// see the same load; `whole`: every frame searched whole (re-acquisition), else followed in the
// window. Counters: each one's mean time per frame (us) and their ratio flatland / contour.
void EdgeVsContour(benchmark::State& state) {
  const bool whole = state.range(0) != 0;
  const std::vector<cv::Mat>& frames = sequence();
  vision::TrackerConfig edge_cfg, contour_cfg;
  contour_cfg.method = vision::TrackMethod::kContour;
  vision::Tracker edge(edge_cfg), contour(contour_cfg);
  const vision::TrackState expected =
      whole ? vision::TrackState::kFound : vision::TrackState::kTracking;
  using clock = std::chrono::steady_clock;
  double edge_s = 0, contour_s = 0;
  long n = 0;
  auto timed = [&](vision::Tracker& t, const cv::Mat& image, double& seconds) {
    if (whole) t.reset();
    const auto t0 = clock::now();
    const vision::TrackResult r = t.track(image);
    seconds += std::chrono::duration<double>(clock::now() - t0).count();
    benchmark::DoNotOptimize(r.center);
    return r.state == expected;
  };
  // The first frame acquires; the benchmark times the frames after it.
  if (!edge.track(frames.front()).ok() || !contour.track(frames.front()).ok())
    state.SkipWithError("disk not found");
  for (auto _ : state) {
    const auto t0 = clock::now();
    for (std::size_t k = 1; k < frames.size(); ++k) {
      if (!timed(edge, frames[k], edge_s) || !timed(contour, frames[k], contour_s)) {
        state.SkipWithError("a tracker lost the disk or left its expected state");
        return;
      }
      ++n;
    }
    state.SetIterationTime(std::chrono::duration<double>(clock::now() - t0).count());
    // Back to the start of the sequence with a track at its first frame.
    edge.reset();
    contour.reset();
    edge.track(frames.front());
    contour.track(frames.front());
  }
  state.counters["flatland_us"] = 1e6 * edge_s / static_cast<double>(n);
  state.counters["contour_us"] = 1e6 * contour_s / static_cast<double>(n);
  state.counters["flatland_over_contour"] = edge_s / contour_s;
  state.SetLabel(whole ? "whole-frame re-acquisition" : "window tracking");
}

constexpr int kReps = 7;

}  // namespace

BENCHMARK(ReadVideo)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

BENCHMARK(EdgeVsContour)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Repetitions(kReps)
    ->ReportAggregatesOnly(true);
BENCHMARK(TrackRoi)
    ->Arg(static_cast<int>(vision::TrackMethod::kEdge))
    ->Arg(static_cast<int>(vision::TrackMethod::kMoments))
    ->Arg(static_cast<int>(vision::TrackMethod::kHough))
    ->Arg(static_cast<int>(vision::TrackMethod::kContour))
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(kReps)
    ->ReportAggregatesOnly(true);
BENCHMARK(TrackRoiTablePlane)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(kReps)
    ->ReportAggregatesOnly(true);
BENCHMARK(TrackFullFrame)
    ->Arg(static_cast<int>(vision::TrackMethod::kEdge))
    ->Arg(static_cast<int>(vision::TrackMethod::kMoments))
    ->Arg(static_cast<int>(vision::TrackMethod::kHough))
    ->Arg(static_cast<int>(vision::TrackMethod::kContour))
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(kReps)
    ->ReportAggregatesOnly(true);
BENCHMARK(PixelToContact)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
