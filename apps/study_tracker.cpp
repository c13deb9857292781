// flatland study tracker: the disk tracker's speed-accuracy trade. The scene's motion is simulated
// once and filmed by its camera at several exposure times (motion blur); every frame gets read
// noise at several levels (the same random numbers scaled, so that levels differ only in size);
// every tracking method follows each sequence from its first frame. Centre error against the
// renderer's truth (px, and mm on the table through the camera), per-frame latency (wall) and
// lost frames per (method, exposure, noise).
#include "study_vision.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <sstream>
#include <tuple>

namespace flatland::app {

namespace {

/// A tracked centre this far from the truth is a wrong lock, not an inaccuracy.
constexpr double kGrossErrorPx = 2.0;

struct MethodSpec {
  std::string name;  // CSV/JSON label
  vision::TrackMethod method;
  bool table_plane;  // the edge fit on the table plane (the camera known), as `flatland track`
};

struct BlurLevel {
  double fraction = 0;  // of the frame interval
  double exposure = 0;  // s
  int subframes = 1;
  double px_mean = 0, px_max = 0;  // streak of the disk centre over the exposure
  // The mean of the sub-frames' projected centres minus the projected centre at mid-exposure
  // (the truth): what a perfect tracker of the smeared disk is off by, from the motion's
  // acceleration and curvature over the exposure. RMS and max over the frames.
  double shift_rms = 0, shift_max = 0;
};

struct Cell {
  std::size_t method = 0, blur = 0, noise = 0;
  int frames = 0, lost = 0, reacquired = 0, gross = 0;
  std::vector<double> err_px, err_mm, ms;
  double rms_px = NAN, max_px = NAN, rms_mm = NAN, max_mm = NAN;
  double ms_median = NAN, ms_p95 = NAN, ms_max = NAN;
};

double rms(const std::vector<double>& v) {
  if (v.empty()) return std::nan("");
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / static_cast<double>(v.size()));
}

double max_of(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::max_element(v.begin(), v.end());
}

/// The projected disk centre's path length (px) over [t - e/2, t + e/2].
double streak_px(const camera::CameraModel& cam, const sim::Trajectory& tr, double z, double t,
                 double exposure) {
  if (exposure <= 0) return 0;
  double len = 0;
  cv::Point2d last;
  for (int i = 0; i <= 16; ++i) {
    const double ts =
        std::clamp(t - 0.5 * exposure + exposure * i / 16.0, tr.t_begin(), tr.t_end());
    const auto c = tr.sample(ts).object_position;
    const cv::Point2d p = cam.project(cv::Point3d(c.x(), c.y(), z));
    if (i > 0) len += cv::norm(p - last);
    last = p;
  }
  return len;
}

/// |mean of the projected centres at the renderer's sub-frame times - projected centre at t| (px).
double subframe_shift_px(const camera::CameraModel& cam, const sim::Trajectory& tr, double z,
                         double t, double exposure, int subframes) {
  auto at = [&](double ts) {
    const auto c = tr.sample(std::clamp(ts, tr.t_begin(), tr.t_end())).object_position;
    return cam.project(cv::Point3d(c.x(), c.y(), z));
  };
  if (exposure <= 0 || subframes <= 1) return 0;
  cv::Point2d mean(0, 0);
  for (int i = 0; i < subframes; ++i)  // as Renderer::capture spaces them
    mean += at(t - 0.5 * exposure + (i + 0.5) * exposure / subframes) * (1.0 / subframes);
  return cv::norm(mean - at(t));
}

Json tracker_defaults_json() {
  const vision::TrackerConfig d;
  Json j;
  j["edge_radius_px"] = d.edge_radius_px;
  j["rays"] = d.rays;
  j["ray_step_px"] = d.ray_step_px;
  j["edge_area_window_px"] = d.edge_area_window_px;
  j["roi_margin_px"] = d.roi_margin_px;
  j["min_inlier_fraction"] = d.min_inlier_fraction;
  j["max_radius_change"] = d.max_radius_change;
  j["min_contrast_dn"] = d.min_contrast_dn;
  return j;
}

const char* kTrackerColumns =
    "method,fit,blur_level,exposure_s,blur_subframes,blur_px_mean,blur_px_max,noise_dn,frames,"
    "lost,reacquired,gross,err_rms_px,err_max_px,err_rms_mm,err_max_mm,latency_median_ms,"
    "latency_p95_ms,latency_max_ms\n";

}  // namespace

