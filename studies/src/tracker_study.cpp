// The tracker's study (tracker_study.hpp).
#include "flatland/studies/tracker_study.hpp"

#include "flatland/render/effects.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/trajectory_csv.hpp"
#include "flatland/studies/timing.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <tuple>

namespace flatland::studies {

namespace {

using sim::format_number;

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

const char* kTrackerColumns =
    "method,fit,blur_level,exposure_s,blur_subframes,blur_px_mean,blur_px_max,noise_dn,frames,"
    "lost,reacquired,gross,err_rms_px,err_max_px,err_rms_mm,err_max_mm,latency_median_ms,"
    "latency_p95_ms,latency_max_ms,sigma_median_px,err_over_sigma_median,beyond_3_sigma\n";

}  // namespace

TrackerStudyGrid tracker_study_grid(bool quick) {
  TrackerStudyGrid g;
  g.methods = {{"edge", vision::TrackMethod::kEdge, false},
               {"edge-one-pass", vision::TrackMethod::kEdge, false, true},
               {"edge-plane", vision::TrackMethod::kEdge, true},
               {"moments", vision::TrackMethod::kMoments, false},
               {"hough", vision::TrackMethod::kHough, false},
               {"contour", vision::TrackMethod::kContour, false}};
  g.noises =
      quick ? std::vector<double>{0, 2, 8, 32} : std::vector<double>{0, 1, 2, 4, 8, 16, 32, 64};
  g.fractions = quick ? std::vector<double>{0, 1} : std::vector<double>{0, 0.25, 0.5, 1};
  g.stride = quick ? 3 : 1;  // every stride-th frame of the camera's rate
  return g;
}

TrackerStudyResult run_tracker_study(const model::Model& model,
                                     const TrackerStudyOptions& options) {
  const Scene& scene = model.spec;
  if (!model.camera)
    throw std::invalid_argument(
        scene.origin + ": camera: the scene has no camera section (needed by study tracker)");
  TrackerStudyResult out;
  out.grid = tracker_study_grid(options.quick);
  const std::vector<TrackerStudyMethod>& methods = out.grid.methods;
  const std::vector<double>& noises = out.grid.noises;
  const std::vector<double>& fractions = out.grid.fractions;
  const int stride = out.grid.stride;
  const std::uint64_t seed = out.seed = scene.effects.seed;
  const double z = scene.render.disk_thickness;
  const double fps = scene.camera->fps;
  sim::SimulationSpec spec = scene.sim;

  out.load_start = load_average_1min();
  const auto wall0 = std::chrono::steady_clock::now();
  spec.run.record = true;  // the frames sample the dense output
  const sim::RunResult run = sim::simulate(model.plant, spec.initial, sim::run_options(spec));
  sim::require_no_numerical_failure(run, "study tracker");
  if (run.trajectory.empty()) throw std::runtime_error("study tracker: the run recorded nothing");
  const sim::Trajectory& tr = run.trajectory;
  std::vector<double>& times = out.times;
  for (int k = 0;; ++k) {
    const double t = tr.t_begin() + k * stride / fps;
    if (t > tr.t_end() + 1e-9) break;
    times.push_back(std::min(t, tr.t_end()));
  }
  if (times.size() < 3)
    throw std::invalid_argument(scene.origin + ": study tracker: the run (" +
                                format_number(tr.t_end() - tr.t_begin()) +
                                " s) gives fewer than 3 frames");

  const camera::CameraModel& cam0 = *model.camera;
  // The longest exposure the camera allows: the frame interval, or an interlaced camera's field
  // interval (each field is exposed on its own; camera_problem).
  const double longest_exposure = scene.camera->readout.mode == "interlaced" ? 0.5 / fps : 1 / fps;
  std::vector<TrackerStudyBlur>& blurs = out.blurs;
  for (double f : fractions) {
    TrackerStudyBlur b;
    b.fraction = f;
    b.exposure = f * longest_exposure;
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

  std::vector<TrackerStudyCell>& cells = out.cells;
  std::string& gl = out.gl;
  {
    long done = 0;
    const long total = static_cast<long>(blurs.size() * times.size());
    for (std::size_t bi = 0; bi < blurs.size(); ++bi) {
      const TrackerStudyBlur& b = blurs[bi];
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
      render::Renderer renderer(model::render_setup(*model::compile(std::move(s))));
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
          if (methods[mi].one_pass) cfg.second_pass_shift_px = 1.0;
          cfg.image_time_variance_frames2 = vision::image_time_variance_frames2(
              b.exposure, stride / fps, scene.camera->readout.mode == "interlaced", 1 / fps);
          if (methods[mi].table_plane) {
            cfg.camera = renderer.camera();
            cfg.plane_z = z;
          }
          trackers[ni].emplace_back(cfg);
          TrackerStudyCell c;
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
            TrackerStudyCell& c = cells[first + ni * methods.size() + mi];
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
            c.sigma_px.push_back(r.sigma_px);
            if (e > kGrossErrorPx) ++c.gross;
            const auto p = vision::pixel_to_table(renderer.camera(), r.center, z);
            const cv::Point3d& truth = f.truth.disk_center_table;
            c.err_mm.push_back(p ? 1e3 * std::hypot(p->x - truth.x, p->y - truth.y) : std::nan(""));
          }
        }
        ++done;
        if (options.progress) options.progress(done, total);
      }
    }
  }
  // Each curve of the plots (a method at an exposure, against noise) as consecutive rows: gnuplot
  // breaks a line at every row its filter skips.
  std::sort(cells.begin(), cells.end(), [](const TrackerStudyCell& a, const TrackerStudyCell& b) {
    return std::tie(a.method, a.blur, a.noise) < std::tie(b.method, b.blur, b.noise);
  });
  for (TrackerStudyCell& c : cells) {
    c.rms_px = rms(c.err_px);
    c.max_px = max_of(c.err_px);
    c.rms_mm = rms(c.err_mm);
    c.max_mm = max_of(c.err_mm);
    c.ms_max = max_of(c.ms);
    c.ms_p95 = quantile(c.ms, 0.95);
    c.ms_median = quantile(c.ms, 0.5);
    std::vector<double> z;
    int beyond = 0;
    for (std::size_t i = 0; i < c.err_px.size(); ++i) {
      z.push_back(c.err_px[i] / c.sigma_px[i]);
      beyond += z.back() > 3;
    }
    std::vector<double> sigma = c.sigma_px;
    c.sigma_median_px = quantile(sigma, 0.5);
    c.z_median = quantile(z, 0.5);
    if (!z.empty()) c.beyond_3_sigma = static_cast<double>(beyond) / static_cast<double>(z.size());
  }
  out.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  out.load_end = load_average_1min();

  out.frame_interval_s = stride / fps;
  out.duration_s = tr.t_end() - tr.t_begin();
  return out;
}

std::string tracker_study_csv(const TrackerStudyResult& r) {
  std::string csv = kTrackerColumns;
  for (const TrackerStudyCell& c : r.cells) {
    const TrackerStudyMethod& m = r.grid.methods[c.method];
    const TrackerStudyBlur& b = r.blurs[c.blur];
    std::string line =
        m.name + (m.table_plane ? ",table-plane," : ",pixel,") + std::to_string(c.blur);
    for (double v :
         {b.exposure, static_cast<double>(b.subframes), b.px_mean, b.px_max, r.grid.noises[c.noise],
          static_cast<double>(c.frames), static_cast<double>(c.lost),
          static_cast<double>(c.reacquired), static_cast<double>(c.gross), c.rms_px, c.max_px,
          c.rms_mm, c.max_mm, c.ms_median, c.ms_p95, c.ms_max, c.sigma_median_px, c.z_median,
          c.beyond_3_sigma}) {
      line += ',';
      line += format_number(v);
    }
    csv += line + "\n";
  }

  return csv;
}

}  // namespace flatland::studies
