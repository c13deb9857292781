// flatland time-optimal: the fastest butterfly that keeps contact (paper section 4.3: 2T = 1.095 s,
// k = -1.1493, the normal force reaching 0 at the apex).
#include "common.hpp"

#include <iostream>
#include <memory>

namespace flatland::app {

namespace {

struct TimeOptimalOptions {
  CommonOptions common;
  MuOption mu;
  double from = 0.9, to = 1.5, period_tolerance = 1e-7, tolerance = 1e-9;
};

void run_time_optimal(const TimeOptimalOptions& o) {
  api::TimeOptimalRequest request;
  request.integrator = integrator_overrides(o.common);
  if (o.mu.opt->count()) request.mu = o.mu.value;
  request.from = o.from;
  request.to = o.to;
  request.period_tolerance = o.period_tolerance;
  request.tolerance = o.tolerance;
  const Scene scene = load_scene_option(o.common);
  const sim::SimulationSpec spec =
      api::prepare_time_optimal(scene, request, api::Spelling::kCommandLine);
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  if (!dir.empty() && !o.common.no_plot) require_gnuplot();
  const bool friction = spec.contact.mu.has_value();

  std::cerr << "flatland: searching the fastest butterfly keeping contact"
            << (friction ? " within mu = " + format_number(*spec.contact.mu) : std::string())
            << " in [" << format_number(o.from) << ", " << format_number(o.to) << "] s\n";
  const sim::TimeOptimalReport r = api::time_optimal(spec, request);

  OutputSet outputs(o.common.force);
  if (!dir.empty()) {
    write_solution_outputs(outputs, dir, r.solution.run, o.common.no_plot);
    outputs.commit();
  }
  if (o.common.json) {
    Json j = api::time_optimal_json(r, spec);
    j["files"] = outputs.paths();
    emit_json(j);
    return;
  }
  std::cout << "flatland time-optimal: fastest butterfly keeping f_n >= 0"
            << (friction ? " and |f_t| <= mu f_n, mu = " + format_number(*spec.contact.mu)
                         : std::string(" (no mu: friction unlimited)"))
            << " (" << scene.origin << "), " << r.solves << " solves\n"
            << "  limited by         "
            << (r.limit == sim::SpeedLimit::kFriction ? "friction (the disk would slip)"
                                                     : "the normal force (the hand would throw "
                                                       "the disk)")
            << "\n"
            << solve_report_text(r.solution);
  for (const auto& p : outputs.paths()) std::cout << "  wrote              " << p << "\n";
}

}  // namespace

Command add_time_optimal_command(CLI::App& app) {
  auto o = std::make_shared<TimeOptimalOptions>();
  CLI::App* cmd = add_command(app, "time-optimal");
  add_common_options(*cmd, o->common,
                     "Directory for the solution's trajectory.csv (every 1 ms; SI units), "
                     "trajectory.png and forces.png with their gnuplot scripts; created if "
                     "missing. Default: no files",
                     true);
  add_mu_option(*cmd, o->mu,
                "Static friction coefficient (>= 0) the solution may need at most. Default: the "
                "scene's contact.mu, else unlimited (only the normal force limits)");
  cmd->add_option("--from", o->from, "Lower end of the 2T bracket, s (> 0). Default: 0.9 s");
  cmd->add_option("--to", o->to, "Upper end of the 2T bracket, s (> FROM). Default: 1.5 s");
  cmd->add_option("--period-tolerance", o->period_tolerance,
                  "Bracket width at which the search in 2T stops, s (> 0). Default: 1e-7 s");
  cmd->add_option("--tolerance", o->tolerance,
                  "Root bracket width in k for each solve (dimensionless, > 0). Default: 1e-9");
  return {cmd, [o] { run_time_optimal(*o); }};
}

}  // namespace flatland::app
