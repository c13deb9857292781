// flatland study: speed-accuracy studies (issue #6), one per knob, regenerating docs/ACCURACY.md.
// `sim` is the work-precision diagram of the simulator: for every integrator setting and both
// formulations, the error in s_h(T) and in the solved k* against the CPU time they cost.
// `calibration`: the intrinsics' parameter error and time against views and corner noise.
#include "study.hpp"

#include "flatland/studies/calibration_study.hpp"
#include "flatland/studies/sim_study.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <iostream>
#include <memory>
#include <numbers>
#include <random>
#include <sstream>

namespace flatland::app {

namespace {

// One log-log work-precision plot: error column `ecol` against CPU column `tcol`, a curve per
// (method, formulation). Errors below 1e-16 are drawn at 1e-16 (the reference's own floor).
std::string plot_body(const std::string& title, const std::string& ylabel, int tcol, int ecol) {
  std::string body = "set title '" + title +
                     "'\n"
                     "set logscale xy\n"
                     "set format x '1e%L'\n"
                     "set format y '1e%L'\n"
                     "set grid\n"
                     "set xlabel 'CPU time (s)'\n"
                     "set ylabel '" +
                     ylabel +
                     "'\n"
                     "set key outside right\n"
                     "lift(e) = e < 1e-16 ? 1e-16 : e\n"
                     "sel(m, f, c) = (strcol(1) eq m && strcol(2) eq f) ? column(c) : NaN\n"
                     "plot ";
  const char* methods[] = {"rk4", "dopri5", "dop853"};
  const char* forms[] = {"reduced", "general"};
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3"};
  bool first = true;
  for (int m = 0; m < 3; ++m)
    for (int f = 0; f < 2; ++f) {
      if (!first) body += ", \\\n     ";
      first = false;
      body += "datafile skip 1 using (sel('" + std::string(methods[m]) + "','" + forms[f] + "'," +
              std::to_string(tcol) + ")):(lift(sel('" + methods[m] + "','" + forms[f] + "'," +
              std::to_string(ecol) + "))) with linespoints lw 2 pt " +
              std::to_string(f == 0 ? 7 : 5) + " dt " + std::to_string(f == 0 ? 1 : 2) +
              " lc rgb '" + colors[m] + "' title '" + methods[m] + " " + forms[f] + "'";
    }
  return body + "\n";
}

}  // namespace

void run_sim_study(const StudyOptions& o) {
  CommonOptions common;
  common.scene = o.scene;
  Scene scene = load_scene_with_overrides(common);
  const sim::SimulationSpec& spec = scene.sim;
  studies::check_sim_study(spec);  // bad input before the banner
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  std::cerr << "flatland: study sim: " << studies::sim_study_settings(o.quick).size()
            << " settings, 2T = " << format_number(spec.motion.period)
            << " s, k = " << format_number(spec.motion.k) << "\n";
  studies::SimStudyResult study;
  {
    ProgressBar bar("study sim");
    studies::SimStudyOptions so;
    so.quick = o.quick;
    so.min_cpu = o.min_cpu;
    so.progress = bar.callback();
    study = studies::run_sim_study(spec, so);
  }
  const std::vector<studies::SimStudyRow>& rows = study.rows;
  const studies::SimStudyRow& ref_red = study.reference_reduced;
  const studies::SimStudyRow& ref_gen = study.reference_general;
  const double seconds = study.cpu_seconds;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "sim.csv", studies::sim_study_csv(study));
    if (plots) {
      run_plot(outputs, dir,
               {"sim_s_h.gp", "sim.csv", "sim_s_h.png",
                plot_body("Work-precision: s_h(T) of the scene butterfly (2T = " +
                              format_number(spec.motion.period) + " s)",
                          "|s_h(T) - reference|", 10, 9)});
      run_plot(outputs, dir,
               {"sim_k.gp", "sim.csv", "sim_k.png",
                plot_body("Work-precision: k* solving s_h(T) = 0 (2T = " +
                              format_number(spec.motion.period) + " s, one solve_k)",
                          "|k* - reference|", 13, 12)});
    }
    outputs.commit();
    written = outputs.paths();
  }

  if (o.json) {
    Json j;
    j["study"] = "sim";
    j["scene"] = scene.origin;
    j["period"] = spec.motion.period;
    j["k"] = spec.motion.k;
    Json ref;
    ref["reduced"] = {{"method", "dop853"},
                      {"rtol", ref_red.setting.rtol},
                      {"s_T", number(ref_red.s_T)},
                      {"k", number(ref_red.k)}};
    ref["general"] = {{"method", "dop853"},
                      {"rtol", ref_gen.setting.rtol},
                      {"s_T", number(ref_gen.s_T)},
                      {"k", number(ref_gen.k)}};
    ref["s_T_disagreement"] = number(std::abs(ref_red.s_T - ref_gen.s_T));
    ref["k_disagreement"] = number(std::abs(ref_red.k - ref_gen.k));
    j["reference"] = ref;
    Json arr = Json::array();
    for (const studies::SimStudyRow& r : rows) {
      const studies::IntegratorSetting& set = r.setting;
      Json q;
      q["method"] = sim::to_string(set.method);
      q["formulation"] = sim::to_string(set.formulation);
      q["rtol"] = set.method == sim::Method::kRungeKutta4 ? Json(nullptr) : Json(set.rtol);
      q["step"] = set.method == sim::Method::kRungeKutta4 ? Json(set.step) : Json(nullptr);
      q["steps"] = r.steps;
      q["rhs_evals"] = r.rhs_evals;
      q["err_s_T"] = number(r.err_s_T);
      q["cpu_s_T"] = number(r.cpu_s_T);
      q["err_k"] = number(r.err_k);
      q["cpu_k"] = number(r.cpu_k);
      q["energy_error"] = number(r.energy_error);
      q["failure"] = r.failure.empty() ? Json(nullptr) : Json(r.failure);
      arr.push_back(q);
    }
    j["rows"] = arr;
    j["files"] = written;
    j["cpu_seconds"] = seconds;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study sim: " << rows.size() << " settings (" << scene.origin << ") in "
     << format_number(std::round(seconds * 100) / 100) << " s CPU\n"
     << "  reference s_h(T): reduced " << format_number(ref_red.s_T) << ", general "
     << format_number(ref_gen.s_T) << "; k*: reduced " << format_number(ref_red.k) << ", general "
     << format_number(ref_gen.k) << "\n";
  for (const studies::SimStudyRow& r : rows) {
    char line[200];
    std::snprintf(line, sizeof line,
                  "  %-34s err s_h(T) %8.1e in %8.2e s   err k* %8.1e in %8.2e s%s\n",
                  studies::label(r.setting).c_str(), r.err_s_T, r.cpu_s_T, r.err_k, r.cpu_k,
                  r.failure.empty() ? "" : ("  FAILED: " + r.failure).c_str());
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

// ---- study calibration ------------------------------------------------------------------------

// The study's rows as an aligned table for the terminal: {JSON key, column header}.
std::string calibration_table(const Json& rows) {
  const std::pair<const char*, const char*> columns[] = {
      {"views", "views"},   {"noise_px", "noise_px"}, {"failures", "failures"},
      {"rms_err_fx", "fx"}, {"rms_err_fy", "fy"},     {"rms_err_cx", "cx"},
      {"rms_err_cy", "cy"}, {"rms_err_k1", "k1"},     {"rms_err_k2", "k2"},
      {"rms_px", "rms_px"}, {"time_s", "time_s"}};
  std::ostringstream os;
  char cell[32];
  for (const auto& [key, header] : columns) {
    std::snprintf(cell, sizeof cell, "%11s", header);
    os << cell;
  }
  os << "\n";
  for (const Json& r : rows) {
    for (const auto& [key, header] : columns) {
      const Json& v = r.at(key);
      if (v.is_number_integer())
        std::snprintf(cell, sizeof cell, "%11lld", v.get<long long>());
      else if (v.is_number())
        std::snprintf(cell, sizeof cell, "%11.3g", v.get<double>());
      else
        std::snprintf(cell, sizeof cell, "%11s", "-");
      os << cell;
    }
    os << "\n";
  }
  return os.str();
}

void run_calibration_study(const StudyOptions& o) {
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();
  const studies::CalibrationStudyGrid grid = studies::calibration_study_grid(o.quick);
  std::cerr << "flatland: study calibration: " << grid.views.size() * grid.noises.size()
            << " cells x " << grid.trials
            << " trials (synthetic corners, cv::projectPoints + Gaussian noise)\n";
  studies::CalibrationStudyResult study;
  {
    ProgressBar bar("study calibration");
    studies::CalibrationStudyOptions so;
    so.quick = o.quick;
    so.progress = bar.callback();
    study = studies::run_calibration_study(so);
  }
  const int trials = study.grid.trials;
  const std::array<double, 6> truth_p = study.truth.parameters();
  Json rows = Json::array();
  for (const studies::CalibrationStudyCell& c : study.cells) {
    Json q;
    q["views"] = c.views;
    q["noise_px"] = c.noise_px;
    q["failures"] = c.failures;
    for (std::size_t i = 0; i < 6; ++i)
      q[std::string("rms_err_") + studies::kCalibrationParameters[i]] = number(c.rms_error[i]);
    q["rms_px"] = number(c.rms_px);
    q["time_s"] = number(c.time_s);
    rows.push_back(q);
  }

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "calibration.csv", studies::calibration_study_csv(study));
    if (plots) {
      // One panel per quantity: error against the number of views, one curve per noise level
      // (rows are views-major with 4 noise levels each: `every 4::i` picks noise level i, so
      // that gnuplot draws each curve as one line).
      auto panel = [](const std::string& title, const std::string& ylabel, int col) {
        std::string b = "set title '" + title + "'\nset ylabel '" + ylabel + "'\nplot ";
        const char* noise[] = {"0", "0.1", "0.3", "1"};
        for (int i = 0; i < 4; ++i)
          b += std::string(i ? ", \\\n     " : "") +
               "datafile skip 1 every 4::" + std::to_string(i) + " using 1:(lift(column(" +
               std::to_string(col) + "))) with linespoints lw 2 pt 7 title 'noise " + noise[i] +
               " px'";
        return b + "\n";
      };
      const std::string head =
          "set logscale xy\nset format y '1e%L'\nset grid\nset xtics (5, 10, 20, 40)\n"
          "set xlabel 'views'\nset key bottom left\nlift(e) = e < 1e-12 ? 1e-12 : e\n"
          "set multiplot layout 2,2 title 'Calibration: RMS parameter error against views'\n";
      run_plot(outputs, dir,
               {"calibration.gp", "calibration.csv", "calibration.png",
                head + panel("fx", "RMS error fx (px)", 5) + panel("cx", "RMS error cx (px)", 9) +
                    panel("k1", "RMS error k1", 13) +
                    "set title 'time'\nset ylabel 'calibration time (s)'\nplot "
                    "datafile skip 1 every 4::2 using 1:18 with "
                    "linespoints lw 2 pt 7 title 'noise 0.3 px'\n"
                    "unset multiplot\n"});
    }
    Json summary;
    summary["study"] = "calibration";
    summary["trials"] = trials;
    summary["rows"] = rows;
    outputs.stage(dir / "calibration.json", summary.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    Json j;
    j["study"] = "calibration";
    j["trials"] = trials;
    j["truth"] = {{"fx", truth_p[0]}, {"fy", truth_p[1]}, {"cx", truth_p[2]},
                  {"cy", truth_p[3]}, {"k1", truth_p[4]}, {"k2", truth_p[5]}};
    j["rows"] = rows;
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::cout << "flatland study calibration: RMS error of each parameter over " << trials
            << " trials (synthetic corners; fx, fy, cx, cy in px)\n"
            << calibration_table(rows);
  for (const auto& p : written) std::cout << "  wrote " << p << "\n";
}

namespace {

void run_study(const StudyOptions& o) {
  if (!o.controllers.empty() && o.name != "closed-loop")
    throw UsageError("--controller: only the closed-loop study has a controller axis, not '" +
                     o.name + "'");
  // The other studies measure speed and accuracy on one machine; only closed-loop is a sweep.
  if (sweeps_on_mpi() && o.name != "closed-loop")
    throw UsageError("study " + o.name +
                     ": not a sweep; run it without mpirun or srun (under MPI: study closed-loop)");
  if (o.name == "sim") return run_sim_study(o);
  if (o.name == "calibration") return run_calibration_study(o);
  if (o.name == "render") return run_render_study(o);
  if (o.name == "tracker") return run_tracker_study(o);
  if (o.name == "closed-loop") return run_closed_loop_study(o);
  throw UsageError("study: unknown study '" + o.name +
                   "' (available: sim, render, tracker, calibration, closed-loop)");
}

}  // namespace

Command add_study_command(CLI::App& app) {
  auto o = std::make_shared<StudyOptions>();
  CLI::App* cmd = add_command(app, "study");
  cmd->add_option("name", o->name,
                  "Which study: sim, render, tracker, calibration, closed-loop. 'render': the "
                  "renderer's centroid error against cv::projectPoints and its frames/s against "
                  "supersampling and resolution; 'tracker': centre error, latency and lost frames "
                  "of each tracking method against read noise and exposure blur. Both film the "
                  "scene's camera (default scene: assets/scenes/butterfly-camera.yaml)")
      ->required();
  cmd->add_option("--scene", o->scene,
                  "Scene file (YAML). Default: sim, the bundled paper butterfly " +
                      default_scene_path() +
                      " (its motion must be the butterfly); render and tracker, the bundled "
                      "butterfly-camera.yaml (the scene needs a camera); closed-loop, the bundled "
                      "airtable-feedback.yaml; calibration uses no scene")
      ->type_name("FILE");
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout (errors, CPU seconds, the references)");
  cmd->add_option(
         "--out", o->out,
         "Directory for the study's files, created if missing. sim: sim.csv (one row "
         "per setting: method, formulation, rtol, atol, step in s, steps, rhs_evals, "
         "s_T, err_s_T, cpu_s_T in s, k, err_k, cpu_k in s, simulations, energy_error: the "
         "run's energy balance relative to the energy it moved) and sim_s_h.png, "
         "sim_k.png (log-log) with their gnuplot scripts; calibration: calibration.csv, "
         "calibration.png, calibration.json; render: render.csv (one row per "
         "supersampling and resolution), render_error.png, render_fps.png, render.json; "
         "tracker: tracker.csv (one row per method, exposure and noise level), "
         "tracker_error.png, tracker_latency.png, tracker.json; closed-loop: "
         "closed_loop.csv, closed_loop.png, closed_loop.json. Default: no files")
      ->type_name("PATH");
  cmd->add_flag("--no-plot", o->no_plot, "Write the CSV but no plots (no gnuplot needed)");
  add_force_option(*cmd, o->force);
  cmd->add_flag("--quick", o->quick,
                "sim: RK4 at 2 steps and each Dormand-Prince at rtol 1e-3, 1e-6, 1e-9, 1e-13 "
                "(a quarter of the settings); calibration: 2 trials per cell instead of 8 (a few "
                "seconds); closed-loop: 2 "
                "worlds per cell on a 2 x 2 grid (15 Hz and the scene's rate; the scene's "
                "latency and 0.3 s) instead of 30 on 4 x 6; render: supersampling 1, 2, 4 at 2 "
                "resolutions, 4 disk positions (about a second); tracker: every third frame, "
                "exposures 0 and 1/fps, noise 0, 2, 8, 32 DN (a few seconds). Default: off");
  cmd->add_option("--controller", o->controllers,
                  "closed-loop only: the controller axis, comma-separated or repeated: open-loop, "
                  "feedback (the scene's controller.type) or a controller type (paper, ...); each "
                  "runs the whole rate x latency grid on the same worlds, and without open-loop "
                  "on the axis it runs once at the scene's camera as the baseline. Default: "
                  "feedback")
      ->delimiter(',');
  cmd->add_option("--min-cpu", o->min_cpu,
                  "CPU seconds each timing repeats for (> 0; longer is steadier). Default: 0.02")
      ->check(CLI::PositiveNumber);
  return {cmd, [o] { run_study(*o); }};
}

}  // namespace flatland::app
