// flatland simulate: one run of the scene, with command-line overrides.
#include "common.hpp"

#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct SimulateOptions {
  CommonOptions common;
  double period = 0, k = 0, sample_dt = 0, duration = 0;
  bool no_stop_on_contact_loss = false;
  CLI::Option* period_opt = nullptr;
  CLI::Option* k_opt = nullptr;
  CLI::Option* sample_dt_opt = nullptr;
  CLI::Option* duration_opt = nullptr;
};

void run_simulate(const SimulateOptions& o) {
  // Everything that can be bad input is checked before anything is computed or written.
  Scene scene = load_scene_with_overrides(o.common);
  sim::SimulationSpec& spec = scene.sim;
  const bool butterfly = spec.motion.kind == sim::MotionSpec::Kind::kButterfly;
  if ((o.period_opt->count() || o.k_opt->count()) && !butterfly)
    throw UsageError("--period/--k: the scene's motion is not the butterfly (motion.kind)");
  if (o.period_opt->count()) {
    require_positive("--period", o.period, "2T in s");
    spec.motion.period = o.period;
    if (!o.duration_opt->count()) spec.duration.reset();  // simulate the new 2T, not the scene's
  }
  if (o.k_opt->count()) {
    require_finite("--k", o.k);
    spec.motion.k = o.k;
  }
  if (o.duration_opt->count()) {
    require_positive("--duration", o.duration, "s");
    spec.duration = o.duration;
  }
  if (o.sample_dt_opt->count()) require_positive("--sample-dt", o.sample_dt, "s");
  if (o.no_stop_on_contact_loss) spec.run.events.stop_on_contact_loss = false;
  std::vector<std::pair<std::string, std::string>> given;
  if (o.k_opt->count()) given.emplace_back("motion.k", "--k");
  if (o.period_opt->count()) given.emplace_back("motion.period", "--period");
  const auto problem = build_problem_checked(spec, given);
  sim::resolve_formulation(*problem, spec.run.formulation);  // e.g. reduced for an ellipse

  OutputSet outputs(o.common.force);
  const fs::path out = o.common.out;
  if (!out.empty() && (o.common.out.back() == '/' || fs::is_directory(out)))
    throw UsageError("--out: must be a file name (FILE.csv), not a directory: " + o.common.out);
  if (!out.empty()) check_output_file("--out", out, o.common.force);

  std::cerr << "flatland: simulating " << scene.origin << " for "
            << format_number(spec.end_time() - spec.initial.t0) << " s\n";
  sim::RunOptions run_opts = sim::run_options(spec);
  run_opts.record = true;  // the report needs the dense output and the per-step samples
  const sim::RunResult r = sim::simulate(problem, spec.initial, run_opts);

  if (!out.empty()) {
    if (r.trajectory.empty()) throw std::runtime_error("the run recorded no trajectory");
    outputs.ensure_directory(out.parent_path());
    const std::vector<sim::Sample>& rows =
        o.sample_dt_opt->count() ? r.trajectory.resample(o.sample_dt) : r.steps;
    outputs.stage(out, samples_csv(rows));
    outputs.commit();
  }

  const double s_T = s_at_half_period(spec, r);
  const double fn_apex = r.fn_apex_ratio ? *r.fn_apex_ratio : std::nan("");
  const bool contact_lost = r.contact_lost || r.fn_min_ratio < 0;
  if (o.common.json) {
    Json j;
    j["period"] = butterfly ? number(spec.motion.period) : Json(nullptr);
    j["k"] = butterfly ? number(spec.motion.k) : Json(nullptr);
    j["s_T"] = number(s_T);
    j["s_end"] = number(r.final.s_h);
    j["sdot_end"] = number(r.final.sdot_h);
    j["fn_apex_ratio"] = number(fn_apex);
    j["fn_min_ratio"] = number(r.fn_min_ratio);
    j["mu_required"] = number(r.mu_required);
    j["steps"] = r.stats.steps;
    j["rhs_evals"] = r.stats.rhs_evals;
    j["contact_lost"] = contact_lost;
    j["formulation"] = sim::to_string(r.formulation);
    j["method"] = sim::to_string(r.method);
    j["stop_reason"] = sim::to_string(r.reason);
    j["t_end"] = number(r.final.t);
    j["rejected"] = r.stats.rejected;
    j["restarts"] = r.stats.restarts;
    j["junction_crossings"] = r.stats.junction_crossings;
    j["max_constraint_residual"] = number(r.stats.max_constraint_residual);
    j["max_redundant_residual"] = number(r.stats.max_redundant_residual);
    j["csv"] = out.empty() ? Json(nullptr) : Json(out.string());
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland simulate: " << scene.origin << (scene.name.empty() ? "" : " (" + scene.name + ")")
     << "\n";
  if (butterfly)
    os << "  motion             butterfly, 2T = " << format_number(spec.motion.period)
       << " s, k = " << format_number(spec.motion.k) << "\n";
  else
    os << "  motion             fixed hand at " << format_number(spec.motion.angle) << " rad\n";
  os << "  formulation        " << sim::to_string(r.formulation) << ", " << sim::to_string(r.method)
     << "\n"
     << "  stopped            " << sim::to_string(r.reason)
     << " at t = " << format_number(r.final.t) << " s\n"
     << "  s_h(T)             " << format_number(s_T) << "\n"
     << "  s_h(end), rate     " << format_number(r.final.s_h) << ", "
     << format_number(r.final.sdot_h) << " 1/s\n"
     << "  f_n at apex / mg   " << format_number(fn_apex) << "\n"
     << "  min f_n / mg       " << format_number(r.fn_min_ratio)
     << (contact_lost ? "  (contact lost)" : "") << "\n"
     << "  required mu        " << format_number(r.mu_required) << "\n"
     << "  steps              " << r.stats.steps << " accepted, " << r.stats.rejected
     << " rejected, " << r.stats.rhs_evals << " rhs evaluations\n";
  if (!out.empty()) os << "  wrote              " << out.string() << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_simulate_command(CLI::App& app) {
  auto o = std::make_shared<SimulateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "simulate",
      "Simulate the scene once (default: the paper's butterfly, 2T = 1.181 s, k = -1.1393) and "
      "report where the disk ends and the contact forces. Command-line values override the scene.");
  add_common_options(*cmd, o->common,
                     "Write the trajectory as CSV to this file (SI units: t in s, angles in rad, "
                     "lengths in m, forces in N; ratios to m g). Default: no file",
                     false);
  o->period_opt = cmd->add_option("--period", o->period,
                                  "Butterfly duration 2T, s (> 0); also sets the simulated "
                                  "time to 2T unless --duration is given. Default: the scene's "
                                  "motion.period (paper: 1.181 s)");
  o->k_opt = cmd->add_option("--k", o->k,
                             "Butterfly dip parameter k (dimensionless; -2/3 = no dip, k = -2 is "
                             "invalid). Default: the scene's motion.k (paper: -1.1393)");
  o->duration_opt = cmd->add_option("--duration", o->duration,
                                    "Simulated time, s (> 0). Default: the scene's duration, else "
                                    "2T for the butterfly, else 1 s");
  o->sample_dt_opt = cmd->add_option("--sample-dt", o->sample_dt,
                                     "CSV row spacing, s (> 0), from the dense output. Default: "
                                     "one row per accepted integrator step");
  cmd->add_flag("--no-stop-on-contact-loss", o->no_stop_on_contact_loss,
                "Keep integrating (rolling enforced) where the normal force reaches 0. Default: "
                "stop there");
  return {cmd, [o] { run_simulate(*o); }};
}

}  // namespace flatland::app
