// flatland simulate: one run of the scene, with command-line overrides.
#include "common.hpp"

#include "flatland/sim/hybrid.hpp"

#include <algorithm>
#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct SimulateOptions {
  CommonOptions common;
  MuOption mu;
  std::string model;
  double period = 0, k = 0, sample_dt = 0, duration = 0;
  bool no_stop_on_contact_loss = false;
  CLI::Option* model_opt = nullptr;
  CLI::Option* period_opt = nullptr;
  CLI::Option* k_opt = nullptr;
  CLI::Option* sample_dt_opt = nullptr;
  CLI::Option* duration_opt = nullptr;
};

std::string hybrid_text(const sim::SimulationSpec& spec, const sim::RunResult& r) {
  // Six significant digits: these lines describe; the JSON has every digit.
  const auto format_number = [](double v) {
    std::ostringstream b;
    b.precision(6);
    b << v;
    return b.str();
  };
  std::ostringstream os;
  const sim::ContactLaw& law = spec.contact;
  os << "  contact            hybrid, mu = " << (law.mu ? format_number(*law.mu) : "unlimited");
  if (law.mu_kinetic) os << ", mu_k = " << format_number(*law.mu_kinetic);
  os << ", e = " << format_number(law.restitution);
  if (law.has_losses())
    os << "; rolling resistance " << format_number(law.rolling_resistance) << " m, drag "
       << format_number(law.drag) << " N s/m, " << format_number(law.drag_angular)
       << " N m s/rad";
  os << "\n  modes              ";
  bool first = true;
  for (int m = 0; m < 4; ++m) {
    if (r.stats.mode_time[m] <= 0) continue;
    os << (first ? "" : ", ") << sim::to_string(static_cast<sim::ContactMode>(m)) << " "
       << format_number(r.stats.mode_time[m]) << " s";
    first = false;
  }
  os << "; " << r.stats.mode_changes << " changes, " << r.stats.impacts << " impacts, ends "
     << sim::to_string(r.final.mode) << "\n";
  if (spec.object.kind != sim::ObjectSpec::Kind::kDisk && r.reason == sim::StopReason::kContactLost)
    os << "  note               flight and impacts are modelled for a disk only: the run stops "
          "where this object would lift off\n";
  int i = 0;
  for (const sim::FlightReport& f : sim::flight_reports(r)) {
    os << "  flight " << ++i << "           leaves at t = " << format_number(f.t_lift_off)
       << " s (s_h = " << format_number(f.s_lift_off) << ")";
    if (f.t_landing)
      os << ", lands at t = " << format_number(*f.t_landing) << " s on s_h = "
         << format_number(f.s_landing) << " (x = " << format_number(f.landing_position.x())
         << ", y = " << format_number(f.landing_position.y()) << " m) after "
         << format_number(*f.t_landing - f.t_lift_off) << " s, impulse "
         << format_number(f.impulse_normal) << " N s normal, "
         << format_number(f.impulse_tangential) << " N s tangential";
    if (f.bounces) os << ", " << f.bounces << " bounces";
    if (f.t_caught) os << ", caught at t = " << format_number(*f.t_caught) << " s";
    if (f.dropped) os << ", dropped (out of the hand's reach)";
    os << "\n";
  }
  return os.str();
}

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
  apply_mu_option(o.mu, spec);
  if (o.model_opt && o.model_opt->count())
    spec.run.model = o.model == "hybrid" ? sim::ContactModel::kHybrid : sim::ContactModel::kRolling;
  if (o.no_stop_on_contact_loss && spec.run.model == sim::ContactModel::kHybrid)
    throw UsageError(
        "--no-stop-on-contact-loss: only for the rolling model (the hybrid model flies where "
        "contact is lost)");
  std::vector<std::pair<std::string, std::string>> given;
  if (o.k_opt->count()) given.emplace_back("motion.k", "--k");
  if (o.period_opt->count()) given.emplace_back("motion.period", "--period");
  if (o.mu.opt->count()) given.emplace_back("contact.mu", "--mu");
  if (o.model_opt->count()) given.emplace_back("contact.model", "--model");
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
    j["model"] = sim::to_string(spec.run.model);
    j["mu"] = spec.contact.mu ? number(*spec.contact.mu) : Json(nullptr);
    j["end_mode"] = sim::to_string(r.final.mode);
    j["mode_changes"] = r.stats.mode_changes;
    j["impacts"] = r.stats.impacts;
    Json modes;
    for (int m = 0; m < 4; ++m)
      modes[sim::to_string(static_cast<sim::ContactMode>(m))] = number(r.stats.mode_time[m]);
    j["mode_time"] = modes;
    j["flights"] = flights_json(sim::flight_reports(r));
    j["events"] = contact_events_json(r.events);
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
     << "  f_n at apex        " << format_number(fn_apex) << " m g sin(tilt)\n"
     << "  min f_n            " << format_number(r.fn_min_ratio) << " m g sin(tilt)"
     << (contact_lost ? "  (contact lost)" : "") << "\n"
     << "  required mu        " << format_number(r.mu_required) << "\n"
     << "  steps              " << r.stats.steps << " accepted, " << r.stats.rejected
     << " rejected, " << r.stats.rhs_evals << " rhs evaluations\n";
  if (spec.run.model == sim::ContactModel::kHybrid) os << hybrid_text(spec, r);
  if (!out.empty()) os << "  wrote              " << out.string() << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_simulate_command(CLI::App& app) {
  auto o = std::make_shared<SimulateOptions>();
  CLI::App* cmd = add_command(app, "simulate");
  add_common_options(
      *cmd, o->common,
      "Write the trajectory as CSV to this file (SI units: t in s, angles in rad, "
      "lengths in m, forces in N; ratios to the in-plane weight m g sin(tilt)). Default: no file",
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
                "Rolling model: keep integrating (rolling enforced) where the normal force "
                "reaches 0. Default: stop there");
  o->model_opt = cmd->add_option("--model", o->model,
                                 "Contact model: rolling (the paper's: rolling enforced, it stops "
                                 "where contact is lost or, with mu, where it slips) or hybrid "
                                 "(it slides, flies, bounces and is caught, with the scene's "
                                 "losses). Default: the scene's contact.model, else rolling")
                     ->check(CLI::IsMember({"rolling", "hybrid"}));
  add_mu_option(*cmd, o->mu,
                "Static friction coefficient (>= 0): the rolling model stops where the disk would "
                "slip, the hybrid model slides. Default: the scene's contact.mu, else unlimited");
  return {cmd, [o] { run_simulate(*o); }};
}

}  // namespace flatland::app
