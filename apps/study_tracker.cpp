// flatland study tracker: the command's side of studies::run_tracker_study (the tracker's centre
// error, latency and lost frames per method, exposure and noise): tracker.csv, .json and the
// plots, the JSON on stdout or a table.
#include "study_vision.hpp"

#include "flatland/studies/tracker_study.hpp"
#include "flatland/vision/tracker.hpp"

#include <cmath>
#include <iostream>
#include <sstream>

namespace flatland::app {

namespace {

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
  j["second_pass_shift_px"] = d.second_pass_shift_px;
  return j;
}

}  // namespace

void run_tracker_study(const StudyOptions& o) {
  // ---- everything that can be bad input, before anything is computed or written
  const Scene scene = load_camera_scene(o, "tracker");
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  const std::shared_ptr<const model::Model> compiled = model::compile(scene);
  const studies::TrackerStudyGrid grid = studies::tracker_study_grid(o.quick);
  std::cerr << "flatland: study tracker: " << grid.methods.size() << " methods x "
            << grid.fractions.size() << " exposures x " << grid.noises.size() << " noise levels ("
            << scene.origin << ", " << scene.camera->width << " x " << scene.camera->height
            << ", supersample " << scene.effects.supersample << ")\n";
  studies::TrackerStudyResult study;
  {
    ProgressBar bar("study tracker");
    studies::TrackerStudyOptions so;
    so.quick = o.quick;
    so.progress = bar.callback();
    study = studies::run_tracker_study(*compiled, so);
  }
  const std::vector<studies::TrackerStudyMethod>& methods = grid.methods;
  const std::vector<double>& noises = grid.noises;
  const std::vector<studies::TrackerStudyBlur>& blurs = study.blurs;
  const std::vector<studies::TrackerStudyCell>& cells = study.cells;
  const std::vector<double>& times = study.times;
  const double wall = study.wall_seconds, load_start = study.load_start, load_end = study.load_end;

  Json rows = Json::array();
  for (const studies::TrackerStudyCell& c : cells) {
    const studies::TrackerStudyMethod& m = methods[c.method];
    const studies::TrackerStudyBlur& b = blurs[c.blur];
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
    q["sigma_median_px"] = number(c.sigma_median_px);
    q["err_over_sigma_median"] = number(c.z_median);
    q["beyond_3_sigma"] = number(c.beyond_3_sigma);
    rows.push_back(q);
  }

  Json j;
  j["study"] = "tracker";
  j["scene"] = scene.origin;
  j["camera"] = camera_summary(*scene.camera);
  // An interlaced camera's exposures are fractions of its field interval (fraction_of_frame).
  j["readout"] = scene.camera->readout.mode;
  j["supersample"] = scene.effects.supersample;
  j["gl"] = study.gl;
  j["frames"] = times.size();
  j["frame_interval_s"] = study.frame_interval_s;
  j["duration_s"] = study.duration_s;
  j["seed"] = study.seed;
  j["noise"] = "read noise only: Gaussian, sigma = noise_dn, shot gain 0; 8-bit quantised";
  j["gross_error_px"] = studies::kGrossErrorPx;
  Json ms = Json::array();
  for (const studies::TrackerStudyMethod& m : methods)
    ms.push_back({{"name", m.name},
                  {"method", vision::to_string(m.method)},
                  {"fit", m.table_plane ? "table-plane" : "pixel"}});
  j["methods"] = ms;
  j["tracker_defaults"] = tracker_defaults_json();
  j["noise_dn"] = noises;
  Json bl = Json::array();
  for (const studies::TrackerStudyBlur& b : blurs)
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
    outputs.stage(dir / "tracker.csv", studies::tracker_study_csv(study));
    if (plots) {
      const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02"};
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
      // A panel per method, two to a row.
      const std::string layout = std::to_string((methods.size() + 1) / 2) + ",2";
      std::string err = head + "set multiplot layout " + layout +
                        " title 'Tracker: RMS centre error (" + std::to_string(times.size()) +
                        " frames per point)'\n";
      for (const studies::TrackerStudyMethod& m : methods) {
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
                 sel + " ? column(17) : NaN) with linespoints lw 2 pt 7 lc rgb '" + colors[mi % 6] +
                 "' title '" + methods[mi].name +
                 "', \\\n     datafile skip 1 using (pos(column(8))):(" + sel +
                 " ? column(18) : NaN) with lines lw 1 dt 2 lc rgb '" + colors[mi % 6] +
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
  for (const studies::TrackerStudyCell& c : cells) {
    char line[320];
    std::snprintf(line, sizeof line,
                  "  %-10s exposure %5.1f ms (blur <= %4.1f px) noise %3g DN   RMS %.4f px "
                  "(%.4f mm)  max %.4f px   sigma %.4f px: |error|/sigma median %.2f, > 3 in "
                  "%.1f %%   latency %.3f / %.3f ms   lost %d  gross %d\n",
                  methods[c.method].name.c_str(), 1e3 * blurs[c.blur].exposure,
                  blurs[c.blur].px_max, noises[c.noise], c.rms_px, c.rms_mm, c.max_px,
                  c.sigma_median_px, c.z_median, 100 * c.beyond_3_sigma, c.ms_median, c.ms_p95,
                  c.lost, c.gross);
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace flatland::app
