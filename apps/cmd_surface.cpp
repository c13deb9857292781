// flatland surface: s_h(T) over a k x 2T grid (paper Fig. 6); its zero level is the locus.
#include "common.hpp"

#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>

namespace flatland::app {

namespace {

struct SurfaceOptions {
  CommonOptions common;
  double k_from = -1.6, k_to = -0.8, p_from = 0.8, p_to = 2.0;
  int nk = 50, np = 50, threads = 0;
  CLI::Option* threads_opt = nullptr;
};

std::string surface_csv(const sim::SurfaceResult& s) {
  std::string out = "k,period,s_T\n";
  for (std::size_t i = 0; i < s.k.size(); ++i)
    for (std::size_t j = 0; j < s.period.size(); ++j)
      out += format_number(s.k[i]) + "," + format_number(s.period[j]) + "," +
             format_number(s.s_T[i * s.period.size() + j]) + "\n";
  return out;
}

// Where s_T changes sign along k, for each period (linear interpolation between grid points):
// the s_T = 0 contour drawn over the heat map, as "period,k" lines.
std::string zero_crossings(const sim::SurfaceResult& s) {
  std::string out;
  const std::size_t np = s.period.size();
  for (std::size_t j = 0; j < np; ++j)
    for (std::size_t i = 0; i + 1 < s.k.size(); ++i) {
      const double a = s.s_T[i * np + j], b = s.s_T[(i + 1) * np + j];
      if (!std::isfinite(a) || !std::isfinite(b) || (a > 0) == (b > 0) || a == b) continue;
      const double k = s.k[i] + (s.k[i + 1] - s.k[i]) * a / (a - b);
      out += format_number(s.period[j]) + "," + format_number(k) + "\n";
    }
  return out;
}

void run_surface(const SurfaceOptions& o) {
  api::SurfaceRequest request;
  request.integrator = integrator_overrides(o.common);
  request.k_from = o.k_from;
  request.k_to = o.k_to;
  request.period_from = o.p_from;
  request.period_to = o.p_to;
  request.nk = o.nk;
  request.np = o.np;
  request.threads = o.threads;
  const Scene scene = load_scene_option(o.common);
  const sim::SimulationSpec spec =
      api::prepare_surface(scene, request, api::Spelling::kCommandLine);
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  const bool plots = !dir.empty() && !o.common.no_plot;
  if (plots) require_gnuplot();

  const auto engine =
      make_sweep_engine(static_cast<unsigned>(o.threads), o.threads_opt->count() > 0);
  std::cerr << "flatland: s_h(T) on a " << o.nk << " x " << o.np << " grid (k x 2T) on "
            << where_it_runs(*engine) << "\n";
  const auto start = std::chrono::steady_clock::now();
  sim::SurfaceResult s;
  {
    ProgressBar bar("surface");
    s = api::surface(spec, request, bar.callback(), engine.get());
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  OutputSet outputs(o.common.force);
  std::string csv_path, png_path;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "surface.csv", surface_csv(s));
    csv_path = (dir / "surface.csv").string();
    if (plots) {
      // Colours symmetric about s_T = 0 so that the solution contour sits on the neutral colour.
      double m = 0;
      for (double v : s.s_T)
        if (std::isfinite(v)) m = std::max(m, std::abs(v));
      if (m == 0) m = 1;
      const std::string zeros = zero_crossings(s);
      std::string body = "$zero << EOD\n" + zeros +
                         "EOD\n"
                         "set title 's_h at t = T over the motion space (paper Fig. 6); s_h(T) = 0 "
                         "is the solution locus'\n"
                         "set xlabel '2T (s)'\n"
                         "set ylabel 'k'\n"
                         "set cblabel 's_h(T)' offset 1,0\n"
                         "set palette defined (-1 '#2166ac', 0 '#f7f7f7', 1 '#b2182b')\n"
                         "set cbrange [" +
                         format_number(-m) + ":" + format_number(m) +
                         "]\n"
                         "set autoscale xfix\n"
                         "set autoscale yfix\n"
                         "set key top left opaque box\n"
                         "plot datafile skip 1 using 2:1:3 with image notitle";
      if (!zeros.empty())
        body += ", \\\n     $zero using 1:2 with points pt 7 ps 0.6 lc 'black' title 's_h(T) = 0'";
      body += "\n";
      run_plot(outputs, dir, {"surface.gp", "surface.csv", "surface.png", body});
      png_path = (dir / "surface.png").string();
    }
    outputs.commit();
  }

  if (o.common.json) {
    Json j;
    j["nk"] = o.nk;
    j["np"] = o.np;
    j["csv"] = csv_path.empty() ? Json(nullptr) : Json(csv_path);
    j["png"] = png_path.empty() ? Json(nullptr) : Json(png_path);
    j["rhs_evals"] = s.rhs_evals;
    j["seconds"] = seconds;
    // Points whose run failed numerically: s_h(T) is NaN ("nan" in the CSV) there.
    Json failed = Json::array();
    for (const auto& f : s.numerical_failures)
      failed.push_back({{"k", s.k[f.i]}, {"period", s.period[f.j]}, {"failure", f.what}});
    j["numerical_failures"] = failed;
    emit_json(j);
    return;
  }
  double lo = INFINITY, hi = -INFINITY;
  for (double v : s.s_T)
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  std::cout << "flatland surface: " << o.nk << " x " << o.np << " runs (" << scene.origin << ") in "
            << format_number(std::round(seconds * 1000) / 1000) << " s, " << s.rhs_evals
            << " rhs evaluations\n"
            << "  s_h(T) ranges over [" << format_number(lo) << ", " << format_number(hi) << "]\n";
  if (!s.numerical_failures.empty())
    std::cout << "  " << s.numerical_failures.size()
              << " points failed numerically (left out, NaN); the first: "
              << s.numerical_failures.front().what << "\n";
  for (const auto& p : outputs.paths()) std::cout << "  wrote " << p << "\n";
}

}  // namespace

Command add_surface_command(CLI::App& app) {
  auto o = std::make_shared<SurfaceOptions>();
  CLI::App* cmd = add_command(app, "surface");
  add_common_options(
      *cmd, o->common,
      "Directory for surface.csv (k, period in s, s_T; k-major rows) and surface.png "
      "(heat map with the s_T = 0 contour) with its gnuplot script; created if "
      "missing. Default: no files",
      true);
  cmd->add_option("--k-from", o->k_from, "Smallest k (dimensionless). Default: -1.6");
  cmd->add_option("--k-to", o->k_to,
                  "Largest k (> K-FROM; the range must not contain -2). Default: -0.8");
  cmd->add_option("--nk", o->nk,
                  "Grid points in k (2 to 10000; nk x np at most 1000000). Default: 50");
  cmd->add_option("--period-from", o->p_from, "Shortest duration 2T, s (> 0). Default: 0.8 s");
  cmd->add_option("--period-to", o->p_to, "Longest duration 2T, s (> PERIOD-FROM). Default: 2.0 s");
  cmd->add_option("--np", o->np, "Grid points in 2T (2 to 10000). Default: 50");
  o->threads_opt = cmd->add_option(
      "--threads", o->threads,
      "Worker threads (>= 0; 0 = all cores; under mpirun: per rank, >= 1, default 1). Results do "
      "not depend on it. Default: 0");
  return {cmd, [o] { run_surface(*o); }};
}

}  // namespace flatland::app
