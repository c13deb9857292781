// flatland locus: the butterfly solutions k(2T) over a range of durations (paper Fig. 7).
#include "common.hpp"

#include <chrono>
#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct LocusOptions {
  CommonOptions common;
  MuOption mu;
  double from = 1.1, to = 3.0, tolerance = 1e-9;
  int n = 20;
};

std::string locus_csv(const std::vector<sim::SolveReport>& points) {
  std::string s =
      "period,k,fn_min_ratio,fn_apex_ratio,mu_required,s_end,sdot_end,friction_margin\n";
  for (const auto& p : points)
    s += format_number(p.period) + "," + format_number(p.k) + "," + format_number(p.fn_min_ratio) +
         "," + format_number(p.fn_apex_ratio) + "," + format_number(p.mu_required) + "," +
         format_number(p.s_end) + "," + format_number(p.sdot_end) + "," +
         format_number(p.friction_margin) + "\n";
  return s;
}

void run_locus(const LocusOptions& o) {
  api::LocusRequest request;
  request.integrator = integrator_overrides(o.common);
  if (o.mu.opt->count()) request.mu = o.mu.value;
  request.from = o.from;
  request.to = o.to;
  request.n = o.n;
  request.tolerance = o.tolerance;
  const Scene scene = load_scene_option(o.common);
  const sim::SimulationSpec spec = api::prepare_locus(scene, request, api::Spelling::kCommandLine);
  const bool friction = spec.contact.mu.has_value();
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  const bool plots = !dir.empty() && !o.common.no_plot;
  if (plots) require_gnuplot();

  std::cerr << "flatland: solving the locus at " << o.n << " periods in [" << format_number(o.from)
            << ", " << format_number(o.to) << "] s\n";
  const auto start = std::chrono::steady_clock::now();
  std::vector<sim::SolveReport> points;
  {
    ProgressBar bar("locus");
    points = api::locus(spec, request, bar.callback());
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  OutputSet outputs(o.common.force);
  std::string csv_path, png_path;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "locus.csv", locus_csv(points));
    csv_path = (dir / "locus.csv").string();
    if (plots) {
      run_plot(outputs, dir,
               {"locus.gp", "locus.csv", "locus.png",
                "set multiplot layout 2,1 title 'Butterfly solutions (paper Fig. 7)'\n"
                "set grid\n"
                "set xlabel '2T (s)'\n"
                "set ylabel 'k'\n"
                "plot datafile skip 1 using 1:2 with linespoints lw 2 pt 7 title 'k solving s_h(T) "
                "= 0'\n"
                "set ylabel 'min f_n / (m g sin(tilt)), the in-plane weight'\n"
                "set key bottom right\n"
                "plot datafile skip 1 using 1:3 with linespoints lw 2 pt 7 title 'minimum normal "
                "force ratio', "
                "0 with lines lc 'black' notitle\n"
                "unset multiplot\n"});
      png_path = (dir / "locus.png").string();
    }
    outputs.commit();
  }

  if (o.common.json) {
    Json j = api::locus_json(points, spec);
    j["csv"] = csv_path.empty() ? Json(nullptr) : Json(csv_path);
    j["png"] = png_path.empty() ? Json(nullptr) : Json(png_path);
    j["seconds"] = seconds;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland locus: " << points.size() << " solutions (" << scene.origin << ")"
     << (friction ? ", mu = " + format_number(*spec.contact.mu) : std::string()) << "\n"
     << "  (forces in units of the in-plane weight m g sin(tilt))\n"
     << "      2T (s)            k     min f_n  required mu"
     << (friction ? "  friction margin" : "") << "\n";
  for (const auto& p : points) {
    char line[160];
    std::snprintf(line, sizeof line, "  %10.5f  %11.6f  %11.5f  %11.5f", p.period, p.k,
                  p.fn_min_ratio, p.mu_required);
    os << line;
    if (friction) {
      std::snprintf(line, sizeof line, "  %15.5f", p.friction_margin);
      os << line;
    }
    os << (p.fn_min_ratio < 0 ? "  contact lost" : "")
       << (friction && p.friction_margin < 0 ? "  slips" : "")
       << (p.failure.empty() ? "" : "  " + p.failure) << "\n";
  }
  for (const auto& p : outputs.paths()) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_locus_command(CLI::App& app) {
  auto o = std::make_shared<LocusOptions>();
  CLI::App* cmd = add_command(app, "locus");
  add_common_options(*cmd, o->common,
                     "Directory for locus.csv (period in s, k, fn_min_ratio, fn_apex_ratio, "
                     "mu_required, s_end, sdot_end in 1/s, friction_margin) and locus.png with its "
                     "gnuplot script; "
                     "created if missing. Default: no files",
                     true);
  add_mu_option(*cmd, o->mu,
                "Static friction coefficient (>= 0): each solution reports its friction margin, "
                "min (mu f_n - |f_t|) / (m g sin(tilt)) (< 0: it would slip). Default: the scene's "
                "contact.mu, "
                "else none reported");
  cmd->add_option("--from", o->from, "Shortest duration 2T, s (> 0). Default: 1.1 s");
  cmd->add_option("--to", o->to, "Longest duration 2T, s (> FROM). Default: 3.0 s");
  cmd->add_option("--n", o->n, "Number of durations (1 to 10000; 1 solves at FROM only). Default: 20");
  cmd->add_option("--tolerance", o->tolerance,
                  "Root bracket width in k (dimensionless, > 0). Default: 1e-9");
  return {cmd, [o] { run_locus(*o); }};
}

}  // namespace flatland::app
