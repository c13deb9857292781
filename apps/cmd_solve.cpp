// flatland solve: the butterfly solution for one period (paper section 4.3): the k (or hand shape
// d) that brings the disk to s_h(T) = 0.
#include "common.hpp"

#include <iostream>
#include <memory>

namespace flatland::app {

namespace {

struct SolveOptions {
  CommonOptions common;
  double period = 0, k = 0, tolerance = 1e-9;
  std::string solve_for = "k";
  CLI::Option* period_opt = nullptr;
  CLI::Option* k_opt = nullptr;
};

void run_solve(const SolveOptions& o) {
  api::SolveRequest request;
  request.integrator = integrator_overrides(o.common);
  if (o.period_opt->count()) request.period = o.period;
  if (o.k_opt->count()) request.k = o.k;
  request.solve_for = o.solve_for;
  request.tolerance = o.tolerance;
  const Scene scene = load_scene_option(o.common);
  const sim::SimulationSpec spec = api::prepare_solve(scene, request, api::Spelling::kCommandLine);
  const bool plots = !o.common.out.empty() && !o.common.no_plot;
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  if (plots) require_gnuplot();

  const bool for_d = o.solve_for == "d";
  std::cerr << "flatland: solving for " << o.solve_for
            << " at 2T = " << format_number(spec.motion.period) << " s (" << scene.origin << ")\n";
  const sim::SolveReport r = api::solve(spec, request);

  OutputSet outputs(o.common.force);
  if (!dir.empty()) {
    write_solution_outputs(outputs, dir, r.run, o.common.no_plot);
    outputs.commit();
  }
  if (o.common.json) {
    Json j = solve_report_json(r);
    if (for_d) j["d"] = number(r.d);
    j["files"] = outputs.paths();
    emit_json(j);
    return;
  }
  std::cout << "flatland solve: butterfly solution (" << scene.origin << ")\n"
            << solve_report_text(r);
  if (for_d) std::cout << "  hand shape d       " << format_number(r.d) << " m\n";
  for (const auto& p : outputs.paths()) std::cout << "  wrote              " << p << "\n";
}

}  // namespace

Command add_solve_command(CLI::App& app) {
  auto o = std::make_shared<SolveOptions>();
  CLI::App* cmd = add_command(app, "solve");
  add_common_options(*cmd, o->common,
                     "Directory for trajectory.csv (the solution every 1 ms; SI units), "
                     "trajectory.png (theta and s_h against t) and forces.png (contact force "
                     "ratios, required mu), with their gnuplot scripts; created if missing. "
                     "Default: no files",
                     true);
  o->period_opt = cmd->add_option("--period", o->period,
                                  "Butterfly duration 2T, s (> 0). Default: the scene's "
                                  "motion.period (paper: 1.181 s)");
  o->k_opt = cmd->add_option("--k", o->k,
                             "Dip parameter k (dimensionless, not -2). Solving for k: the starting "
                             "guess; solving for d: the motion's k. Default: the scene's motion.k "
                             "(paper: -1.1393)");
  cmd->add_option("--solve-for", o->solve_for,
                  "Unknown: k (the motion's dip) or d (the hand shape's cubic coefficient, m, with "
                  "a, b, c from the scene). Default: k")
      ->check(CLI::IsMember({"k", "d"}));
  cmd->add_option("--tolerance", o->tolerance,
                  "Root bracket width: in k (dimensionless), or for d relative to max(|a|, |b|) "
                  "(> 0). Default: 1e-9");
  return {cmd, [o] { run_solve(*o); }};
}

}  // namespace flatland::app
