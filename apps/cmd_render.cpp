// flatland render: simulate the scene and film it with the scene's camera: an MP4 video or a
// directory of PNG frames, with the ground truth of every frame (CSV) and the camera (JSON).
#include "common.hpp"

#include "flatland/camera/camera_file.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/overlay_text.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/render/video_writer.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/spatial_spec.hpp"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <sstream>

namespace flatland::app {

namespace {

struct RenderOptions {
  CommonOptions common;
  std::string view, gl;
  bool overlay = false, solve = false, mask = false;
  double fps = 0, duration = 0;
  CLI::Option* view_opt = nullptr;
  CLI::Option* gl_opt = nullptr;
  CLI::Option* fps_opt = nullptr;
  CLI::Option* duration_opt = nullptr;
};

/// The side view: the scene's intrinsics, from downhill (-y) and above the table, looking at the
/// hand a little above the table plane, the table's normal up in the image.
CameraSpec side_camera(CameraSpec c) {
  c.position = {0.0, -1.2, 0.4};
  c.look_at = {0.0, 0.0, 0.05};
  c.up = {0.0, 0.0, 1.0};
  return c;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

const char* kTruthColumns =
    "frame,t,dropped,theta,s_h,disk_x,disk_y,disk_z,disk_u,disk_v,marker_x,marker_y,marker_z,"
    "marker_u,marker_v";

/// The column a readout other than global adds: when the row's state holds (FrameTruth::t_state).
const char* kTruthStateColumn = "t_state";

/// One truth.csv row. `frame` is the image's index in the output, -1 for a dropped frame; with
/// `state_time`, t_state last.
std::string truth_row(long frame, const render::FrameTruth& t, bool state_time) {
  const double v[] = {t.t,
                      t.theta,
                      t.s_h,
                      t.disk_center_table.x,
                      t.disk_center_table.y,
                      t.disk_center_table.z,
                      t.disk_center_px.x,
                      t.disk_center_px.y,
                      t.marker_table.x,
                      t.marker_table.y,
                      t.marker_table.z,
                      t.marker_px.x,
                      t.marker_px.y};
  std::string row =
      std::to_string(frame) + "," + format_number(v[0]) + "," + (t.dropped ? "1" : "0");
  // Appended piece by piece: GCC 12's -Wrestrict misfires on "literal" + std::string&&.
  for (std::size_t i = 1; i < sizeof v / sizeof v[0]; ++i)
    row.append(",").append(format_number(v[i]));
  if (state_time) row.append(",").append(format_number(t.t_state));
  return row + "\n";
}

/// The hand angle every millisecond of the run (rows t,theta): the encoder log flatland track
/// reads, as the closed loop's 1 kHz servo would record it.
std::string encoder_csv(const sim::Trajectory& trajectory) {
  std::string csv = "t,theta\n";
  const double t0 = trajectory.t_begin(), t1 = trajectory.t_end();
  const long n = static_cast<long>(std::floor((t1 - t0) * 1000 + 1e-9));
  for (long i = 0; i <= n; ++i) {
    const double t = std::min(t0 + i * 1e-3, t1);
    csv += format_number(t) + "," + format_number(trajectory.sample(t).theta) + "\n";
  }
  return csv;
}

/// --overlay: time, s_h, the contact's mode and the hand's contact force on the frame. The force f
/// = f_n n + f_t t (n the hand's outward normal, t its tangent towards increasing s_h, both rotated
/// by theta into the table frame) is drawn from the projected contact point, 0.1 m on the table per
/// in-plane weight m g sin(tilt).
void draw_overlay(cv::Mat& bgr, const camera::CameraModel& camera, const sim::HandCurve& hand,
                  double disk_radius, const sim::Sample& s, const render::FrameTruth& truth) {
  const double c = std::cos(s.theta), sn = std::sin(s.theta);
  const auto rotate = [&](const sim::Vec2& v) {
    return sim::Vec2(c * v.x() - sn * v.y(), sn * v.x() + c * v.y());
  };
  const sim::CurveGeometry g = hand.geometry(s.s_h);
  const sim::Vec2 contact = rotate(g.point);
  const sim::Vec2 force = s.fn_ratio * rotate(g.normal) + s.ft_ratio * rotate(g.tangent);
  constexpr double kMetresPerWeight = 0.1;
  const double z = truth.disk_center_table.z;
  const cv::Point2d from = camera.project(cv::Point3d(contact.x(), contact.y(), z));
  const cv::Point2d to = camera.project(cv::Point3d(contact.x() + kMetresPerWeight * force.x(),
                                                    contact.y() + kMetresPerWeight * force.y(), z));
  const double scale = std::max(0.35, bgr.rows / 960.0);
  const int thick = std::max(1, static_cast<int>(std::lround(2 * scale)));
  const cv::Scalar red(0, 0, 255), yellow(0, 220, 255);
  if (std::isfinite(from.x) && std::isfinite(to.x)) {
    cv::circle(bgr, from, 3 * thick, yellow, thick, cv::LINE_AA);
    if (cv::norm(to - from) >= 2) cv::arrowedLine(bgr, from, to, red, thick, cv::LINE_AA, 0, 0.2);
  }
  char line[3][96];
  std::snprintf(line[0], sizeof line[0], "t = %.3f s", truth.t);
  // The contact's mode (the hybrid model's): in flight, how far the disk is from the hand.
  if (s.mode == sim::ContactMode::kFlight)
    std::snprintf(line[1], sizeof line[1], "s_h = %+.3f  flight, gap %.1f mm", s.s_h, 1e3 * s.gap);
  else
    std::snprintf(line[1], sizeof line[1], "s_h = %+.3f  %s", s.s_h,
                  sim::to_string(s.mode).c_str());
  std::snprintf(line[2], sizeof line[2], "f/(m g sin tilt) = %.3f (n %+.3f, t %+.3f)", force.norm(),
                s.fn_ratio, s.ft_ratio);
  // The text goes in the corner farthest from the disk's image, so that it never hides it.
  const cv::Point3d& d = truth.disk_center_table;
  const render::KeepClear disk = render::disk_in_image(
      truth.disk_center_px, camera.project(cv::Point3d(d.x + disk_radius, d.y, d.z)));
  render::draw_text_block(bgr, {line[0], line[1], line[2]}, 1.2 * scale, thick, {disk});
}

Json effects_json(const EffectsSpec& e) {
  Json j;
  j["supersample"] = e.supersample;
  j["blur_subframes"] = e.blur_subframes;
  j["noise_read_dn"] = e.noise_read_dn;
  j["noise_shot_gain"] = e.noise_shot_gain;
  j["quantize"] = e.quantize;
  j["vignetting"] = e.vignetting;
  j["jitter_s"] = e.jitter_s;
  j["drop_probability"] = e.drop_probability;
  j["seed"] = e.seed;
  return j;
}

Json camera_json(const camera::CameraModel& m, const CameraSpec& spec) {
  Json j;
  j["width"] = m.width;
  j["height"] = m.height;
  j["fx"] = m.K(0, 0);
  j["fy"] = m.K(1, 1);
  j["cx"] = m.K(0, 2);
  j["cy"] = m.K(1, 2);
  j["K"] = {{m.K(0, 0), m.K(0, 1), m.K(0, 2)},
            {m.K(1, 0), m.K(1, 1), m.K(1, 2)},
            {m.K(2, 0), m.K(2, 1), m.K(2, 2)}};
  j["distortion"] = {m.dist[0], m.dist[1], m.dist[2], m.dist[3], m.dist[4]};
  if (m.rational())
    for (int k = 5; k < 8; ++k) j["distortion"].push_back(m.dist[k]);
  const cv::Vec3d r = m.rvec();
  j["rvec"] = {r[0], r[1], r[2]};
  j["tvec"] = {m.t[0], m.t[1], m.t[2]};
  j["position"] = spec.position;
  j["look_at"] = spec.look_at;
  j["up"] = spec.up;
  j["fps"] = m.fps;
  j["exposure"] = m.exposure;
  return j;
}

// One run writes at most this many frames (an hour at 30 fps is 108 000), at this rate at most.
constexpr long kMaxRenderFrames = 200000;
constexpr double kMaxRenderFps = 1000;

/// One frame into the MP4 (when `video` is given) or as DIR/frame_NNNNNN.png, staged.
void write_png(const cv::Mat& image, const char* prefix, long index, OutputSet& outputs,
               const fs::path& dir, std::vector<unsigned char>& png) {
  if (!cv::imencode(".png", image, png))
    throw std::runtime_error(std::string("cannot encode ") + prefix + std::to_string(index) +
                             " as PNG");
  char name[48];
  std::snprintf(name, sizeof name, "%s_%06ld.png", prefix, index);
  outputs.stage(dir / name, std::string(png.begin(), png.end()));
}

void write_frame(const cv::Mat& bgr, long index, render::Mp4Writer* video, OutputSet& outputs,
                 const fs::path& dir, std::vector<unsigned char>& png) {
  if (video) {
    video->write(bgr);
    return;
  }
  write_png(bgr, "frame", index, outputs, dir, png);
}

/// --duration and --fps into the scene (UsageError for a bad value, or a frame interval shorter
/// than the camera's exposure).
void apply_duration_and_fps(const RenderOptions& o, std::optional<double>& duration,
                            CameraSpec& camera) {
  if (o.duration_opt->count()) {
    require_positive("--duration", o.duration, "s");
    duration = o.duration;
  }
  if (o.fps_opt->count()) {
    require_positive("--fps", o.fps, "frames per s");
    if (o.fps > kMaxRenderFps)
      throw UsageError("--fps: at most " + format_number(kMaxRenderFps) + " frames per s, got " +
                       format_number(o.fps));
    if (camera.exposure > 1.0 / o.fps)
      throw UsageError("--fps: the frame interval 1/" + format_number(o.fps) +
                       " s is shorter than camera.exposure (" + format_number(camera.exposure) +
                       " s)");
    camera.fps = o.fps;
    // The readout's rules that depend on the rate (a rolling readout within the frame interval,
    // an interlaced field's exposure within the field interval).
    if (auto problem = camera_problem(camera))
      throw UsageError("--fps: " + format_number(o.fps) + " frames per s breaks camera." +
                       problem->field + ": " + problem->reason);
  }
}

/// flatland render on a spatial scene: the run sampled at the camera's rate, each sample drawn
/// (the hand's surface and the object at their poses) through the scene's camera, with
/// supersampling and lens distortion; the other image effects are refused (not built for space).
void run_render_spatial(const RenderOptions& o, Scene scene) {
  if (!scene.camera)
    throw UsageError(scene.origin + ": camera: the scene has no camera section (needed by render)");
  if (o.overlay) throw UsageError("--overlay: only for planar scenes");
  if (o.mask) throw UsageError("--mask: only for planar scenes");
  if (o.solve) throw UsageError("--solve: only for planar scenes");
  if (o.view_opt->count())
    throw UsageError("--view: only for planar scenes (a spatial scene is seen by its camera)");
  sim::SpatialSpec spec = *scene.spatial;
  api::apply_integrator_overrides(integrator_overrides(o.common), spec.integrator,
                                  api::Spelling::kCommandLine);
  CameraSpec& camera = *scene.camera;
  apply_duration_and_fps(o, spec.duration, camera);
  if (o.gl_opt->count()) scene.render.backend = o.gl;
  const render::GlBackend backend = render::parse_backend(scene.render.backend);
  sim::SpatialSetup setup;
  try {
    setup = sim::build_spatial(spec);
  } catch (const std::invalid_argument& err) {
    throw UsageError(scene.origin + ": " + err.what());
  }
  // The camera (with --fps), the bodies; effects that spatial frames do not have are refused.
  const render::RenderSetup rs = model::spatial_render_setup(scene, setup);
  const double frames_wanted = std::floor(spec.end_time() * camera.fps) + 1;
  if (frames_wanted > kMaxRenderFrames)
    throw UsageError("--fps/--duration: " + format_number(frames_wanted) + " frames; at most " +
                     std::to_string(kMaxRenderFrames) + " are rendered in one run");
  const std::string out_text = o.common.out;
  if (out_text.empty()) throw UsageError("--out: required (FILE.mp4 or a directory)");
  const fs::path out = out_text;
  const bool mp4 = lower(out.extension().string()) == ".mp4" && out_text.back() != '/';
  if (mp4 && fs::is_directory(out))
    throw UsageError("--out: " + out_text + " is a directory; give a FILE.mp4 or a directory");
  const fs::path dir = mp4 ? out.parent_path() : out;
  const std::string stem = mp4 ? out.stem().string() + "." : std::string();
  const fs::path truth_path = dir / (stem + "truth.csv"),
                 meta_path = dir / (stem + (mp4 ? "json" : "meta.json")),
                 camera_path = dir / (stem + "camera.yaml");
  if (mp4) {
    for (const fs::path& p : {out, truth_path, meta_path, camera_path})
      check_output_file("--out", p, o.common.force);
  } else {
    check_output_directory("--out", out, o.common.force);
  }
  render::Renderer renderer(rs, backend);
  const camera::CameraModel& model = renderer.camera();
  const std::string gl = renderer.gl_description();

  OutputSet outputs(o.common.force);
  const cv::Size size(model.width, model.height);
  render::Mp4Writer writer;
  fs::path video_tmp;
  std::string codec;
  if (mp4) {
    outputs.ensure_directory(out.parent_path());
    video_tmp = outputs.reserve_keep_extension(out);
    codec = render::open_mp4(writer, video_tmp.string(), model.fps, size,
                             "cannot open an MP4 writer for " + out_text + ": ",
                             "; --out DIR writes PNG frames instead");
  } else {
    outputs.begin_directory(out);
  }
  std::cerr << "flatland: simulating " << scene.origin << " (spatial) for "
            << format_number(spec.end_time()) << " s\n";
  setup.options.sample_dt = 1.0 / model.fps;
  const sim::SpatialRunResult run = sim::run_spatial(setup);
  if (run.stop != sim::SpatialStop::kEndTime)
    std::cerr << "flatland: the run stopped at t = " << format_number(run.final.t) << " s ("
              << sim::to_string(run.stop) << "); rendering up to there\n";
  std::string truth_csv = "frame,t,x,y,z,u,v\n";
  std::vector<unsigned char> png;
  long written = 0;
  const auto start = std::chrono::steady_clock::now();
  {
    ProgressBar bar("render");
    const long n = static_cast<long>(run.samples.size());
    for (const sim::SpatialSample& sample : run.samples) {
      // The run's last sample is its end (an event's time), off the frame grid: not a frame.
      if (written > 0 && std::abs(sample.t * model.fps - std::round(sample.t * model.fps)) > 1e-6)
        continue;
      const render::SceneState st =
          render::SceneState::from_spatial_sample(sample, setup.motion->at(sample.t));
      const cv::Mat bgr = renderer.render_8u(st);
      write_frame(bgr, written, mp4 ? &writer : nullptr, outputs, out, png);
      const render::FrameTruth truth = renderer.truth(st);
      std::string row = std::to_string(written);
      for (double v : {sample.t, truth.disk_center_table.x, truth.disk_center_table.y,
                       truth.disk_center_table.z, truth.disk_center_px.x, truth.disk_center_px.y})
        row.append(",").append(format_number(v));
      truth_csv += row + "\n";
      ++written;
      bar.update(written, n);
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (mp4) writer.release();
  outputs.stage(truth_path, truth_csv);
  camera::CameraFile camera_file;
  camera_file.camera_name = scene.name.empty() ? "flatland" : scene.name;
  camera_file.camera = model;
  camera_file.has_table_pose = true;  // the pose in the scene's world frame
  camera::write_camera_file(outputs.reserve(camera_path).string(), camera_file);
  Json meta;
  meta["scene"] = scene.origin;
  meta["name"] = scene.name;
  meta["space"] = "3d";
  meta["format"] = mp4 ? "mp4" : "png";
  meta["codec"] = mp4 ? Json(codec) : Json(nullptr);
  meta["output"] = out.string();
  meta["truth"] = truth_path.string();
  meta["camera_file"] = camera_path.string();
  meta["frames"] = written;
  meta["stop_reason"] = sim::to_string(run.stop);
  meta["camera"] = camera_json(model, camera);
  meta["effects"] = effects_json(scene.effects);
  meta["gl"] = {{"backend", render::to_string(backend)}, {"description", gl}};
  meta["truth_columns"] = "frame,t,x,y,z,u,v";
  outputs.stage(meta_path, meta.dump(2) + "\n");
  outputs.commit();
  const double fps_rendered = seconds > 0 ? static_cast<double>(written) / seconds : 0.0;
  if (o.common.json) {
    Json j;
    j["space"] = "3d";
    j["frames"] = written;
    j["width"] = model.width;
    j["height"] = model.height;
    j["fps"] = model.fps;
    j["fps_rendered"] = number(fps_rendered);
    j["output"] = out.string();
    j["codec"] = mp4 ? Json(codec) : Json(nullptr);
    j["truth"] = truth_path.string();
    j["meta"] = meta_path.string();
    j["camera_file"] = camera_path.string();
    j["stop_reason"] = sim::to_string(run.stop);
    j["gl"] = {{"backend", render::to_string(backend)}, {"description", gl}};
    emit_json(j);
    return;
  }
  std::cout << "flatland render: " << scene.origin
            << (scene.name.empty() ? "" : " (" + scene.name + ")") << "\n"
            << "  camera             " << model.width << " x " << model.height << " px at "
            << format_number(model.fps) << " fps (spatial scene)\n"
            << "  frames             " << written << " written, run " << sim::to_string(run.stop)
            << " at t = " << format_number(run.final.t) << " s\n"
            << "  speed              " << format_number(std::round(fps_rendered * 10) / 10)
            << " frames/s (" << gl << ")\n"
            << "  wrote              " << out.string() << (mp4 ? " (" + codec + ")" : "") << ", "
            << truth_path.string() << ", " << meta_path.string() << ", " << camera_path.string()
            << "\n";
}

void run_render(const RenderOptions& o) {
  // ---- everything that can be bad input, before anything is computed or written
  Scene scene = load_scene_option(o.common, SceneSpaces::kPlanarOrSpatial);
  if (scene.spatial) return run_render_spatial(o, std::move(scene));
  api::apply_integrator_overrides(integrator_overrides(o.common), scene,
                                  api::Spelling::kCommandLine);
  if (!scene.camera)
    throw UsageError(scene.origin + ": camera: the scene has no camera section (needed by render)");
  sim::SimulationSpec& spec = scene.sim;
  const bool butterfly = spec.motion.kind == sim::MotionSpec::Kind::kButterfly;
  if (o.solve && !butterfly)
    throw UsageError("--solve: the scene's motion is not the butterfly (motion.type)");
  CameraSpec& camera = *scene.camera;
  apply_duration_and_fps(o, spec.duration, camera);
  if (o.view_opt->count()) scene.render.view = o.view;
  if (scene.render.view == "side") camera = side_camera(camera);
  if (o.gl_opt->count()) scene.render.backend = o.gl;
  const render::GlBackend backend = render::parse_backend(scene.render.backend);
  const std::shared_ptr<const model::Model> compiled = model::compile(scene);
  sim::resolve_formulation(*compiled->plant, spec.run.formulation);
  if (o.solve) sim::require_palm_and_back(spec.hand, *compiled->hand, "render --solve");
  // The frames the run will write, known before it runs: bounded, like every output.
  const double frames_wanted = std::floor((spec.end_time() - spec.initial.t0) * camera.fps) + 1;
  if (frames_wanted > kMaxRenderFrames)
    throw UsageError("--fps/--duration: " + format_number(frames_wanted) + " frames; at most " +
                     std::to_string(kMaxRenderFrames) +
                     " are rendered in one run (lower the duration or the rate)");

  const std::string out_text = o.common.out;
  if (out_text.empty()) throw UsageError("--out: required (FILE.mp4 or a directory)");
  const fs::path out = out_text;
  const std::string ext = lower(out.extension().string());
  const bool mp4 = ext == ".mp4" && out_text.back() != '/';
  for (const char* video : {".avi", ".mkv", ".mov", ".webm", ".gif", ".m4v"})
    if (ext == video)
      throw UsageError(
          "--out: only .mp4 video is written (any other --out is a directory of PNG "
          "frames), got " +
          out_text);
  if (mp4 && fs::is_directory(out))
    throw UsageError("--out: " + out_text + " is a directory; give a FILE.mp4 or a directory");
  // The MP4 comes with two files beside it; a PNG directory is replaced as a whole (with
  // --force), so that frames of an earlier, longer render cannot mix with this one's.
  if (mp4) {
    check_output_file("--out", out, o.common.force);
    check_output_file("--out", out.parent_path() / (out.stem().string() + ".truth.csv"),
                      o.common.force);
    check_output_file("--out", out.parent_path() / (out.stem().string() + ".json"), o.common.force);
    check_output_file("--out", out.parent_path() / (out.stem().string() + ".camera.yaml"),
                      o.common.force);
    check_output_file("--out", out.parent_path() / (out.stem().string() + ".encoder.csv"),
                      o.common.force);
    if (o.mask)
      check_output_directory("--mask", out.parent_path() / (out.stem().string() + ".masks"),
                             o.common.force);
  } else {
    check_output_directory("--out", out, o.common.force);
  }

  // The renderer validates the camera and effects (bad input) and makes the GL context (a
  // runtime failure), both before any file exists.
  const render::RenderSetup setup = model::render_setup(*compiled);
  if (o.mask && setup.boards.size() > static_cast<std::size_t>(render::kMaxMaskBoards))
    throw UsageError("--mask: the scene has " + std::to_string(setup.boards.size()) +
                     " targets; a mask's 8-bit ids tell at most " +
                     std::to_string(render::kMaxMaskBoards) + " boards apart");
  render::Renderer renderer(setup, backend);
  const camera::CameraModel& model = renderer.camera();
  const std::string gl = renderer.gl_description();

  // ---- outputs: the video (or the frame directory) first, so that a missing codec fails fast
  OutputSet outputs(o.common.force);
  const cv::Size size(model.width, model.height);
  const double fps = model.fps;
  fs::path truth_path, meta_path, camera_path, encoder_path, video_tmp, mask_dir;
  render::Mp4Writer writer;  // declared after `outputs`: released before its files are removed
  std::string codec;
  if (mp4) {
    outputs.ensure_directory(out.parent_path());
    video_tmp = outputs.reserve_keep_extension(out);
    codec = render::open_mp4(writer, video_tmp.string(), fps, size,
                             "cannot open an MP4 writer for " + out_text + ": ",
                             "; --out DIR writes PNG frames instead");
    const fs::path dir = out.parent_path();
    truth_path = dir / (out.stem().string() + ".truth.csv");
    meta_path = dir / (out.stem().string() + ".json");
    camera_path = dir / (out.stem().string() + ".camera.yaml");
    encoder_path = dir / (out.stem().string() + ".encoder.csv");
    if (o.mask) {
      mask_dir = dir / (out.stem().string() + ".masks");
      outputs.begin_directory(mask_dir);
    }
  } else {
    outputs.begin_directory(out);
    mask_dir = out;
    truth_path = out / "truth.csv";
    meta_path = out / "meta.json";
    camera_path = out / "camera.yaml";
    encoder_path = out / "encoder.csv";
  }

  // ---- simulate
  if (o.solve) {
    std::cerr << "flatland: solving k for 2T = " << format_number(spec.motion.period) << " s\n";
    const sim::SolveReport solved = sim::solve_k(spec, spec.motion.period);
    spec.motion.k = solved.k;
    std::cerr << "flatland: k = " << format_number(solved.k) << "\n";
  }
  std::cerr << "flatland: simulating " << scene.origin << " for "
            << format_number(spec.end_time() - spec.initial.t0) << " s\n";
  spec.run.record = true;  // the frames sample the dense output
  const sim::RunResult run = sim::run_spec(spec);
  sim::require_no_numerical_failure(run, "render");
  if (run.trajectory.empty()) throw std::runtime_error("the run recorded no trajectory");
  const double t0 = run.trajectory.t_begin(), t_end = run.trajectory.t_end();
  if (run.reason != sim::StopReason::kEndTime)
    std::cerr << "flatland: the run stopped at t = " << format_number(t_end) << " s ("
              << sim::to_string(run.reason) << "); rendering up to there\n";

  // ---- render
  const long n = static_cast<long>(std::floor((t_end - t0) * fps + 1e-9)) + 1;
  const sim::HandCurve& hand = *compiled->hand;
  // A readout other than global adds when each row's state holds (FrameTruth::t_state).
  const bool state_time = !setup.readout.global();
  const std::string truth_columns =
      std::string(kTruthColumns) + (state_time ? std::string(",") + kTruthStateColumn : "");
  std::string truth_csv = truth_columns + "\n";
  render::CaptureOptions capture_options;
  capture_options.mask = o.mask;
  long written = 0, dropped = 0;
  std::vector<unsigned char> png;
  std::cerr << "flatland: rendering " << n << " frames at " << format_number(fps) << " fps, "
            << model.width << " x " << model.height << " px (" << gl << ")\n";
  const auto start = std::chrono::steady_clock::now();
  {
    ProgressBar bar("render");
    for (long i = 0; i < n; ++i) {
      const double t = std::min(t0 + static_cast<double>(i) / fps, t_end);
      render::Frame frame = renderer.capture(run.trajectory, t, capture_options);
      if (frame.truth.dropped) {
        ++dropped;
        truth_csv += truth_row(-1, frame.truth, state_time);
        bar.update(i + 1, n);
        continue;
      }
      cv::Mat bgr = render::to_bgr8(frame.image);
      if (bgr.cols != size.width || bgr.rows != size.height)
        throw std::runtime_error("the renderer returned a " + std::to_string(bgr.cols) + " x " +
                                 std::to_string(bgr.rows) + " image for a " +
                                 std::to_string(size.width) + " x " + std::to_string(size.height) +
                                 " camera");
      if (o.overlay) {
        if (bgr.data == frame.image.data) bgr = bgr.clone();
        draw_overlay(bgr, model, hand, setup.object.radius, run.trajectory.sample(frame.truth.t),
                     frame.truth);
      }
      write_frame(bgr, written, mp4 ? &writer : nullptr, outputs, out, png);
      if (o.mask) write_png(frame.mask, "mask", written, outputs, mask_dir, png);
      truth_csv += truth_row(written, frame.truth, state_time);
      ++written;
      bar.update(i + 1, n);
    }
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double fps_rendered = seconds > 0 ? static_cast<double>(written) / seconds : 0.0;
  if (mp4) {
    writer.release();
    std::error_code ec;
    if (written > 0 && !(fs::file_size(video_tmp, ec) > 0))
      throw std::runtime_error("the MP4 writer (" + codec + ") produced no data for " + out_text);
  }

  // ---- ground truth and metadata, then everything into place
  outputs.stage(truth_path, truth_csv);
  // What flatland track needs to map these frames to s_h: the camera (with the table pose and
  // the joint: the hand pivots at the table origin, its encoder reads the true angle) and the
  // encoder log.
  camera::CameraFile camera_file;
  camera_file.camera_name = scene.name.empty() ? "flatland" : scene.name;
  camera_file.camera = model;
  camera_file.has_table_pose = true;
  camera_file.joint = camera::JointCalibration{};
  camera::write_camera_file(outputs.reserve(camera_path).string(), camera_file);
  outputs.stage(encoder_path, encoder_csv(run.trajectory));
  Json meta;
  meta["scene"] = scene.origin;
  meta["name"] = scene.name;
  meta["view"] = scene.render.view;
  meta["format"] = mp4 ? "mp4" : "png";
  meta["codec"] = mp4 ? Json(codec) : Json(nullptr);
  meta["output"] = out.string();
  meta["truth"] = truth_path.string();
  meta["camera_file"] = camera_path.string();
  meta["encoder"] = encoder_path.string();
  meta["frames"] = written;
  meta["dropped"] = dropped;
  meta["t_begin"] = t0;
  meta["t_end"] = t_end;
  meta["stop_reason"] = sim::to_string(run.reason);
  meta["model"] = sim::to_string(spec.run.model);
  meta["contact"] = contact_summary_json(run.stats.mode_time, run.stats.mode_changes,
                                         run.stats.impacts, run.events, run.initial);
  meta["motion"] = {{"type", butterfly ? "butterfly" : "fixed"},
                    {"period", butterfly ? number(spec.motion.period) : Json(nullptr)},
                    {"k", butterfly ? number(spec.motion.k) : Json(nullptr)},
                    {"solved", o.solve}};
  meta["camera"] = camera_json(model, camera);
  meta["effects"] = effects_json(scene.effects);
  meta["gl"] = {{"backend", render::to_string(backend)}, {"description", gl}};
  meta["overlay"] = o.overlay;
  meta["truth_columns"] = truth_columns;
  if (state_time || o.mask) {  // absent by default: the outputs of earlier versions unchanged
    meta["readout"] = {{"mode", setup.readout.mode}};
    if (setup.readout.mode == "interlaced") {
      meta["readout"]["field_order"] = setup.readout.field_order;
      meta["readout"]["field_interval_s"] = 0.5 / fps;
    } else if (setup.readout.mode == "rolling") {
      meta["readout"]["time_s"] = setup.readout.time;
      meta["readout"]["band_rows"] = setup.readout.band_rows;
    }
  }
  if (o.mask) {
    meta["mask"] = {{"directory", mask_dir.string()},
                    {"files", "mask_%06d.png"},
                    {"ids",
                     {{"background", int(render::kMaskBackground)},
                      {"table", int(render::kMaskTable)},
                      {"hand", int(render::kMaskHand)},
                      {"disk", int(render::kMaskDisk)},
                      {"first_board", int(render::kMaskFirstBoard)}}}};
  }
  outputs.stage(meta_path, meta.dump(2) + "\n");
  outputs.commit();

  if (o.common.json) {
    Json j;
    j["frames"] = written;
    j["dropped"] = dropped;
    j["width"] = model.width;
    j["height"] = model.height;
    j["fps"] = fps;
    j["fps_rendered"] = number(fps_rendered);
    j["view"] = scene.render.view;
    j["output"] = out.string();
    j["codec"] = mp4 ? Json(codec) : Json(nullptr);
    j["truth"] = truth_path.string();
    j["meta"] = meta_path.string();
    j["camera_file"] = camera_path.string();
    j["encoder"] = encoder_path.string();
    if (o.mask) j["masks"] = mask_dir.string();
    j["k"] = butterfly ? number(spec.motion.k) : Json(nullptr);
    j["gl"] = {{"backend", render::to_string(backend)}, {"description", gl}};
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland render: " << scene.origin << (scene.name.empty() ? "" : " (" + scene.name + ")")
     << "\n"
     << "  camera             " << scene.render.view << ", " << model.width << " x " << model.height
     << " px at " << format_number(fps) << " fps\n"
     << "  frames             " << written << " written, " << dropped
     << " dropped, t = " << format_number(t0) << " .. " << format_number(t_end) << " s\n"
     << "  speed              " << format_number(std::round(fps_rendered * 10) / 10)
     << " frames/s (" << gl << ")\n"
     << "  wrote              " << out.string() << (mp4 ? " (" + codec + ")" : "") << "\n"
     << "  wrote              " << truth_path.string() << "\n"
     << "  wrote              " << meta_path.string() << "\n"
     << (o.mask ? "  wrote              " + mask_dir.string() + "/mask_*.png\n" : "")
     << "  wrote              " << camera_path.string() << ", " << encoder_path.string()
     << " (for flatland track --camera --encoder)\n";
  std::cout << os.str();
}

}  // namespace

Command add_render_command(CLI::App& app) {
  auto o = std::make_shared<RenderOptions>();
  CLI::App* cmd = add_command(app, "render");
  add_common_options(*cmd, o->common,
                     "FILE.mp4: an H.264 video (MPEG-4 part 2 if H.264 cannot be encoded) with "
                     "FILE.truth.csv and FILE.json beside it; anything else: a directory of "
                     "frame_000000.png ... with truth.csv and meta.json, created if missing. "
                     "Required",
                     false);
  cmd->get_option("--out")->required();
  o->view_opt = cmd->add_option("--view", o->view,
                                "Camera: overhead (the scene's camera) or side (its intrinsics, "
                                "placed at [0, -1.2, 0.4] m looking at [0, 0, 0.05] m). Default: "
                                "the scene's render.view, else overhead")
                    ->check(CLI::IsMember({"overhead", "side"}));
  o->gl_opt = cmd->add_option("--gl", o->gl,
                              "OpenGL backend: osmesa (software, no GPU needed) or egl. Default: "
                              "the scene's render.backend, else osmesa")
                  ->check(CLI::IsMember({"osmesa", "egl"}));
  o->fps_opt = cmd->add_option("--fps", o->fps,
                               "Frame rate, frames per s (> 0; the frame interval must not be "
                               "shorter than camera.exposure). Default: the scene's camera.fps, "
                               "else 30");
  o->duration_opt = cmd->add_option("--duration", o->duration,
                                    "Simulated (and filmed) time, s (> 0). Default: the scene's "
                                    "duration, else 2T for the butterfly, else 1 s");
  cmd->add_flag(
      "--overlay", o->overlay,
      "Draw on each frame: t (s), s_h, and the hand's contact force as an arrow from the "
      "contact point (0.1 m on the table per in-plane weight m g sin(tilt)). Default: off");
  cmd->add_flag("--mask", o->mask,
                "Planar scenes: a segmentation mask beside each frame, mask_000000.png ... (8-bit, "
                "one id per body: 0 background, 1 table, 2 hand, 3 disk, 4 + i board i of the "
                "scene's targets; nearest sample, no effects; at the same rows' times as the "
                "frame), in the frame directory, or FILE.masks/ beside FILE.mp4. Default: off");
  cmd->add_flag("--solve", o->solve,
                "Butterfly only: first solve k for the scene's period (as `flatland solve`) and "
                "film that motion. Default: off (the scene's k)");
  return {cmd, [o] { run_render(*o); }};
}

}  // namespace flatland::app
