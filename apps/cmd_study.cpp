// flatland study: speed-accuracy studies (issue #6), one per knob, regenerating docs/ACCURACY.md.
// `sim` is the work-precision diagram of the simulator: for every integrator setting and both
// formulations, the error in s_h(T) and in the solved k* against the CPU time they cost.
#include "common.hpp"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct StudyOptions {
  std::string name;
  std::string scene;
  std::string out;
  bool force = false;
  bool json = false;
  bool no_plot = false;
  double min_cpu = 0.02;  // s: timing repeats until this much CPU time has been spent
};

// Studies other issues will add; asking for one is an error that says so (exit 2), not silence.
const std::vector<std::string> kPlanned = {"render", "tracker", "calibration", "closed-loop"};

double cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// CPU seconds per call of f, repeated until min_cpu has passed (single runs at loose tolerances
// take microseconds, below the clock's useful resolution).
template <class F>
double cpu_per_call(F&& f, double min_cpu) {
  const double start = cpu_now();
  long n = 0;
  do {
    f();
    ++n;
  } while (cpu_now() - start < min_cpu && n < 1000);
  return (cpu_now() - start) / static_cast<double>(n);
}

struct Setting {
  sim::Method method;
  sim::Formulation formulation;
  double rtol = 0, step = 0;  // rtol for the adaptive methods, step (s) for RK4
};

struct Row {
  Setting set;
  long steps = 0, rhs_evals = 0;
  double s_T = NAN, err_s_T = NAN, cpu_s_T = NAN;
  double k = NAN, err_k = NAN, cpu_k = NAN;
  int simulations = 0;
  std::string failure;  // the integrator's or the search's error, if any
};

sim::SimulationSpec with_setting(sim::SimulationSpec spec, const Setting& s) {
  auto& in = spec.run.integrator;
  in.method = s.method;
  if (s.method == sim::Method::kRungeKutta4) {
    in.fixed_step = s.step;
  } else {
    in.rtol = s.rtol;
    in.atol = s.rtol * 1e-2;  // docs/BENCHMARKS.md's convention: the state is O(1e-2..1)
  }
  spec.run.formulation = s.formulation;
  return spec;
}

// s_h(T) for the scene's motion (one unrecorded run to T) and k* solving s_h(T) = 0, each with
// the CPU time it costs at this setting.
Row measure(const sim::SimulationSpec& base, const Setting& s, double min_cpu) {
  Row r;
  r.set = s;
  const sim::SimulationSpec spec = with_setting(base, s);
  const double period = spec.motion.period;
  try {
    sim::RunOptions o = sim::run_options(spec);
    o.t_end = 0.5 * period;
    o.record = false;
    o.events.stop_on_contact_loss = false;  // as the searches: rolling enforced
    const auto problem = sim::build_problem(spec);
    sim::RunResult run;
    r.cpu_s_T = cpu_per_call([&] { run = sim::simulate(problem, spec.initial, o); }, min_cpu);
    r.s_T = run.final.s_h;
    r.steps = run.stats.steps;
    r.rhs_evals = run.stats.rhs_evals;
    sim::SearchSettings search;
    search.tolerance = 1e-14;  // below every integrator's error, so k* shows the integrator's
    sim::SolveReport rep;
    r.cpu_k = cpu_per_call([&] { rep = sim::solve_k(spec, period, search); }, min_cpu);
    r.k = rep.k;
    r.simulations = rep.simulations;
  } catch (const std::runtime_error& e) {
    r.failure = e.what();
  }
  return r;
}

std::string method_name(const Setting& s) { return sim::to_string(s.method); }

std::string label(const Setting& s) {
  std::ostringstream os;
  os << method_name(s) << " " << sim::to_string(s.formulation) << " ";
  if (s.method == sim::Method::kRungeKutta4)
    os << "h=" << format_number(s.step) << " s";
  else
    os << "rtol=" << format_number(s.rtol);
  return os.str();
}

std::string study_csv(const std::vector<Row>& rows) {
  std::string out =
      "method,formulation,rtol,atol,step,steps,rhs_evals,s_T,err_s_T,cpu_s_T,k,err_k,cpu_k,"
      "simulations\n";
  for (const Row& r : rows) {
    const bool rk4 = r.set.method == sim::Method::kRungeKutta4;
    out += method_name(r.set) + "," + sim::to_string(r.set.formulation) + "," +
           (rk4 ? "nan" : format_number(r.set.rtol)) + "," +
           (rk4 ? "nan" : format_number(r.set.rtol * 1e-2)) + "," +
           (rk4 ? format_number(r.set.step) : "nan") + "," + std::to_string(r.steps) + "," +
           std::to_string(r.rhs_evals) + "," + format_number(r.s_T) + "," +
           format_number(r.err_s_T) + "," + format_number(r.cpu_s_T) + "," + format_number(r.k) +
           "," + format_number(r.err_k) + "," + format_number(r.cpu_k) + "," +
           std::to_string(r.simulations) + "\n";
  }
  return out;
}

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

