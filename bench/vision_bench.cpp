// Tracker latency per 640 x 480 frame (docs/VISION.md): following the disk in its region of
// interest, and whole-frame re-acquisition, for each method, on one rendered frame of the
// air-table butterfly (noise 2 DN, 30 Hz exposure blur). Medians over repetitions are reported.
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

#include <filesystem>
#include <numbers>

using namespace flatland;

namespace {

// Mid-roll (t = 2 s: the disk near the fingertip, the hand touching it, moving fast).
const cv::Mat& frame() {
  static const cv::Mat image = [] {
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
    const sim::RunResult run = sim::run_spec(s.sim);
    render::Renderer renderer(flatland::model::render_setup(*flatland::model::compile(s)));
    return renderer.capture(run.trajectory, 2.0).image;
  }();
  return image;
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

constexpr int kReps = 7;

}  // namespace

BENCHMARK(ReadVideo)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

BENCHMARK(TrackRoi)
    ->Arg(static_cast<int>(vision::TrackMethod::kEdge))
    ->Arg(static_cast<int>(vision::TrackMethod::kMoments))
    ->Arg(static_cast<int>(vision::TrackMethod::kHough))
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
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(kReps)
    ->ReportAggregatesOnly(true);
BENCHMARK(PixelToContact)->Unit(benchmark::kMicrosecond);

BENCHMARK_MAIN();