void run_tracker_study(const StudyOptions& o) {
  // ---- everything that can be bad input, before anything is computed or written
  Scene scene = load_camera_scene(o, "tracker");
  sim::SimulationSpec spec = scene.sim;
  build_problem_checked(spec, {});
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  const std::vector<MethodSpec> methods = {{"edge", vision::TrackMethod::kEdge, false},
                                           {"edge-plane", vision::TrackMethod::kEdge, true},
                                           {"moments", vision::TrackMethod::kMoments, false},
                                           {"hough", vision::TrackMethod::kHough, false}};
  const std::vector<double> noises =
      o.quick ? std::vector<double>{0, 2, 8, 32} : std::vector<double>{0, 1, 2, 4, 8, 16, 32, 64};
  const std::vector<double> fractions =
      o.quick ? std::vector<double>{0, 1} : std::vector<double>{0, 0.25, 0.5, 1};
  const int stride = o.quick ? 3 : 1;  // every stride-th frame of the camera's rate
  const std::uint64_t seed = scene.effects.seed;
  const double z = scene.render.disk_thickness;
  const double fps = scene.camera->fps;

  const double load_start = load_average_1min();
  const auto wall0 = std::chrono::steady_clock::now();
  spec.run.record = true;  // the frames sample the dense output
  const sim::RunResult run = sim::run_spec(spec);
  if (run.trajectory.empty()) throw std::runtime_error("study tracker: the run recorded nothing");
  const sim::Trajectory& tr = run.trajectory;
  std::vector<double> times;
  for (int k = 0;; ++k) {
    const double t = tr.t_begin() + k * stride / fps;
    if (t > tr.t_end() + 1e-9) break;
    times.push_back(std::min(t, tr.t_end()));
  }
  if (times.size() < 3)
    throw UsageError(scene.origin + ": study tracker: the run (" +
                     format_number(tr.t_end() - tr.t_begin()) + " s) gives fewer than 3 frames");

  const camera::CameraModel cam0 = flatland::model::compile_camera(*scene.camera);
  std::vector<BlurLevel> blurs;
  for (double f : fractions) {
    BlurLevel b;
    b.fraction = f;
    b.exposure = f / fps;
    for (double t : times) {
      const double s = streak_px(cam0, tr, z, t, b.exposure);
      b.px_mean += s / static_cast<double>(times.size());
      b.px_max = std::max(b.px_max, s);
    }
    // Sub-frames at most ~1 px of motion apart, so that the blur is a smear and not a row of
    // ghosts (the renderer's limit is 64; 16 keeps the study's cost bounded).
    b.subframes = b.exposure > 0 ? std::clamp(static_cast<int>(std::ceil(b.px_max)) + 1, 2, 16) : 1;
    for (double t : times) {
      const double d = subframe_shift_px(cam0, tr, z, t, b.exposure, b.subframes);
      b.shift_rms += d * d / static_cast<double>(times.size());
      b.shift_max = std::max(b.shift_max, d);
    }
    b.shift_rms = std::sqrt(b.shift_rms);
    blurs.push_back(b);
  }
  std::cerr << "flatland: study tracker: " << methods.size() << " methods x " << blurs.size()
            << " exposures x " << noises.size() << " noise levels, " << times.size()
            << " frames each (" << scene.origin << ", " << scene.camera->width << " x "
            << scene.camera->height << ", supersample " << scene.effects.supersample << ")\n";

  std::vector<Cell> cells;
  std::string gl;
  {
    ProgressBar bar("study tracker");
    long done = 0;
    const long total = static_cast<long>(blurs.size() * times.size());
    for (std::size_t bi = 0; bi < blurs.size(); ++bi) {
      const BlurLevel& b = blurs[bi];
      // The scene's camera, supersampling and vignetting; the exposure of this level; float
      // frames without noise (added below per level), jitter or drops.
      Scene s = scene;
      s.camera->exposure = b.exposure;
      s.effects.blur_subframes = b.subframes;
      s.effects.noise_read_dn = 0;
      s.effects.noise_shot_gain = 0;
      s.effects.quantize = false;
      s.effects.jitter_s = 0;
      s.effects.drop_probability = 0;
      render::Renderer renderer(model::compile(std::move(s)));
      gl = renderer.gl_description();
      // One noise stream per level, all seeded alike: a frame's noise is the same normal
      // variates times sigma at every level (common random numbers), at every exposure too.
      std::vector<render::EffectsRng> rngs(noises.size(), render::EffectsRng(seed));
      std::vector<std::vector<vision::Tracker>> trackers(noises.size());
      const std::size_t first = cells.size();
      for (std::size_t ni = 0; ni < noises.size(); ++ni)
        for (std::size_t mi = 0; mi < methods.size(); ++mi) {
          vision::TrackerConfig cfg;  // the library's defaults (reported in the JSON)
          cfg.method = methods[mi].method;
          if (methods[mi].table_plane) {
            cfg.camera = renderer.camera();
            cfg.plane_z = z;
          }
          trackers[ni].emplace_back(cfg);
          Cell c;
          c.method = mi;
          c.blur = bi;
          c.noise = ni;
          cells.push_back(std::move(c));
        }
      for (std::size_t k = 0; k < times.size(); ++k) {
        const render::Frame f = renderer.capture(tr, times[k]);
        for (std::size_t ni = 0; ni < noises.size(); ++ni) {
          cv::Mat noisy = f.image.clone();
          render::apply_noise(noisy, noises[ni], 0, rngs[ni]);
          const cv::Mat image = render::quantize(noisy);
          for (std::size_t mi = 0; mi < methods.size(); ++mi) {
            Cell& c = cells[first + ni * methods.size() + mi];
            const auto t0 = std::chrono::steady_clock::now();
            const vision::TrackResult r = trackers[ni][mi].track(image);
            c.ms.push_back(
                1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
            ++c.frames;
            if (!r.ok()) {
              ++c.lost;
              continue;
            }
            if (r.state == vision::TrackState::kFound && k > 0) ++c.reacquired;
            const double e = cv::norm(r.center - f.truth.disk_center_px);
            c.err_px.push_back(e);
            if (e > kGrossErrorPx) ++c.gross;
            const auto p = vision::pixel_to_table(renderer.camera(), r.center, z);
            const cv::Point3d& truth = f.truth.disk_center_table;
            c.err_mm.push_back(p ? 1e3 * std::hypot(p->x - truth.x, p->y - truth.y) : std::nan(""));
          }
        }
        bar.update(++done, total);
      }
    }
  }
  // Each curve of the plots (a method at an exposure, against noise) as consecutive rows: gnuplot
  // breaks a line at every row its filter skips.
  std::sort(cells.begin(), cells.end(), [](const Cell& a, const Cell& b) {
    return std::tie(a.method, a.blur, a.noise) < std::tie(b.method, b.blur, b.noise);
  });
  for (Cell& c : cells) {
    c.rms_px = rms(c.err_px);
    c.max_px = max_of(c.err_px);
    c.rms_mm = rms(c.err_mm);
    c.max_mm = max_of(c.err_mm);
    c.ms_max = max_of(c.ms);
    c.ms_p95 = quantile(c.ms, 0.95);
    c.ms_median = quantile(c.ms, 0.5);
  }
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double load_end = load_average_1min();

  std::string csv = kTrackerColumns;
  Json rows = Json::array();
  for (const Cell& c : cells) {
    const MethodSpec& m = methods[c.method];
    const BlurLevel& b = blurs[c.blur];
    std::string line =
        m.name + (m.table_plane ? ",table-plane," : ",pixel,") + std::to_string(c.blur);
    for (double v : {b.exposure, static_cast<double>(b.subframes), b.px_mean, b.px_max,
                     noises[c.noise], static_cast<double>(c.frames), static_cast<double>(c.lost),
                     static_cast<double>(c.reacquired), static_cast<double>(c.gross), c.rms_px,
                     c.max_px, c.rms_mm, c.max_mm, c.ms_median, c.ms_p95, c.ms_max}) {
      line += ',';
      line += format_number(v);
    }
    csv += line + "\n";
    Json q;
    q["method"] = m.name;
    q["fit"] = m.table_plane ? "table-plane" : "pixel";
    q["exposure_s"] = b.exposure;
    q["blur_px_max"] = b.px_max;
    q["noise_dn"] = noises[c.noise];
    q["frames"] = c.frames;
    q["lost"] = c.lost;
    q["reacquired"] = c.reacquired;
    q["gross"] = c.gross;
    q["err_rms_px"] = number(c.rms_px);
    q["err_max_px"] = number(c.max_px);
    q["err_rms_mm"] = number(c.rms_mm);
    q["err_max_mm"] = number(c.max_mm);
    q["latency_median_ms"] = number(c.ms_median);
    q["latency_p95_ms"] = number(c.ms_p95);
    q["latency_max_ms"] = number(c.ms_max);
    rows.push_back(q);
  }

  Json j;
  j["study"] = "tracker";
  j["scene"] = scene.origin;
  j["camera"] = camera_summary(*scene.camera);
  j["supersample"] = scene.effects.supersample;
  j["gl"] = gl;
  j["frames"] = times.size();
  j["frame_interval_s"] = stride / fps;
  j["duration_s"] = tr.t_end() - tr.t_begin();
  j["seed"] = seed;
  j["noise"] = "read noise only: Gaussian, sigma = noise_dn, shot gain 0; 8-bit quantised";
  j["gross_error_px"] = kGrossErrorPx;
  Json ms = Json::array();
  for (const MethodSpec& m : methods)
    ms.push_back({{"name", m.name},
                  {"method", vision::to_string(m.method)},
                  {"fit", m.table_plane ? "table-plane" : "pixel"}});
  j["methods"] = ms;
  j["tracker_defaults"] = tracker_defaults_json();
  j["noise_dn"] = noises;
  Json bl = Json::array();
  for (const BlurLevel& b : blurs)
    bl.push_back({{"exposure_s", b.exposure},
                  {"fraction_of_frame", b.fraction},
                  {"subframes", b.subframes},
                  {"blur_px_mean", b.px_mean},
                  {"blur_px_max", b.px_max},
                  {"truth_shift_px_rms", b.shift_rms},
                  {"truth_shift_px_max", b.shift_max}});
  j["exposures"] = bl;
  j["rows"] = rows;
  j["load_average_1min"] = {number(load_start), number(load_end)};
  j["wall_seconds"] = wall;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "tracker.csv", csv);
    if (plots) {
      const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e"};
      // Noise levels double from 1 DN: x = 1 + log2(noise), 0 DN at x = 0, labelled in DN.
      auto pos = [](double n) { return n <= 0 ? 0.0 : 1 + std::log2(n); };
      std::string xtics = "pos(n) = n <= 0 ? 0 : 1 + log(n) / log(2)\nset xtics (";
      for (std::size_t i = 0; i < noises.size(); ++i)
        xtics +=
            (i ? ", '" : "'") + format_number(noises[i]) + "' " + format_number(pos(noises[i]));
      xtics += ")\nset xrange [" + format_number(pos(noises.front()) - 0.2) + ":" +
               format_number(pos(noises.back()) + 0.2) + "]\n";
      const std::string head = "set grid\nset logscale y\n" + kLogTics + "set format y '%g'\n" +
                               xtics +
                               "set xlabel 'read noise sigma (DN)'\nset key top left\n"
                               "lift(e) = e < 1e-4 ? 1e-4 : e\n";
      // Centre error: a panel per method, a curve per exposure.
      std::string err = head + "set multiplot layout 2,2 title 'Tracker: RMS centre error (" +
                        std::to_string(times.size()) + " frames per point)'\n";
      for (const MethodSpec& m : methods) {
        err += "set title '" + m.name + "'\nset ylabel 'RMS centre error (px)'\nplot ";
        for (std::size_t bi = 0; bi < blurs.size(); ++bi) {
          char title[120];
          std::snprintf(title, sizeof title, "exposure %.1f ms (blur <= %.1f px)",
                        1e3 * blurs[bi].exposure, blurs[bi].px_max);
          err += std::string(bi ? ", \\\n     " : "") +
                 "datafile skip 1 using (pos(column(8))):((strcol(1) eq '" + m.name +
                 "' && column(3) == " + std::to_string(bi) +
                 ") ? lift(column(13)) : NaN) with linespoints lw 2 pt 7 lc rgb '" +
                 colors[bi % 5] + "' title '" + title + "'";
        }
        err += "\n";
      }
      err += "unset multiplot\n";
      run_plot(outputs, dir, {"tracker_error.gp", "tracker.csv", "tracker_error.png", err});
      // Latency: the sharpest and the most blurred sequence, a curve per method.
      std::string lat = head +
                        "set multiplot layout 1,2 title 'Tracker: latency per frame (wall; median "
                        "solid, 95th percentile dashed)'\n";
      for (std::size_t bi : {std::size_t{0}, blurs.size() - 1}) {
        char title[120];
        std::snprintf(title, sizeof title, "exposure %.1f ms", 1e3 * blurs[bi].exposure);
        lat += std::string("set title '") + title + "'\nset ylabel 'latency (ms)'\nplot ";
        for (std::size_t mi = 0; mi < methods.size(); ++mi) {
          const std::string sel = "(strcol(1) eq '" + methods[mi].name +
                                  "' && column(3) == " + std::to_string(bi) + ")";
          lat += std::string(mi ? ", \\\n     " : "") + "datafile skip 1 using (pos(column(8))):(" +
                 sel + " ? column(17) : NaN) with linespoints lw 2 pt 7 lc rgb '" + colors[mi % 5] +
                 "' title '" + methods[mi].name +
                 "', \\\n     datafile skip 1 using (pos(column(8))):(" + sel +
                 " ? column(18) : NaN) with lines lw 1 dt 2 lc rgb '" + colors[mi % 5] +
                 "' notitle";
        }
        lat += "\n";
      }
      lat += "unset multiplot\n";
      run_plot(outputs, dir, {"tracker_latency.gp", "tracker.csv", "tracker_latency.png", lat});
    }
    outputs.stage(dir / "tracker.json", j.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study tracker: " << times.size() << " frames per sequence (" << scene.origin
     << "), " << format_number(std::round(wall * 10) / 10) << " s wall, load "
     << format_number(load_start) << " -> " << format_number(load_end) << "\n";
  for (const Cell& c : cells) {
    char line[240];
    std::snprintf(line, sizeof line,
                  "  %-10s exposure %5.1f ms (blur <= %4.1f px) noise %3g DN   RMS %.4f px "
                  "(%.4f mm)  max %.4f px   latency %.3f / %.3f ms   lost %d  gross %d\n",
                  methods[c.method].name.c_str(), 1e3 * blurs[c.blur].exposure,
                  blurs[c.blur].px_max, noises[c.noise], c.rms_px, c.rms_mm, c.max_px, c.ms_median,
                  c.ms_p95, c.lost, c.gross);
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace flatland::app
