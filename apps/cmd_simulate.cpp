// flatland simulate: one run of the scene, with command-line overrides.
#include "common.hpp"

#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/spatial_spec.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include <algorithm>
#include <cmath>
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
  bool no_plot = false;
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
       << format_number(law.drag) << " N s/m, " << format_number(law.drag_angular) << " N m s/rad";
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
  if (!spec.object.round() && r.reason == sim::StopReason::kContactLost)
    os << "  note               flight and impacts are modelled for a disk only: the run stops "
          "where this object would lift off\n";
  int i = 0;
  for (const sim::FlightReport& f : sim::flight_reports(r)) {
    os << "  flight " << ++i << "           leaves at t = " << format_number(f.t_lift_off)
       << " s (s_h = " << format_number(f.s_lift_off) << ")";
    if (f.t_landing)
      os << ", lands at t = " << format_number(*f.t_landing)
         << " s on s_h = " << format_number(f.s_landing)
         << " (x = " << format_number(f.landing_position.x())
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

/// The energy audit's line of the summary (docs/DYNAMICS.md, "Energy audit").
std::string energy_text(const sim::EnergyAudit& a) {
  const auto f3 = [](double v) { return sim::format_significant(v, 3); };
  return "  energy balance     " + f3(a.balance) + " J (bound " + f3(a.bound()) + " J): E " +
         f3(a.initial) + " -> " + f3(a.final) + " J, hand " + f3(a.work_hand) + " J, losses " +
         f3(a.work_losses) + " J, impacts " + f3(a.impact_losses) + " J" +
         (a.broken ? "  (BROKEN: numerical failure)" : "") + "\n";
}

/// A run whose energy balance broke is a runtime failure (exit 1) once its report is printed:
/// its numbers are wrong from the breach on.
void fail_if_broken(const sim::EnergyAudit& a) {
  if (a.broken) throw std::runtime_error(api::energy_failure_text(a));
}

/// The y range of a panel whose values `v` do not vary beyond rounding: gnuplot would spread the
/// rounding over the whole axis and label every tick with the same number. Such a quantity is
/// drawn on a range of +-0.1 % of itself (at least 1e-9: a flat line with distinct tick labels)
/// and its panel's title says that it is constant to the digits it keeps; a varying one is left
/// to gnuplot's autoscale.
std::string constant_axis(const std::vector<double>& v, std::string& title) {
  const std::string autoscale = "set autoscale y\nset format y '% h'\n";
  if (v.empty()) return autoscale;
  const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
  const double mid = 0.5 * (*lo + *hi), spread = *hi - *lo;
  const double size = std::max(std::abs(mid), 1e-300);
  if (!(spread <= 1e-9 * size) || !std::isfinite(mid)) return autoscale;
  const int digits =
      spread > 0 ? std::min(15, static_cast<int>(std::floor(-std::log10(spread / size)))) : 15;
  title += " (constant: " + sim::format_significant(mid, 6) + " to " + std::to_string(digits) +
           " digits)";
  const double half = std::max(1e-3 * std::abs(mid), 1e-9);
  return "set yrange [" + sim::format_number(mid - half) + ":" + sim::format_number(mid + half) +
         "]\nset format y '%.7g'\n";
}

/// The plot beside a spatial run's CSV: the contact's path over the hand's surface coordinates,
/// the object's path in the world (seen from above, and its height) and the contact force. A
/// panel whose quantity stays constant says so instead of drawing its rounding at full scale.
std::string spatial_plot(const std::string& title, const std::vector<sim::SpatialSample>& samples) {
  const auto col = [](const char* name) {
    return std::to_string(sim::spatial_sample_column(name));
  };
  std::vector<double> heights, forces;  // the two panels' values (the forces': both curves)
  for (const sim::SpatialSample& q : samples) {
    heights.push_back(q.state.position.z());
    forces.push_back(q.force_normal);
    forces.push_back(
        std::sqrt(std::max(0.0, q.force.squaredNorm() - q.force_normal * q.force_normal)));
  }
  std::string height_title = "object centre height", force_title = "contact force on the object";
  const std::string height_range = constant_axis(heights, height_title);
  const std::string force_range = constant_axis(forces, force_title);
  return "set multiplot layout 2,2 title " + gnuplot_quote(title) +
         "\n"
         "set grid\n"
         "set title 'contact path on the hand (surface coordinates)'\n"
         "set xlabel 'u_h'\nset ylabel 'v_h'\n"
         "plot datafile skip 1 using " +
         col("sh_u") + ":" + col("sh_v") +
         " with lines lw 2 notitle\n"
         "set title 'object centre, seen along z (m)'\n"
         "set xlabel 'x'\nset ylabel 'y'\nset size ratio -1\nset xtics rotate by 45 right\n"
         "plot datafile skip 1 using " +
         col("x") + ":" + col("y") +
         " with lines lw 2 notitle\n"
         "set size noratio\nset xtics norotate\n"
         "set title " +
         gnuplot_quote(height_title) +
         "\n"
         "set xlabel 't (s)'\nset ylabel 'z (m)'\n" +
         height_range + "plot datafile skip 1 using " + col("t") + ":" + col("z") +
         " with lines lw 2 notitle\n"
         "set title " +
         gnuplot_quote(force_title) +
         "\n"
         "set xlabel 't (s)'\nset ylabel 'N'\n" +
         force_range + "plot datafile skip 1 using " + col("t") + ":" + col("f_n") +
         " with lines lw 2 title 'normal', datafile skip 1 using " + col("t") + ":(sqrt(($" +
         col("f_x") + ")**2 + ($" + col("f_y") + ")**2 + ($" + col("f_z") + ")**2 - ($" +
         col("f_n") +
         ")**2)) with lines lw 2 title 'tangential'\n"
         "unset multiplot\n";
}

void run_simulate_spatial(const SimulateOptions& o, const Scene& scene,
                          const api::SimulateRequest& request) {
  // Everything that can be bad input is checked before anything is computed or written.
  const sim::SpatialSpec spec =
      api::prepare_spatial_simulate(scene, request, api::Spelling::kCommandLine);
  if (o.sample_dt_opt->count())
    api::require_sample_spacing("--sample-dt", o.sample_dt, spec.end_time());
  sim::SpatialSetup setup;
  try {
    setup = sim::build_spatial(spec);
  } catch (const std::invalid_argument& e) {
    throw UsageError(scene.origin + ": " + e.what());
  }
  if (o.sample_dt_opt->count()) setup.options.sample_dt = o.sample_dt;
  const fs::path out = o.common.out;
  // Samples are kept only for the CSV: without --out the run's memory does not grow with time.
  setup.options.record = !out.empty();
  if (!out.empty() && (o.common.out.back() == '/' || fs::is_directory(out)))
    throw UsageError("--out: must be a file name (FILE.csv), not a directory: " + o.common.out);
  const bool plots = !out.empty() && !o.no_plot;
  fs::path png, script;
  if (!out.empty()) {
    check_output_file("--out", out, o.common.force);
    png = fs::path(out).replace_extension(".png");
    script = fs::path(out).replace_extension(".gp");
    if (plots) {
      if (png == out) throw UsageError("--out: the CSV cannot be named .png (the plot is)");
      check_output_file("--out", png, o.common.force);
      check_output_file("--out", script, o.common.force);
      require_gnuplot();
    }
  }
  OutputSet outputs(o.common.force);

  std::cerr << "flatland: simulating " << scene.origin << " (spatial) for "
            << format_number(spec.end_time()) << " s\n";
  sim::SpatialRunResult r;
  {
    ProgressBar bar("simulate");
    const double t0 = setup.t0, span = setup.options.t_end - setup.t0;
    setup.options.progress = [&bar, t0, span](double t) {
      bar.update(std::lround(1000 * (t - t0) / span), 1000);
    };
    r = sim::run_spatial(setup);
  }

  if (!out.empty()) {
    const fs::path dir = out.parent_path().empty() ? fs::path(".") : out.parent_path();
    outputs.ensure_directory(out.parent_path());
    outputs.stage(dir / out.filename(), sim::spatial_samples_csv(r.samples));
    if (plots) {
      run_plot(outputs, dir,
               {script.filename().string(), out.filename().string(), png.filename().string(),
                spatial_plot(scene.name.empty() ? scene.origin : scene.name, r.samples)});
    }
    outputs.commit();
  }
  if (o.common.json) {
    Json j = api::spatial_simulate_json(spec, r);
    j["csv"] = out.empty() ? Json(nullptr) : Json(out.string());
    j["png"] = plots ? Json(png.string()) : Json(nullptr);
    emit_json(j);
    fail_if_broken(r.audit);
    return;
  }
  const sim::SpatialSample& f = r.final;
  // Six significant digits: these lines describe; the JSON and the CSV have every digit.
  const auto f6 = [](double v) { return sim::format_significant(v, 6); };
  const auto v3 = [&f6](const sim::Vec3& v) {
    return "(" + f6(v.x()) + ", " + f6(v.y()) + ", " + f6(v.z()) + ")";
  };
  std::ostringstream os;
  os << "flatland simulate: " << scene.origin << (scene.name.empty() ? "" : " (" + scene.name + ")")
     << "\n"
     << "  space              3d: " << setup.problem.object.surface->describe() << " on "
     << setup.problem.hand->describe() << ", " << setup.motion->describe() << "\n"
     << "  stopped            " << sim::to_string(r.stop) << " at t = " << f6(f.t) << " s"
     << (r.stop == sim::SpatialStop::kEndTime ? "" : "  (not a success)") << "\n"
     << "  centre             " << v3(f.state.position) << " m, moving " << v3(f.state.velocity)
     << " m/s\n"
     << "  contact            s_h = (" << f6(f.state.s_h.x()) << ", " << f6(f.state.s_h.y())
     << "), at " << v3(f.contact) << " m\n"
     << "  min f_n            " << f6(r.stats.min_force_normal) << " N\n"
     << "  required mu        " << f6(r.stats.max_mu_required)
     << (spec.mu ? " (mu = " + f6(*spec.mu) + ")" : std::string()) << "\n"
     << "  energy change      " << f6(f.energy - r.initial.energy) << " J\n"
     << energy_text(r.audit) << "  steps              " << r.stats.steps << " accepted, "
     << r.stats.rejected << " rejected, " << r.stats.rhs_evals << " rhs evaluations, "
     << r.stats.chart_changes << " chart changes (" << sim::to_string(spec.integrator.method)
     << ")\n"
     << "  residuals          constraints " << f6(r.stats.max_constraint_residual)
     << ", redundant row " << f6(r.stats.max_redundant_residual) << "\n";
  if (!out.empty())
    os << "  wrote              " << out.string() << (plots ? ", " + png.string() : "") << "\n";
  std::cout << os.str();
  fail_if_broken(r.audit);
}

void run_simulate(const SimulateOptions& o) {
  // Everything that can be bad input is checked before anything is computed or written.
  api::SimulateRequest request;
  request.integrator = integrator_overrides(o.common);
  if (o.period_opt->count()) request.period = o.period;
  if (o.k_opt->count()) request.k = o.k;
  if (o.duration_opt->count()) request.duration = o.duration;
  if (o.mu.opt->count()) request.mu = o.mu.value;
  if (o.model_opt->count()) request.model = o.model;
  request.stop_on_contact_loss = !o.no_stop_on_contact_loss;
  // Without --out no trajectory is written: the run keeps a bounded window of it.
  request.keep_trajectory = !o.common.out.empty();
  const Scene scene = load_scene_option(o.common, SceneSpaces::kPlanarOrSpatial);
  if (scene.spatial) return run_simulate_spatial(o, scene, request);
  const api::PreparedSimulation prepared =
      api::prepare_simulate(scene, request, api::Spelling::kCommandLine);
  const sim::SimulationSpec& spec = prepared.spec;
  const bool butterfly = spec.motion.kind == sim::MotionSpec::Kind::kButterfly;
  if (o.sample_dt_opt->count())
    api::require_sample_spacing("--sample-dt", o.sample_dt, spec.end_time() - spec.initial.t0);

  OutputSet outputs(o.common.force);
  const fs::path out = o.common.out;
  if (!out.empty() && (o.common.out.back() == '/' || fs::is_directory(out)))
    throw UsageError("--out: must be a file name (FILE.csv), not a directory: " + o.common.out);
  if (!out.empty()) check_output_file("--out", out, o.common.force);

  std::cerr << "flatland: simulating " << scene.origin << " for "
            << format_number(spec.end_time() - spec.initial.t0) << " s\n";
  const sim::RunResult r = api::simulate(prepared);

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
    Json j = api::simulate_json(spec, r);
    j["csv"] = out.empty() ? Json(nullptr) : Json(out.string());
    emit_json(j);
    fail_if_broken(r.audit);
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
     << " rejected, " << r.stats.rhs_evals << " rhs evaluations\n"
     << energy_text(r.audit);
  if (spec.run.model == sim::ContactModel::kHybrid) os << hybrid_text(spec, r);
  if (!out.empty()) os << "  wrote              " << out.string() << "\n";
  std::cout << os.str();
  fail_if_broken(r.audit);
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
  cmd->add_flag("--no-plot", o->no_plot,
                "Spatial scenes: write the CSV but not the plot beside it (FILE.png and its "
                "gnuplot script FILE.gp; no gnuplot needed). A planar run's --out writes the CSV "
                "only. Default: off");
  add_mu_option(*cmd, o->mu,
                "Static friction coefficient (>= 0): the rolling model stops where the disk would "
                "slip, the hybrid model slides. Default: the scene's contact.mu, else unlimited");
  return {cmd, [o] { run_simulate(*o); }};
}

}  // namespace flatland::app
