// flatland experiment: one closed-loop butterfly experiment (paper section 5, Fig. 10) against a
// synthetic world, a recording (replay) or a live camera; the 1 kHz log, the result, the plots of
// theta(t) and s_h(t) planned vs actual, optionally a video of what the loop saw and a recording.
#include "common.hpp"

#include "flatland/render/effects.hpp"
#include "flatland/render/overlay_text.hpp"

#include "flatland/control/choice.hpp"
#include "flatland/control/types.hpp"
#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/live.hpp"
#include "flatland/drivers/montecarlo.hpp"
#include "flatland/drivers/recorded.hpp"
#include "flatland/drivers/synthetic.hpp"
#include "flatland/drivers/tick_log_csv.hpp"
#include "flatland/render/video_writer.hpp"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <sstream>

namespace flatland::app {

namespace {

struct ExperimentOptions {
  CommonOptions common;
  std::string controller, estimator, camera = "synthetic", joint, record;
  bool video = false;
  CLI::Option* controller_opt = nullptr;
  CLI::Option* estimator_opt = nullptr;
  CLI::Option* joint_opt = nullptr;
};

enum class CameraKind { kSynthetic, kRecorded, kLive };

/// The plan as an inline gnuplot data block (t, theta, s_h every 5 ms over [0, duration]; comma
/// separated like the CSV, as the scripts set), so that the scripts need only log.csv beside them.
std::string plan_datablock(const control::Plan& plan) {
  std::string s = "$plan << EOD\n";
  const double T = plan.duration();
  const long n = static_cast<long>(std::ceil(T / 0.005));
  for (long i = 0; i <= n; ++i) {
    const double t = std::min(T, static_cast<double>(i) * 0.005);
    s += format_number(t) + ',' + format_number(plan.hand(t).angle) + ',' +
         format_number(plan.s_h_at(t)) + '\n';
  }
  return s + "EOD\n";
}

/// A frame the loop received, kept (JPEG in memory: ~100 kB instead of 0.9 MB raw) until the
/// loop's log can say what the estimate and stage were when it arrived.
struct KeptFrame {
  long index = 0;
  double t_capture = 0, t_arrival = 0;
  std::vector<unsigned char> jpeg;
  vision::TrackResult track;
  std::optional<double> s_meas;
};

/// --video overlay: time, stage, estimated and measured s_h, the tracked circle.
void draw_overlay(cv::Mat& bgr, const KeptFrame& f, const drivers::TickLog* row) {
  const double scale = std::max(0.35, bgr.rows / 960.0);
  const int thick = std::max(1, static_cast<int>(std::lround(2 * scale)));
  const cv::Scalar green(0, 220, 0), yellow(0, 220, 255), red(0, 0, 255), white(255, 255, 255),
      black(0, 0, 0);
  if (f.track.ok()) {
    const cv::Scalar colour = f.s_meas ? green : yellow;  // yellow: found but not mapped to s_h
    cv::circle(bgr, f.track.center, static_cast<int>(std::lround(f.track.radius_px)), colour, thick,
               cv::LINE_AA);
    cv::drawMarker(bgr, f.track.center, colour, cv::MARKER_CROSS, 8 * thick, thick, cv::LINE_AA);
  }
  char line[4][112];
  std::snprintf(line[0], sizeof line[0], "t = %.3f s (frame %ld captured %.3f s)",
                row ? row->t : f.t_arrival, f.index, f.t_capture);
  std::snprintf(line[1], sizeof line[1], "stage: %s", row ? row->mode.c_str() : "?");
  if (row && row->estimating)
    std::snprintf(line[2], sizeof line[2], "s_h estimated %+.4f", row->s_est);
  else
    std::snprintf(line[2], sizeof line[2], "s_h estimated: not yet");
  if (f.s_meas)
    std::snprintf(line[3], sizeof line[3], "s_h measured  %+.4f (at capture)", *f.s_meas);
  else
    std::snprintf(line[3], sizeof line[3], "s_h measured: %s",
                  f.track.ok() ? "disk found, not mapped" : "disk lost");
  // The text goes in the corner farthest from the tracked disk, so that it never hides it.
  std::vector<render::KeepClear> keep;
  if (f.track.ok()) keep.push_back({f.track.center, f.track.radius_px});
  render::draw_text_block(bgr, {line[0], line[1], line[2], line[3]}, 1.1 * scale, thick, keep,
                          {white, white, white, f.s_meas ? white : red});
}

/// Turn a driver's std::invalid_argument into one naming the option (exit 2 either way).
[[noreturn]] void rethrow_for_option(const std::string& option, const std::invalid_argument& e) {
  const std::string what = e.what();
  if (what.rfind(option, 0) == 0) throw UsageError(what);
  if (what.rfind(option.substr(2) + " ", 0) == 0) throw UsageError("--" + what);
  throw UsageError(option + ": " + what);
}

Json nullable(const std::string& s) { return s.empty() ? Json(nullptr) : Json(s); }

void run_experiment(const ExperimentOptions& o) {
  // ---- everything that can be bad input, before anything is computed or written
  CommonOptions common = o.common;
  if (common.scene.empty()) common.scene = default_experiment_scene();
  Scene scene = load_scene_with_overrides(common);
  // --controller: what Monte Carlo accepts (open-loop, feedback or a built-in type), the same way.
  if (o.controller_opt->count()) {
    try {
      scene = drivers::scene_for_controller(scene, o.controller, "--controller");
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
  }
  if (o.estimator_opt->count()) {
    const auto& types = control::estimator_types();
    if (std::find(types.begin(), types.end(), o.estimator) == types.end())
      throw UsageError(control::unknown_type_message("--estimator", o.estimator, types));
    scene.estimator.type = o.estimator;
  }
  // What the run is called: the controller as asked for, else the scene's mode.
  const std::string controller_label =
      o.controller_opt->count() ? o.controller : scene.controller.mode;

  CameraKind kind;
  if (o.camera == "synthetic")
    kind = CameraKind::kSynthetic;
  else if (o.camera.rfind("video:", 0) == 0)
    kind = CameraKind::kRecorded;
  else if (o.camera.rfind("v4l2:", 0) == 0)
    kind = CameraKind::kLive;
  else
    throw UsageError("--camera: unknown camera '" + o.camera +
                     "' (synthetic, video:FILE or video:DIR, v4l2:N)");
  const bool joint_given = o.joint_opt->count() > 0;
  const std::string joint_spec = joint_given ? o.joint : "synthetic";
  if (joint_spec != "synthetic" && joint_spec.rfind("log:", 0) != 0)
    throw UsageError("--joint: unknown joint '" + joint_spec + "' (synthetic or log:DIR)");
  const bool log_joint = joint_spec != "synthetic";
  if (kind == CameraKind::kSynthetic && log_joint)
    throw UsageError("--joint: " + joint_spec +
                     " replays a recorded joint, which needs a recorded or live --camera; a "
                     "synthetic camera films the simulated joint");
  if (kind == CameraKind::kRecorded && !log_joint)
    throw UsageError("--joint: a recorded camera (--camera " + o.camera +
                     ") is replayed with its recorded joint: give --joint log:DIR");
  // Checked before the device is opened: there is nothing to run it with.
  if (kind == CameraKind::kLive && !log_joint)
    throw UsageError("--joint: no live joint driver exists yet; a live camera (--camera " +
                     o.camera + ") can only run against a recorded joint, --joint log:DIR");

  if (o.common.out.empty()) throw UsageError("--out: required (a directory)");
  const fs::path out = o.common.out;
  check_output_directory("--out", out, o.common.force);
  if (!o.record.empty()) {
    const fs::path rec = fs::absolute(o.record).lexically_normal();
    const fs::path dir = fs::absolute(out).lexically_normal();
    if (std::mismatch(dir.begin(), dir.end(), rec.begin(), rec.end()).first == dir.end())
      throw UsageError("--record: " + o.record + " must not be --out or inside it (" +
                       o.common.out + ")");
    check_output_directory("--record", o.record, o.common.force);
    // --force would replace the recording being replayed while it is read.
    for (const std::string& source : {o.camera, o.joint}) {
      const auto colon = source.find(':');
      if (colon == std::string::npos) continue;
      const fs::path src = fs::absolute(source.substr(colon + 1)).lexically_normal();
      if (std::mismatch(rec.begin(), rec.end(), src.begin(), src.end()).first == rec.end())
        throw UsageError("--record: " + o.record + " is the recording being replayed (" + source +
                         ")");
    }
  }

  // The loop's own view of the experiment (plan, mapping, estimator, controller): bad scene
  // fields are std::invalid_argument here.
  const std::shared_ptr<const model::Model> nominal = model::compile(scene);
  const drivers::LoopSetup setup(nominal);
  const control::Plan& plan = *setup.plan.plan;
  if (kind == CameraKind::kSynthetic) drivers::require_friction(scene);

  // The drivers: a bad --camera/--joint is bad input (missing recording, no such device).
  drivers::LoopOptions loop_options;
  // A live clock starts |t_start| s before t = 0, so that the hand's wait is real time too.
  const auto live_start = std::chrono::steady_clock::now() +
                          std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                              std::chrono::duration<double>(-loop_options.t_start));
  std::unique_ptr<drivers::Camera> camera;
  std::unique_ptr<drivers::Joint> joint;
  if (kind != CameraKind::kSynthetic) {
    try {
      camera = drivers::open_camera(o.camera, live_start);
    } catch (const std::invalid_argument& e) {
      rethrow_for_option("--camera", e);
    }
    try {
      joint = drivers::open_joint(joint_spec);
    } catch (const std::invalid_argument& e) {
      rethrow_for_option("--joint", e);
    }
  }
  auto* log_joint_driver = dynamic_cast<drivers::LogJoint*>(joint.get());

  const bool plots = !o.common.no_plot;
  if (plots) require_gnuplot();

  // ---- outputs: the directory and the video writer first, so that a missing codec fails fast
  OutputSet outputs(o.common.force);
  outputs.begin_directory(out);
  const CameraSpec& cam = *scene.camera;
  const cv::Size size(cam.width, cam.height);
  render::Mp4Writer writer;  // after `outputs`: released before its files are removed
  fs::path video_tmp;
  std::string codec;
  if (o.video) {
    video_tmp = outputs.reserve_keep_extension(out / "video.mp4");
    codec = render::open_mp4(writer, video_tmp.string(), cam.fps, size,
                             "--video: cannot open an MP4 writer: ");
  }

  // The recording (its own atomic directory; finished only when the run completed).
  std::unique_ptr<drivers::Recorder> recorder;
  if (!o.record.empty()) {
    drivers::RecordingMetadata meta;
    meta.rate_hz = scene.joint.rate;
    meta.camera = camera ? camera->describe() : "synthetic";
    meta.joint = joint ? joint->describe() : "simulated";
    meta.scene = scene.origin;
    try {
      // The recorder builds its directory itself (with its own partial directory beside it):
      // both live inside a registered staging root, so that an interruption removes them and
      // commit() moves (or, with --force, swaps) the finished recording into place.
      recorder = std::make_unique<drivers::Recorder>(outputs.begin_directory(o.record, true), meta);
    } catch (const std::invalid_argument& e) {
      rethrow_for_option("--record", e);
    }
  }

  // ---- run
  std::vector<KeptFrame> kept;
  std::vector<int> jpeg_params = {cv::IMWRITE_JPEG_QUALITY, 95};
  auto on_frame = [&](const drivers::CameraFrame& f, const vision::TrackResult& tr,
                      const std::optional<control::Measurement>& z) {
    if (!o.video) return;
    KeptFrame k;
    k.index = f.index;
    k.t_capture = f.t_capture;
    k.t_arrival = f.t_arrival;
    k.track = tr;
    if (z) k.s_meas = z->s_h;
    // An unreadable frame keeps its place in the video as a black picture.
    const cv::Mat picture =
        f.image.empty() ? cv::Mat(size, CV_8UC3, cv::Scalar::all(0)) : render::to_bgr8(f.image);
    if (!cv::imencode(".jpg", picture, k.jpeg, jpeg_params))
      throw std::runtime_error("--video: cannot encode frame " + std::to_string(f.index));
    kept.push_back(std::move(k));
  };
  std::optional<ProgressBar> bar;
  bar.emplace("experiment");
  const double t_start = loop_options.t_start;
  auto progress = [&](double t, double t_end) {
    double total = t_end - t_start;
    if (log_joint_driver) total = static_cast<double>(log_joint_driver->ticks()) / scene.joint.rate;
    const long total_ms = std::max(1L, std::lround(1000 * total));
    bar->update(std::min(total_ms, std::lround(1000 * (t - t_start))), total_ms);
  };

  std::cerr << "flatland: " << controller_label << " experiment, " << scene.origin << ", camera "
            << (camera ? camera->describe() : "synthetic") << ", joint "
            << (joint ? joint->describe() : "simulated") << "\n";
  const auto start = std::chrono::steady_clock::now();
  drivers::LoopResult loop;
  std::optional<drivers::SyntheticResult> synthetic;
  if (kind == CameraKind::kSynthetic) {
    drivers::SyntheticOptions so;
    so.recorder = recorder.get();
    so.on_frame = on_frame;
    so.progress = progress;
    synthetic = drivers::run_synthetic(setup, nominal, so);
    loop = synthetic->loop;
  } else {
    loop_options.recorder = recorder.get();
    loop_options.on_frame = on_frame;
    loop_options.progress = progress;
    if (log_joint_driver) loop_options.max_ticks = log_joint_driver->ticks();
    if (kind == CameraKind::kLive) {
      drivers::SteadyClock clock(live_start);
      loop = drivers::run_loop(setup, clock, *camera, *joint, loop_options);
    } else {
      drivers::SimClock clock(nullptr, t_start);  // replay: time is the log's, not the wall's
      loop = drivers::run_loop(setup, clock, *camera, *joint, loop_options);
    }
  }
  bar.reset();
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // ---- video, log, plots, result
  if (o.video) {
    for (const KeptFrame& k : kept) {
      // The tick that received the frame: the first at or after its arrival.
      const auto it = std::lower_bound(loop.log.begin(), loop.log.end(), k.t_arrival,
                                       [](const drivers::TickLog& r, double t) { return r.t < t; });
      const drivers::TickLog* row = it != loop.log.end() ? &*it : nullptr;
      cv::Mat bgr = cv::imdecode(k.jpeg, cv::IMREAD_COLOR);
      if (bgr.empty()) throw std::runtime_error("--video: cannot decode kept frame");
      if (bgr.size() != size) cv::resize(bgr, bgr, size);  // a recording from another camera
      draw_overlay(bgr, k, row);
      writer.write(bgr);
    }
    writer.release();
    std::error_code ec;
    if (!kept.empty() && !(fs::file_size(video_tmp, ec) > 0))
      throw std::runtime_error("--video: the MP4 writer (" + codec + ") produced no data");
  }
  outputs.stage(out / "log.csv", drivers::tick_log_csv(loop.log));
  outputs.stage(out / "frames.csv", drivers::frame_log_csv(loop.frame_log));
  if (plots) {
    const auto col = [](const char* name) {
      return std::to_string(drivers::tick_log_column_index(name));
    };
    const std::string t = col("t");
    const std::string title =
        gnuplot_quote(scene.controller.mode + " experiment (paper Fig. 10): planned vs actual");
    run_plot(outputs, out,
             {"theta.gp", "log.csv", "theta.png",
              plan_datablock(plan) + "set title " + title +
                  "\nset grid\nset key bottom right\nset xlabel 't (s)'\n"
                  "set ylabel 'hand angle theta (rad)'\n"
                  "plot $plan using 1:2 with lines lw 2 dt 2 lc 'black' title 'planned', \\\n"
                  "     datafile skip 1 using " +
                  t + ":" + col("theta") + " with lines lw 2 lc 'red' title 'actual (encoder)'\n"});
    // Drawn so that each stays visible: the truth thick and light underneath, the estimate thin on
    // top of it, the plan dashed, each measurement at the time its frame was captured (the loop
    // gets it a latency later).
    std::string s_plot = plan_datablock(plan) + "set title " + title +
                         "\nset grid\nset key bottom right\nset xlabel 't (s)'\n"
                         "set ylabel 'contact parameter s_h'\n"
                         "set yrange [-1.2:1.2]\nplot ";
    if (synthetic)
      s_plot += "datafile skip 1 using " + t + ":" + col("s_true") +
                " with lines lw 9 lc rgb '#a0d8a0' title 'true', \\\n     ";
    s_plot +=
        "$plan using 1:3 with lines lw 2 dt 2 lc 'black' title 'planned', \\\n"
        "     datafile skip 1 using " +
        t + ":(column(" + col("estimating") + ") == 1 ? column(" + col("s_est") +
        ") : 1/0) with lines lw 1.5 lc 'red' title 'estimated', \\\n"
        "     datafile skip 1 using " +
        col("t_capture") + ":(column(" + col("measured") + ") == 1 ? column(" + col("s_meas") +
        ") : 1/0) with points pt 6 ps 0.5 lc 'blue' title 'measured (at capture time)'";
    run_plot(outputs, out, {"s_h.gp", "log.csv", "s_h.png", s_plot + "\n"});
  }

  const bool truth = synthetic.has_value();
  Json j;
  j["success"] = truth ? Json(synthetic->success) : Json(nullptr);
  j["duration_s"] = number(loop.duration_s);
  j["s_end"] = truth ? number(synthetic->s_end) : Json(nullptr);
  j["fn_min_ratio"] = truth ? number(synthetic->fn_min_ratio) : Json(nullptr);
  j["mu_max"] = truth ? number(synthetic->mu_max) : Json(nullptr);
  j["frames"] = loop.frames;
  j["frames_lost"] = loop.frames_lost;
  j["frames_damaged"] = loop.frames_damaged;
  j["frames_repeated"] = loop.frames_repeated;
  j["frames_unreadable"] = loop.frames_unreadable;
  j["safe_stop"] = loop.safe_stop;
  j["stop_reason"] = loop.stop_reason ? Json(loop.stop_reason->detail) : Json(nullptr);
  j["failure"] = truth ? nullable(synthetic->failure) : Json(nullptr);
  j["finished"] = loop.finished;
  j["k"] = number(loop.k);
  j["period"] = number(loop.period);
  j["controller"] = controller_label;
  j["controller_type"] = loop.controller;  // what ran: Controller::name(), Estimator::name()
  j["estimator"] = loop.estimator;
  j["camera"] = camera ? camera->describe() : "synthetic";
  j["joint"] = joint ? joint->describe() : "simulated";
  j["nees_mean"] = truth ? number(synthetic->nees_mean) : Json(nullptr);
  j["measurements"] = loop.measurements;
  j["estimator_steps"] = loop.estimator_steps;
  // The estimator propagates with what the joint did: its ticks by where the hand's acceleration
  // came from (the read rates' change, or the command where the readings gave none).
  j["hand_acceleration"] = {{"readings", loop.acceleration_from_readings},
                            {"command", loop.acceleration_from_command}};
  j["ticks"] = static_cast<long>(loop.log.size());
  j["t_stage2"] = loop.t_stage2 ? number(*loop.t_stage2) : Json(nullptr);
  j["t_stage3"] = loop.t_stage3 ? number(*loop.t_stage3) : Json(nullptr);
  j["outcome"] = truth ? Json(drivers::to_string(synthetic->outcome)) : Json(nullptr);
  if (truth) {
    j["frames_rendered"] = synthetic->frames_rendered;
    j["frames_dropped"] = synthetic->frames_dropped;
    // What the disk did on the hand (the world is the hybrid model): time sliding and flying,
    // each flight's landing and impulse.
    sim::Sample start;
    start.t = loop.log.empty() ? 0.0 : loop.log.front().t;
    j["contact"] = contact_summary_json(synthetic->mode_time, synthetic->mode_changes,
                                        synthetic->impacts, synthetic->contact_events, start);
    // The world's own energy audit: every servo period's run balances within its bound.
    j["world_energy"] = {{"worst_balance", number(synthetic->energy_worst)},
                         {"bound", number(synthetic->energy_worst_bound)}};
  } else {
    j["contact"] = nullptr;
    j["world_energy"] = nullptr;
  }
  if (log_joint_driver)
    j["replay"] = {{"ticks", log_joint_driver->ticks()},
                   {"ticks_read", log_joint_driver->ticks_read()},
                   {"command_mismatches", log_joint_driver->mismatches()},
                   {"first_mismatch_tick", log_joint_driver->first_mismatch_tick()},
                   {"max_command_difference", number(log_joint_driver->max_command_difference())}};
  else
    j["replay"] = nullptr;
  j["scene"] = scene.origin;
  j["seconds"] = number(seconds);
  j["recording"] = o.record.empty() ? Json(nullptr) : Json(o.record);
  j["video"] = o.video ? Json((out / "video.mp4").string()) : Json(nullptr);
  j["codec"] = o.video ? Json(codec) : Json(nullptr);
  j["out"] = out.string();
  outputs.stage(out / "result.json", j.dump(2) + "\n");

  // The recording first: if it cannot be finished, the run's outputs are removed too.
  if (recorder) recorder->finish();
  outputs.commit();

  if (o.common.json) {
    emit_json(j);
    return;
  }
  const auto opt = [](const Json& v, const std::string& unit = "") {
    return v.is_null() ? std::string("n/a")
                       : (v.is_string() ? v.get<std::string>() : v.dump()) + unit;
  };
  std::ostringstream os;
  os << "flatland experiment: " << scene.origin << " (" << controller_label << ": controller "
     << loop.controller << ", estimator " << loop.estimator << ")\n"
     << "  success            " << opt(j["success"])
     << (truth && !synthetic->success ? " (" + synthetic->failure + ")" : "") << "\n"
     << "  duration           " << opt(j["duration_s"], " s") << "\n"
     << "  s_h at the end     " << opt(j["s_end"]) << "\n"
     << "  min f_n            " << opt(j["fn_min_ratio"], " m g sin(tilt)") << "\n"
     << "  max mu required    " << opt(j["mu_max"]) << " (while rolling)\n";
  if (truth) {
    const auto& m = synthetic->mode_time;
    os << "  contact            sliding " << format_number(std::round(m[2] * 1e4) / 1e4)
       << " s, flight " << format_number(std::round(m[3] * 1e4) / 1e4) << " s, "
       << synthetic->impacts << " impacts, " << synthetic->mode_changes << " mode changes\n";
    for (const Json& f : j["contact"]["flights"])
      os << "  flight             leaves at t = " << opt(f["t_lift_off"], " s")
         << ", lands at t = " << opt(f["t_landing"], " s") << " on s_h = " << opt(f["s_landing"])
         << ", impulse " << opt(f["impulse_normal"], " N s")
         << (f["dropped"].get<bool>() ? ", dropped" : "") << "\n";
  }
  os << "  frames             " << loop.frames << " received, " << loop.frames_lost
     << " not usable (" << loop.frames_damaged << " damaged, " << loop.frames_repeated
     << " repeated, " << loop.frames_unreadable << " unreadable), " << loop.measurements
     << " measurements\n"
     << "  safe stop          "
     << (loop.stop_reason ? "yes (" + loop.stop_reason->detail + ")" : "no") << "\n";
  if (log_joint_driver)
    os << "  replay             " << log_joint_driver->mismatches()
       << " commands differ from the log\n";
  for (const std::string& p : outputs.paths()) os << "  wrote              " << p << "\n";
  if (recorder) os << "  recorded           " << o.record << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_experiment_command(CLI::App& app) {
  auto o = std::make_shared<ExperimentOptions>();
  CLI::App* cmd = add_command(app, "experiment");
  add_common_options(
      *cmd, o->common,
      "Directory for log.csv, frames.csv, result.json, theta.png, s_h.png (+ their .gp "
      "scripts) and, with --video, video.mp4; created, and refused if it exists "
      "and is not empty. Required",
      true);
  cmd->get_option("--out")->required();
  cmd->get_option("--scene")->description(
      "Scene file (YAML, SI units; schema in docs/SCENE.md). Default: the bundled closed-loop "
      "scene, " +
      default_experiment_scene());
  std::string controllers, estimators;
  for (const std::string& t : control::controller_types()) controllers += ", " + t;
  for (const std::string& t : control::estimator_types())
    estimators += (estimators.empty() ? "" : ", ") + t;
  o->controller_opt =
      cmd->add_option("--controller", o->controller,
                      "open-loop (plays the paper's plan), feedback (the scene's controller.type "
                      "with vision feedback) or a controller type in feedback mode (" +
                          controllers.substr(2) +
                          "). Default: the scene's controller.type and controller.mode")
          ->type_name("NAME");
  o->estimator_opt = cmd->add_option("--estimator", o->estimator,
                                     "The contact estimator's type (" + estimators +
                                         "; docs/ESTIMATOR.md). Default: the scene's "
                                         "estimator.type")
                         ->type_name("NAME");
  cmd->add_option("--camera", o->camera,
                  "synthetic (render the simulated world), video:DIR or video:FILE (replay a "
                  "recording, or a video with FILE.timestamps.csv), v4l2:N (live /dev/videoN). "
                  "Default: synthetic")
      ->type_name("SPEC");
  o->joint_opt = cmd->add_option("--joint", o->joint,
                                 "synthetic (the simulated joint) or log:DIR (a recorded joint "
                                 "log; required with a recorded camera). Default: synthetic for "
                                 "a synthetic camera")
                     ->type_name("SPEC");
  cmd->add_option("--record", o->record,
                  "Record what the loop saw and commanded (frames, joint readings, commands) to "
                  "this directory for replay (docs/RECORDING.md); refused if it exists and is not "
                  "empty. Default: no recording")
      ->type_name("DIR");
  cmd->add_flag("--video", o->video,
                "Also write DIR/video.mp4 (H.264) of the frames the loop received, with t (s), "
                "the controller's stage, the estimated and measured s_h and the tracked circle "
                "drawn on them. Default: off");
  return {cmd, [o] { run_experiment(*o); }};
}

}  // namespace flatland::app
