// flatland study closed-loop: the command's side of studies::run_closed_loop_study (success of
// the vision-feedback loop against camera rate and latency): closed_loop.csv, .json and .png, the
// JSON on stdout or a table.
#include "study.hpp"

#include "flatland/studies/closed_loop_study.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <sstream>
#include <thread>

namespace flatland::app {

namespace {

Json cell_json(const studies::ClosedLoopCellResult& c, int n) {
  Json j;
  j["rate_hz"] = c.cell.fps;
  j["latency_s"] = c.cell.latency;
  j["latency_jitter_s"] = c.cell.jitter;
  j["controller"] = c.cell.controller;
  j["runs"] = n;
  j["successes"] = c.successes;
  // Worlds with a physical outcome: a failed simulation or a world the draw made impossible has
  // none, and is left out of the rate as the interval leaves it out.
  const int counted = n - c.numerical_failures - c.invalid_worlds;
  j["success_rate"] = counted > 0 ? Json(static_cast<double>(c.successes) / counted) : Json();
  j["ci95"] = Json::array({c.ci.lo, c.ci.hi});
  Json f = Json::object();
  for (const auto& [cls, count] : c.failures) f[cls] = count;
  j["failures"] = f;
  j["numerical_failures"] = c.numerical_failures;
  j["invalid_worlds"] = c.invalid_worlds;
  j["fn_min_ratio_mean"] = number(c.fn_min_mean);
  j["fn_min_ratio_min"] = number(c.fn_min_min);
  j["duration_mean_s"] = number(c.duration_mean);
  j["est_err_rms"] = number(c.est_rms);
  j["nees_mean"] = number(c.nees);
  j["frames_lost_fraction"] = number(c.frames_lost_fraction);
  j["wall_s"] = c.wall;
  j["cpu_s"] = c.cpu;
  return j;
}

/// 2 x 2 panels against latency (ms), one curve per controller of the axis and camera rate (a
/// colour per rate, a point shape and dash per controller), the open-loop baseline (when the
/// grid has one) as one black square: success rate with its Wilson interval, the smallest normal
/// force (mean and worst over the successes), the estimator's RMS error in the servo stage, and
/// the CPU time per experiment.
std::string plot_body(const studies::ClosedLoopGrid& grid, int n) {
  const std::vector<double>& rates = grid.rates;
  const std::vector<std::string>& controllers = grid.controllers;
  const double max_latency = grid.latencies.back();
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02"};
  const int points[] = {7, 9, 5, 11, 13};  // filled circle, triangle, square, diamond, pentagon
  const int dashes[] = {1, 4, 5, 2, 3};
  const std::size_t curves = rates.size() * controllers.size();
  // Curve i: controller i / rates, rate i % rates; neighbouring curves are drawn 1.5 ms apart so
  // that their error bars do not overlap.
  const auto offset = [&](std::size_t i) {
    return format_number(1.5 * (static_cast<double>(i) - 0.5 * static_cast<double>(curves - 1)));
  };
  const auto name = [&](std::size_t i) { return "'" + controllers[i / rates.size()] + "'"; };
  const auto rate = [&](std::size_t i) { return format_number(rates[i % rates.size()]); };
  // `scale` multiplies the column (e.g. "100 * " for percent); `bars` adds the Wilson interval.
  // `col2`: a second column drawn dashed with open points, in the same colours.
  const auto panel = [&](const std::string& title, const std::string& ylabel, int col,
                         const std::string& scale, bool bars, int col2 = 0) {
    const std::string c = std::to_string(col);
    std::string p = "set title '" + title + "'\nset ylabel '" + ylabel + "'\nplot ";
    for (std::size_t i = 0; col2 && i < curves; ++i) {
      const std::string args = name(i) + ", " + rate(i);
      p += "datafile skip 1 using (cx(" + args + ", " + offset(i) + ")):(" + scale + "cc(" + args +
           ", " + std::to_string(col2) + ")) with linespoints lw 1 dt 2 pt 6 lc rgb '" +
           colors[i % rates.size() % 6] + "' notitle, \\\n     ";
    }
    for (std::size_t i = 0; i < curves; ++i) {
      const std::string args = name(i) + ", " + rate(i);
      const std::size_t k = i / rates.size();
      p += std::string(i ? ", \\\n     " : "") + "datafile skip 1 using (cx(" + args + ", " +
           offset(i) + ")):(" + scale + "cc(" + args + ", " + c + "))" +
           (bars ? ":(100 * cc(" + args + ", 8)):(100 * cc(" + args + ", 9)) with yerrorlines"
                 : std::string(" with linespoints")) +
           " lw 2 dt " + std::to_string(dashes[k % 5]) + " pt " + std::to_string(points[k % 5]) +
           " lc rgb '" + colors[i % rates.size() % 6] + "' title '" +
           (controllers.size() > 1 ? controllers[k] + " " : std::string()) + rate(i) + " Hz'";
    }
    if (grid.open_loop_baseline)
      p += ", \\\n     datafile skip 1 using (ox(0)):(" + scale + "ol(" + c + "))" +
           (bars ? std::string(":(100 * ol(8)):(100 * ol(9)) with yerrorbars") : " with points") +
           " pt 5 ps 1.5 lc rgb 'black' title 'open loop'";
    return p + "\n";
  };
  return "set datafile missing 'nan'\n"
         "set grid\nset key bottom left box opaque\nset xlabel 'camera latency (ms)'\n"
         "set xrange [-10:" +
         format_number(std::ceil(1000 * max_latency / 10) * 10 + 10) +
         "]\n"
         "# cc(c, r, col): column col of controller c's row at rate r; ol(col): of the open-loop "
         "baseline\n"
         "cc(c, r, col) = (column(1) == r && strcol(4) eq c) ? column(col) : NaN\n"
         "cx(c, r, off) = (column(1) == r && strcol(4) eq c) ? 1000 * column(2) + off : NaN\n"
         "ol(col) = strcol(4) eq 'open-loop' ? column(col) : NaN\n"
         "ox(off) = strcol(4) eq 'open-loop' ? 1000 * column(2) + off : NaN\n"
         "set multiplot layout 2,2 title 'Closed loop against camera rate and latency (" +
         std::to_string(n) + " perturbed worlds per point)'\n" + "set yrange [0:105]\n" +
         panel("success (Wilson 95 % interval)", "success (%)", 7, "100 * ", true) +
         "set autoscale y\nunset key\n" +
         panel("smallest normal force of the successes: mean, and worst (dashed)",
               "f_n min / (m g sin tilt)", 15, "", false, 16) +
         "set logscale y\n" +
         panel("estimate error in the servo stage", "RMS error of s_h", 18, "", false) +
         panel("cost per experiment", "CPU s per experiment (its thread)", 22,
               "1.0 / " + std::to_string(n) + " * ", false) +
         "unset multiplot\n";
}

std::string percent(double f) { return std::to_string(std::lround(100 * f)); }

}  // namespace

void run_closed_loop_study(const StudyOptions& o) {
  // ---- bad input first: nothing is run or written before these checks pass
  CommonOptions common;
  common.scene = o.scene.empty() ? default_experiment_scene() : o.scene;
  const Scene scene = load_scene_with_overrides(common);
  const std::shared_ptr<const model::Model> nominal = model::compile(scene);
  std::vector<std::string> controllers = o.controllers;
  if (controllers.empty()) controllers = {"feedback"};
  for (std::size_t i = 0; i < controllers.size(); ++i) {
    // std::invalid_argument (exit 2) naming --controller and the known names.
    drivers::scene_for_controller(scene, controllers[i], "--controller");
    for (std::size_t j = 0; j < i; ++j)
      if (controllers[i] == controllers[j])
        throw UsageError("--controller: " + controllers[i] + " given twice");
  }
  const studies::ClosedLoopGrid grid = studies::closed_loop_grid(*nominal, o.quick, controllers);
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  const int n = grid.runs_per_cell;
  const std::uint64_t seed = studies::kClosedLoopSeed;
  // Every core (no --threads: the experiments are whole and independent); under MPI, one
  // thread per rank.
  const auto engine = make_sweep_engine(0, false);
  rasterise_on_workers(*engine);
  std::string axis;
  for (const std::string& c : controllers) axis += (axis.empty() ? "" : ", ") + c;
  std::cerr << "flatland: study closed-loop: " << grid.cells.size() << " cells ("
            << controllers.size() << " controllers (" << axis << ") x " << grid.rates.size()
            << " rates x " << grid.latencies.size() << " latencies"
            << (grid.open_loop_baseline ? "; open-loop baseline" : "") << ") x " << n
            << " worlds (seed " << seed << ") on " << where_it_runs(*engine) << ", " << scene.origin
            << "\n";
  studies::ClosedLoopStudyResult study;
  {
    ProgressBar bar("study closed-loop");
    study = studies::run_closed_loop_study(*nominal, grid, *engine, bar.callback());
  }
  const std::vector<double>& rates = grid.rates;
  const std::vector<double>& latencies = grid.latencies;
  const drivers::Perturbations& defaults = study.perturbations;

  Json j;
  j["study"] = "closed-loop";
  j["scene"] = scene.origin;
  j["seed"] = seed;
  j["runs_per_cell"] = n;
  j["controllers"] = controllers;
  j["open_loop_baseline"] = grid.open_loop_baseline;
  j["quick"] = o.quick;
  j["rates_hz"] = rates;
  j["latencies_s"] = latencies;
  j["nominal"] = {{"rate_hz", grid.nominal_fps}, {"latency_s", grid.nominal_latency}};
  j["perturbations"] = {{"s_h", defaults.s_h},
                        {"tilt_deg", defaults.tilt_deg},
                        {"radius_rel", defaults.radius_rel},
                        {"friction_rel", defaults.friction_rel},
                        {"noise_dn", defaults.noise_dn},
                        {"drop", defaults.drop},
                        {"latency_jitter", defaults.latency_jitter}};
  Json rows = Json::array();
  for (const studies::ClosedLoopCellResult& c : study.cells) rows.push_back(cell_json(c, n));
  j["rows"] = rows;
  j["threads"] = study.threads;
  j["ranks"] = study.processes;
  j["seconds"] = study.seconds;
  j["cpu_seconds"] = study.cpu_seconds;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "closed_loop.csv", studies::closed_loop_study_csv(study));
    if (plots)
      run_plot(outputs, dir,
               {"closed_loop.gp", "closed_loop.csv", "closed_loop.png", plot_body(grid, n)});
    outputs.stage(dir / "closed_loop.json", j.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study closed-loop: " << scene.origin << ", " << n << " worlds per cell (seed "
     << seed << "), " << format_number(std::round(study.seconds)) << " s\n";
  for (const studies::ClosedLoopCellResult& c : study.cells) {
    char line[160];
    std::snprintf(line, sizeof line, "  %5g Hz %5.0f ms  %-9s %3d/%d  (95 %%: %3s..%3s %%)",
                  c.cell.fps, 1000 * c.cell.latency, c.cell.controller.c_str(), c.successes, n,
                  percent(c.ci.lo).c_str(), percent(c.ci.hi).c_str());
    os << line << "  fn_min " << format_number(std::round(c.fn_min_mean * 1000) / 1000);
    for (const auto& [cls, count] : c.failures) os << "; " << cls << " " << count;
    if (c.numerical_failures > 0)
      os << "; " << c.numerical_failures << " failed numerically (not counted)";
    if (c.invalid_worlds > 0) os << "; " << c.invalid_worlds << " could not exist (not counted)";
    os << "\n";
  }
  for (const std::string& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace flatland::app