void run_sim_study(const StudyOptions& o) {
  CommonOptions common;
  common.scene = o.scene;
  Scene scene = load_scene_with_overrides(common);
  sim::SimulationSpec& spec = scene.sim;
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw UsageError("study sim: the scene's motion must be the butterfly (motion.kind)");
  sim::build_problem(spec);
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  std::vector<Setting> settings;
  for (auto f : {sim::Formulation::kReduced, sim::Formulation::kGeneral}) {
    for (double h : {1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4})
      settings.push_back({sim::Method::kRungeKutta4, f, 0, h});
    for (auto m : {sim::Method::kDormandPrince54, sim::Method::kDormandPrince853})
      for (int e = 3; e <= 13; ++e) settings.push_back({m, f, std::pow(10.0, -e), 0});
  }
  std::cerr << "flatland: study sim: " << settings.size()
            << " settings, 2T = " << format_number(spec.motion.period)
            << " s, k = " << format_number(spec.motion.k) << "\n";
  const double start = cpu_now();
  std::vector<Row> rows;
  {
    ProgressBar bar("study sim");
    for (std::size_t i = 0; i < settings.size(); ++i) {
      rows.push_back(measure(spec, settings[i], o.min_cpu));
      bar.update(static_cast<long>(i + 1), static_cast<long>(settings.size()));
    }
  }
  // Reference: the tightest run of the other formulation (so a formulation's own systematic
  // error cannot cancel in its reference); the tightest is DOP853 at the smallest rtol.
  auto tightest = [&](sim::Formulation f) -> const Row& {
    const Row* best = nullptr;
    for (const Row& r : rows)
      if (r.set.formulation == f && r.set.method == sim::Method::kDormandPrince853 &&
          r.failure.empty() && (!best || r.set.rtol < best->set.rtol))
        best = &r;
    if (!best) throw std::runtime_error("study sim: no DOP853 reference run succeeded");
    return *best;
  };
  const Row& ref_red = tightest(sim::Formulation::kReduced);
  const Row& ref_gen = tightest(sim::Formulation::kGeneral);
  for (Row& r : rows) {
    const Row& ref = r.set.formulation == sim::Formulation::kReduced ? ref_gen : ref_red;
    r.err_s_T = std::abs(r.s_T - ref.s_T);
    r.err_k = std::abs(r.k - ref.k);
  }
  const double seconds = cpu_now() - start;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "sim.csv", study_csv(rows));
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
                      {"rtol", ref_red.set.rtol},
                      {"s_T", number(ref_red.s_T)},
                      {"k", number(ref_red.k)}};
    ref["general"] = {{"method", "dop853"},
                      {"rtol", ref_gen.set.rtol},
                      {"s_T", number(ref_gen.s_T)},
                      {"k", number(ref_gen.k)}};
    ref["s_T_disagreement"] = number(std::abs(ref_red.s_T - ref_gen.s_T));
    ref["k_disagreement"] = number(std::abs(ref_red.k - ref_gen.k));
    j["reference"] = ref;
    Json arr = Json::array();
    for (const Row& r : rows) {
      Json q;
      q["method"] = method_name(r.set);
      q["formulation"] = sim::to_string(r.set.formulation);
      q["rtol"] = r.set.method == sim::Method::kRungeKutta4 ? Json(nullptr) : Json(r.set.rtol);
      q["step"] = r.set.method == sim::Method::kRungeKutta4 ? Json(r.set.step) : Json(nullptr);
      q["steps"] = r.steps;
      q["rhs_evals"] = r.rhs_evals;
      q["err_s_T"] = number(r.err_s_T);
      q["cpu_s_T"] = number(r.cpu_s_T);
      q["err_k"] = number(r.err_k);
      q["cpu_k"] = number(r.cpu_k);
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
  for (const Row& r : rows) {
    char line[200];
    std::snprintf(line, sizeof line,
                  "  %-34s err s_h(T) %8.1e in %8.2e s   err k* %8.1e in %8.2e s%s\n",
                  label(r.set).c_str(), r.err_s_T, r.cpu_s_T, r.err_k, r.cpu_k,
                  r.failure.empty() ? "" : ("  FAILED: " + r.failure).c_str());
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

void run_study(const StudyOptions& o) {
  if (o.name == "sim") return run_sim_study(o);
  std::string planned;
  for (const auto& p : kPlanned) planned += (planned.empty() ? "" : ", ") + p;
  if (std::find(kPlanned.begin(), kPlanned.end(), o.name) != kPlanned.end())
    throw UsageError("study: '" + o.name + "' is not implemented yet (available: sim)");
  throw UsageError("study: unknown study '" + o.name + "' (available: sim; planned: " + planned +
                   ")");
}

}  // namespace

Command add_study_command(CLI::App& app) {
  auto o = std::make_shared<StudyOptions>();
  CLI::App* cmd = app.add_subcommand(
      "study",
      "Speed-accuracy studies (docs/ACCURACY.md). 'sim': the simulator's work-precision diagram "
      "(RK4 at several steps, dopri5 and dop853 at rtol 1e-3 ... 1e-13, general and reduced "
      "formulations): error in s_h(T) and in the solved k against CPU time.");
  cmd->add_option("name", o->name,
                  "Which study: sim (render, tracker, calibration, closed-loop: planned)")
      ->required();
  cmd->add_option("--scene", o->scene,
                  "Scene file (YAML; its motion must be the butterfly). Default: the bundled "
                  "paper butterfly, " +
                      default_scene_path())
      ->type_name("FILE");
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout (errors, CPU seconds, the references)");
  cmd->add_option("--out", o->out,
                  "Directory for sim.csv (one row per setting: method, formulation, rtol, atol, "
                  "step in s, steps, rhs_evals, s_T, err_s_T, cpu_s_T in s, k, err_k, cpu_k in "
                  "s, simulations) and sim_s_h.png, sim_k.png (log-log) with their gnuplot "
                  "scripts; created if missing. Default: no files")
      ->type_name("PATH");
  cmd->add_flag("--no-plot", o->no_plot, "Write the CSV but no plots (no gnuplot needed)");
  add_force_option(*cmd, o->force);
  cmd->add_option("--min-cpu", o->min_cpu,
                  "CPU seconds each timing repeats for (> 0; longer is steadier). Default: 0.02")
      ->check(CLI::PositiveNumber);
  return {cmd, [o] { run_study(*o); }};
}

}  // namespace flatland::app
