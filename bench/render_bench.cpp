// Renderer throughput on llvmpipe: frames per second including readback into a cv::Mat, against
// the raw throughput of a trivial scene (clear + the same readback) measured in the same run.
// Results and how to rerun: docs/BENCHMARKS.md.
#define GL_GLEXT_PROTOTYPES 1
#include <GL/gl.h>
#include <GL/glext.h>
#include <benchmark/benchmark.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "flatland/model/model.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/render/video_writer.hpp"

#include <filesystem>
#include <string>
#include <utility>

using namespace flatland;

namespace {

Scene camera_scene(int width, int height, int supersample) {
  Scene s;  // the paper's butterfly
  CameraSpec cam;
  cam.width = width;
  cam.height = height;
  cam.fx = cam.fy = 900.0 * width / 640.0;  // the same field of view at every resolution
  cam.cx = (width - 1) / 2.0;
  cam.cy = (height - 1) / 2.0;
  cam.position = {0.0, 0.0, 1.0};
  s.camera = cam;
  s.effects.supersample = supersample;
  return s;
}

// A mid-roll state of the solved butterfly (disk near the tip, hand turning).
render::SceneState mid_roll() {
  static const render::SceneState st = [] {
    const sim::RunResult run = sim::run_spec(sim::SimulationSpec{});
    return render::SceneState::from_sample(run.trajectory.sample(0.45));
  }();
  return st;
}

// The references: clear an FBO of the same size, optionally draw one triangle with a minimal
// shader (a trivial scene: llvmpipe's per-draw cost without the scene's geometry), and read it
// back through the renderer's path (RGBA readback, conversion to BGR).
void TrivialScene(benchmark::State& state, render::GlBackend backend, int width, int height,
                  bool one_triangle) {
  auto ctx = render::create_context(backend);
  auto get = [&](const char* n) { return ctx->proc_address(n); };
  auto gen_fb = reinterpret_cast<decltype(&glGenFramebuffers)>(get("glGenFramebuffers"));
  auto bind_fb = reinterpret_cast<decltype(&glBindFramebuffer)>(get("glBindFramebuffer"));
  auto gen_rb = reinterpret_cast<decltype(&glGenRenderbuffers)>(get("glGenRenderbuffers"));
  auto bind_rb = reinterpret_cast<decltype(&glBindRenderbuffer)>(get("glBindRenderbuffer"));
  auto storage = reinterpret_cast<decltype(&glRenderbufferStorage)>(get("glRenderbufferStorage"));
  auto attach =
      reinterpret_cast<decltype(&glFramebufferRenderbuffer)>(get("glFramebufferRenderbuffer"));
  auto clear = reinterpret_cast<decltype(&glClear)>(get("glClear"));
  auto viewport = reinterpret_cast<decltype(&glViewport)>(get("glViewport"));
  auto read = reinterpret_cast<decltype(&glReadPixels)>(get("glReadPixels"));
  unsigned fbo = 0, rb[2] = {0, 0};
  gen_fb(1, &fbo);
  bind_fb(GL_FRAMEBUFFER, fbo);
  gen_rb(2, rb);
  bind_rb(GL_RENDERBUFFER, rb[0]);
  storage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  attach(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb[0]);
  bind_rb(GL_RENDERBUFFER, rb[1]);
  storage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  attach(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
  viewport(0, 0, width, height);
  unsigned program = 0, vao = 0, vbo = 0;
  auto draw = reinterpret_cast<decltype(&glDrawArrays)>(get("glDrawArrays"));
  if (one_triangle) {
    auto create_shader = reinterpret_cast<decltype(&glCreateShader)>(get("glCreateShader"));
    auto source = reinterpret_cast<decltype(&glShaderSource)>(get("glShaderSource"));
    auto compile = reinterpret_cast<decltype(&glCompileShader)>(get("glCompileShader"));
    auto create_program = reinterpret_cast<decltype(&glCreateProgram)>(get("glCreateProgram"));
    auto attach_shader = reinterpret_cast<decltype(&glAttachShader)>(get("glAttachShader"));
    auto link = reinterpret_cast<decltype(&glLinkProgram)>(get("glLinkProgram"));
    auto use = reinterpret_cast<decltype(&glUseProgram)>(get("glUseProgram"));
    auto gen_va = reinterpret_cast<decltype(&glGenVertexArrays)>(get("glGenVertexArrays"));
    auto bind_va = reinterpret_cast<decltype(&glBindVertexArray)>(get("glBindVertexArray"));
    auto gen_b = reinterpret_cast<decltype(&glGenBuffers)>(get("glGenBuffers"));
    auto bind_b = reinterpret_cast<decltype(&glBindBuffer)>(get("glBindBuffer"));
    auto data = reinterpret_cast<decltype(&glBufferData)>(get("glBufferData"));
    auto enable_attr =
        reinterpret_cast<decltype(&glEnableVertexAttribArray)>(get("glEnableVertexAttribArray"));
    auto attr = reinterpret_cast<decltype(&glVertexAttribPointer)>(get("glVertexAttribPointer"));
    const char* vs =
        "#version 330 core\nlayout(location=0) in vec2 p;\n"
        "void main(){gl_Position=vec4(p,0.0,1.0);}\n";
    const char* fs = "#version 330 core\nout vec4 c;\nvoid main(){c=vec4(0.9,0.9,0.9,1.0);}\n";
    const unsigned v = create_shader(GL_VERTEX_SHADER), f = create_shader(GL_FRAGMENT_SHADER);
    source(v, 1, &vs, nullptr);
    source(f, 1, &fs, nullptr);
    compile(v);
    compile(f);
    program = create_program();
    attach_shader(program, v);
    attach_shader(program, f);
    link(program);
    use(program);
    const float tri[] = {-0.1f, -0.1f, 0.1f, -0.1f, 0.0f, 0.1f};  // about 1 % of the frame
    gen_va(1, &vao);
    bind_va(vao);
    gen_b(1, &vbo);
    bind_b(GL_ARRAY_BUFFER, vbo);
    data(GL_ARRAY_BUFFER, sizeof tri, tri, GL_STATIC_DRAW);
    enable_attr(0);
    attr(0, 2, GL_FLOAT, GL_FALSE, 0, nullptr);
  }
  cv::Mat rgba(height, width, CV_8UC4), bgr;
  for (auto _ : state) {
    clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if (one_triangle) draw(GL_TRIANGLES, 0, 3);
    read(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data);
    cv::cvtColor(rgba, bgr, cv::COLOR_RGBA2BGR);
    benchmark::DoNotOptimize(bgr.data);
  }
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void Render(benchmark::State& state, render::GlBackend backend, int width, int height,
            int supersample) {
  render::Renderer r(flatland::model::render_setup(
                         *flatland::model::compile(camera_scene(width, height, supersample))),
                     backend);
  const render::SceneState st = mid_roll();
  for (auto _ : state) {
    cv::Mat image = r.render_8u(st);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

// The scene's lamp, each effect on its own and all together, against the same frame unlit
// (docs/SCENE.md "Lighting"; the lamp at its defaults, the bundled scenes' values). `lamp`:
// "off" (no lighting section), "diffuse" (the point light's inverse-square and cosine fall-off,
// no highlights, no shadows), "specular" (diffuse + Blinn-Phong highlights), "shadows" (diffuse +
// the hand's and the disk's planar shadows), "all" (the default lamp).
void RenderLighting(benchmark::State& state, render::GlBackend backend, int width, int height,
                    int supersample, const std::string& lamp) {
  Scene scene = camera_scene(width, height, supersample);
  if (lamp != "off") {
    LightingSpec lighting;
    lighting.specular = lamp == "specular" || lamp == "all";
    lighting.shadows = lamp == "shadows" || lamp == "all";
    scene.lighting = lighting;
  }
  render::Renderer r(model::render_setup(*model::compile(scene)), backend);
  const render::SceneState st = mid_roll();
  for (auto _ : state) {
    cv::Mat image = r.render_8u(st);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

// The bundled butterfly-camera scene (640 x 480, 2 x 2 supersampling) at its run's t = 0.45 s:
// the frame bench/python_bindings.py renders through Python, for the binding's overhead.
void RenderButterflyCamera(benchmark::State& state) {
  const auto model =
      model::compile(load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml"));
  render::Renderer r(model::render_setup(*model));
  sim::SimulationSpec spec = model->spec.sim;
  spec.run.record = true;
  const render::SceneState st =
      render::SceneState::from_sample(sim::run_spec(spec).trajectory.sample(0.45));
  for (auto _ : state) {
    cv::Mat image = r.render_8u(st);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

// A frame of the bundled butterfly-camera scene (640 x 480, 2 x 2 supersampling, no lamp) through
// Renderer::capture with each readout: global (the peer), interlaced (two fields), rolling
// (30 ms readout) with one row per GL pass (exact) or bands of 8 and 32 rows; each with its mask
// too when `mask`.
void CaptureReadout(benchmark::State& state, std::string readout, int band_rows, bool mask) {
  Scene scene = load_scene(std::string(FLATLAND_ASSET_DIR) + "/scenes/butterfly-camera.yaml");
  scene.camera->readout.mode = readout;
  if (readout == "rolling") {
    scene.camera->readout.time = 0.03;
    scene.camera->readout.band_rows = band_rows;
  }
  const auto model = model::compile(scene);
  render::Renderer r(model::render_setup(*model));
  sim::SimulationSpec spec = model->spec.sim;
  spec.run.record = true;
  const sim::RunResult run = sim::run_spec(spec);
  render::CaptureOptions options;
  options.mask = mask;
  double t = 0.3;
  for (auto _ : state) {
    render::Frame f = r.capture(run.trajectory, t, options);
    benchmark::DoNotOptimize(f.image.data);
    t = t < 0.9 ? t + 1.0 / 30 : 0.3;
  }
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

// H.264 encoding of rendered 640x480 frames: flatland's writer (libavcodec, a key frame a second)
// against OpenCV's FFmpeg writer (its peer: same codec and CRF, x264's 250-frame key interval).
void Mp4Encode(benchmark::State& state, bool opencv) {
  render::Renderer r(
      flatland::model::render_setup(*flatland::model::compile(camera_scene(640, 480, 1))),
      render::GlBackend::kOsmesa);
  const cv::Mat frame = r.render_8u(mid_roll());
  const std::string path =
      (std::filesystem::temp_directory_path() / "flatland_bench_encode.mp4").string();
  cv::VideoWriter cv_writer;
  render::Mp4Writer writer;
  if (opencv) {
    cv_writer.open(path, cv::CAP_FFMPEG, cv::VideoWriter::fourcc('a', 'v', 'c', '1'), 30.0,
                   frame.size());
    if (!cv_writer.isOpened()) {
      state.SkipWithError("the avc1 writer cannot be opened here");
      return;
    }
  } else if (render::open_mp4(writer, path, 30.0, frame.size(), "") != "avc1") {
    state.SkipWithError("no H.264 encoder here");
    return;
  }
  cv::Mat moving = frame.clone();
  int i = 0;
  for (auto _ : state) {
    // Change a few pixels per frame so the encoder does real work, as with a moving disk.
    cv::circle(moving, {100 + (i % 400), 100}, 20, cv::Scalar(255, i % 255, 0), -1);
    if (opencv)
      cv_writer.write(moving);
    else
      writer.write(moving);
    ++i;
  }
  if (opencv)
    cv_writer.release();
  else
    writer.release();
  state.counters["bytes_per_frame"] = static_cast<double>(std::filesystem::file_size(path)) / i;
  std::filesystem::remove(path);
  state.counters["fps"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void register_all() {
  for (const auto backend : {render::GlBackend::kOsmesa, render::GlBackend::kEgl}) {
    const std::string b = render::to_string(backend);
    for (const auto& [w, h] : {std::pair{640, 480}, std::pair{1280, 1024}}) {
      const std::string size = std::to_string(w) + "x" + std::to_string(h);
      benchmark::RegisterBenchmark(("BM_TrivialScene/" + b + "/" + size + "/clear").c_str(),
                                   TrivialScene, backend, w, h, false)
          ->Unit(benchmark::kMicrosecond)
          ->UseRealTime();
      benchmark::RegisterBenchmark(("BM_TrivialScene/" + b + "/" + size + "/one_triangle").c_str(),
                                   TrivialScene, backend, w, h, true)
          ->Unit(benchmark::kMicrosecond)
          ->UseRealTime();
      for (const int ss : {1, 2}) {
        const std::string aa = ss == 1 ? "aa:off" : "aa:4x";  // supersample 2 = 4 samples/pixel
        benchmark::RegisterBenchmark(("BM_Render/" + b + "/" + size + "/" + aa).c_str(), Render,
                                     backend, w, h, ss)
            ->Unit(benchmark::kMicrosecond)
            ->UseRealTime();
      }
    }
  }
  for (const auto backend : {render::GlBackend::kOsmesa, render::GlBackend::kEgl})
    for (const int ss : {1, 2})
      for (const char* lamp : {"off", "diffuse", "specular", "shadows", "all"}) {
        const std::string name = "BM_RenderLighting/" + render::to_string(backend) + "/640x480/" +
                                 (ss == 1 ? "aa:off/" : "aa:4x/") + lamp;
        benchmark::RegisterBenchmark(name.c_str(), RenderLighting, backend, 640, 480, ss,
                                     std::string(lamp))
            ->Unit(benchmark::kMicrosecond)
            ->UseRealTime();
      }
  benchmark::RegisterBenchmark("BM_RenderButterflyCamera", RenderButterflyCamera)
      ->Unit(benchmark::kMicrosecond)
      ->UseRealTime();
  for (const bool mask : {false, true})
    for (const auto& [readout, bands] :
         {std::pair{"global", 1}, std::pair{"interlaced", 1}, std::pair{"rolling", 1},
          std::pair{"rolling", 8}, std::pair{"rolling", 32}}) {
      std::string name = std::string("BM_CaptureReadout/") + readout;
      if (std::string(readout) == "rolling") name += "/band_rows:" + std::to_string(bands);
      if (mask) name += "/mask";
      benchmark::RegisterBenchmark(name.c_str(), CaptureReadout, std::string(readout), bands, mask)
          ->Unit(benchmark::kMicrosecond)
          ->UseRealTime();
    }
  for (const bool opencv : {false, true})
    benchmark::RegisterBenchmark(
        (std::string("BM_Mp4Encode/640x480/") + (opencv ? "opencv" : "flatland")).c_str(),
        Mp4Encode, opencv)
        ->Unit(benchmark::kMicrosecond)
        ->Iterations(300)
        ->UseRealTime();
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  register_all();
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
