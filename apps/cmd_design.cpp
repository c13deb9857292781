// flatland design: the hand's shape and the butterfly's motion designed together (docs/DESIGN.md),
// objective 1: the least friction a butterfly of a given period needs.
#include "common.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/sensitivity.hpp"

#include <cmath>
#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct DesignOptions {
  CommonOptions common;
  api::DesignRequest request;
  double period = 0;
  CLI::Option* period_opt = nullptr;
  MuOption mu;
};

std::string iterate_line(const design::Iterate& it) {
  std::ostringstream s;
  s << "  " << it.evaluation << ":";
  for (std::size_t i = 0; i < it.parameters.size(); ++i)
    s << " " << sim::kButterflyParameters[i] << " " << sim::format_significant(it.parameters[i], 6);
  s << " | mu " << sim::format_significant(it.mu_required, 6);
  if (!std::isnan(it.robustness)) s << ", robustness " << sim::format_significant(it.robustness, 6);
  s << ", s_h(T) " << sim::format_significant(it.s_T, 3) << ", min f_n/mg "
    << sim::format_significant(it.fn_min_ratio, 4) << (it.feasible ? "" : " (infeasible)");
  return s.str();
}

std::string iterates_csv(const design::DesignResult& r) {
  std::ostringstream s;
  s << "evaluation";
  for (auto name : sim::kButterflyParameters) s << "," << name;
  s << ",mu_required,s_T,fn_min_ratio,feasible\n";
  for (const auto& it : r.iterates) {
    s << it.evaluation;
    for (double v : it.parameters) s << "," << sim::format_number(v);
    s << "," << sim::format_number(it.mu_required) << "," << sim::format_number(it.s_T) << ","
      << sim::format_number(it.fn_min_ratio) << "," << (it.feasible ? 1 : 0) << "\n";
  }
  return s.str();
}

void run_design(const DesignOptions& o) {
  api::DesignRequest request = o.request;
  request.integrator = integrator_overrides(o.common);
  if (o.period_opt->count()) request.period = o.period;
  if (o.mu.opt->count()) request.mu = o.mu.value;
  const Scene scene = load_scene_option(o.common);
  const sim::SimulationSpec spec = api::prepare_design(scene, request, api::Spelling::kCommandLine);
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  if (!dir.empty() && !o.common.no_plot) require_gnuplot();

  const bool robustness = request.objective == "robustness";
  const std::string goal =
      robustness ? "the largest robustness margin at mu = " + format_number(*spec.contact.mu)
                 : std::string("the least friction");
  std::cerr << "flatland: designing " << (request.motion_only ? "the motion" : "shape and motion")
            << " for " << goal << " at 2T = " << format_number(spec.motion.period) << " s ("
            << scene.origin << ")\n";
  const design::DesignResult r = api::design(
      spec, request, [](const design::Iterate& it) { std::cerr << iterate_line(it) << "\n"; });

  OutputSet outputs(o.common.force);
  if (!dir.empty()) {
    // The best design's solution, run again recorded and audited, as `solve --out` writes one.
    const design::Parameters& p = r.best.parameters;
    write_solution_outputs(outputs, dir, sim::evaluate(design::spec_with(spec, p), p[5], p[4]).run,
                           o.common.no_plot);
    outputs.stage(dir / "iterates.csv", iterates_csv(r));
    outputs.commit();
  }
  if (o.common.json) {
    api::Json j = api::design_json(r, spec);
    j["files"] = outputs.paths();
    emit_json(j);
    return;
  }
  std::cout << "flatland design: " << goal << " at 2T = " << format_number(spec.motion.period)
            << " s, " << (request.motion_only ? "motion only" : "shape and motion") << " ("
            << scene.origin << ")\n"
            << "  start (k solved)  " << iterate_line(r.start_point) << "\n"
            << "  best              " << iterate_line(r.best) << "\n";
  if (!r.best.feasible) std::cout << "  no feasible design was found\n";
  for (const auto& a : r.active) std::cout << "  binding           " << a << "\n";
  if (!r.restore_stop.empty())
    std::cout << "  margin restored   " << (r.restored ? "yes" : "no") << " (" << r.restore_stop
              << ")\n";
  std::cout << "  stopped           " << r.stop << "\n"
            << "  evaluations       " << r.iterates.size() << " (" << r.simulations << " runs)\n";
  for (const auto& path : outputs.paths()) std::cout << "  wrote             " << path << "\n";
}

}  // namespace

Command add_design_command(CLI::App& app) {
  auto o = std::make_shared<DesignOptions>();
  CLI::App* cmd = add_command(app, "design");
  add_common_options(*cmd, o->common,
                     "Directory for the best design's solution (trajectory.csv every 1 ms, SI "
                     "units; trajectory.png and forces.png with their gnuplot scripts) and "
                     "iterates.csv (every evaluation); created if missing. Default: no files",
                     true);
  cmd->add_option("--objective", o->request.objective,
                  "What to optimise: least-friction (the least mu a butterfly of the period "
                  "needs, keeping --fn-margin) or robustness (the largest margin, over the "
                  "motion until T, of (mu f_n - |f_t|) and f_n per in-plane weight m g "
                  "sin(tilt), at --mu). shortest-period is not built yet. Default: "
                  "least-friction");
  add_mu_option(*cmd, o->mu,
                "Static friction coefficient (> 0) for --objective robustness. Default: the "
                "scene's contact.mu");
  o->period_opt = cmd->add_option("--period", o->period,
                                  "Butterfly duration 2T, s (> 0), held. Default: the scene's "
                                  "motion.period (paper: 1.181 s)");
  cmd->add_flag("--motion-only", o->request.motion_only,
                "Hold the scene's hand: k alone is free (the paper's own search). Default: off");
  cmd->add_option("--shape-range", o->request.shape_range,
                  "Each of a, b, c, d stays within this fraction of the scene's value, in (0, 1). "
                  "Default: 0.25");
  cmd->add_option("--fn-margin", o->request.fn_margin,
                  "least-friction: keep the normal force >= this fraction of the in-plane weight "
                  "m g sin(tilt) until T (>= 0). Default: 0.05");
  cmd->add_option("--max-evaluations", o->request.max_evaluations,
                  "Most evaluations of each search (each one run set with sensitivities), in "
                  "[1, 100000]. Default: 100");
  cmd->add_option("--tolerance", o->request.tolerance,
                  "Relative change of the variables that ends the search, in (0, 1). Default: "
                  "1e-7");
  return {cmd, [o] { run_design(*o); }};
}

}  // namespace flatland::app
