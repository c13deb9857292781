// The simulator's work-precision study (sim_study.hpp).
#include "flatland/studies/sim_study.hpp"

#include "flatland/sim/trajectory_csv.hpp"
#include "flatland/studies/timing.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace flatland::studies {

namespace {

using sim::format_number;

sim::SimulationSpec with_setting(sim::SimulationSpec spec, const IntegratorSetting& s) {
  auto& in = spec.run.integrator;
  in.method = s.method;
  if (s.method == sim::Method::kRungeKutta4) {
    in.fixed_step = s.step;
  } else {
    in.rtol = s.rtol;
    in.atol = s.rtol * 1e-2;  // docs/BENCHMARKS.md's convention: the state is O(1e-2..1)
  }
  spec.run.formulation = s.formulation;
  // The study measures every setting's error, the energy balance's among them (energy_error),
  // instead of stopping the coarse ones at the audit's bound.
  in.energy_tolerance = 1.0;
  return spec;
}

// s_h(T) for the scene's motion (one unrecorded run to T) and k* solving s_h(T) = 0, each with
// the CPU time it costs at this setting.
SimStudyRow measure(const sim::SimulationSpec& base, const IntegratorSetting& s, double min_cpu) {
  SimStudyRow r;
  r.setting = s;
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
    r.energy_error = std::abs(run.audit.balance) / run.audit.scale;
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

// The tightest run of a formulation: DOP853 at the smallest rtol that succeeded.
const SimStudyRow& tightest(const std::vector<SimStudyRow>& rows, sim::Formulation f) {
  const SimStudyRow* best = nullptr;
  for (const SimStudyRow& r : rows)
    if (r.setting.formulation == f && r.setting.method == sim::Method::kDormandPrince853 &&
        r.failure.empty() && (!best || r.setting.rtol < best->setting.rtol))
      best = &r;
  if (!best) throw std::runtime_error("study sim: no DOP853 reference run succeeded");
  return *best;
}

}  // namespace

std::string label(const IntegratorSetting& s) {
  std::ostringstream os;
  os << sim::to_string(s.method) << " " << sim::to_string(s.formulation) << " ";
  if (s.method == sim::Method::kRungeKutta4)
    os << "h=" << format_number(s.step) << " s";
  else
    os << "rtol=" << format_number(s.rtol);
  return os.str();
}

std::vector<IntegratorSetting> sim_study_settings(bool quick) {
  const std::vector<double> steps =
      quick ? std::vector<double>{1e-2, 1e-3}
            : std::vector<double>{1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4};
  const std::vector<int> exponents =
      quick ? std::vector<int>{3, 6, 9, 13} : std::vector<int>{3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13};
  std::vector<IntegratorSetting> settings;
  for (auto f : {sim::Formulation::kReduced, sim::Formulation::kGeneral}) {
    for (double h : steps) settings.push_back({sim::Method::kRungeKutta4, f, 0, h});
    for (auto m : {sim::Method::kDormandPrince54, sim::Method::kDormandPrince853})
      for (int e : exponents) settings.push_back({m, f, std::pow(10.0, -e), 0});
  }
  return settings;
}

void check_sim_study(const sim::SimulationSpec& spec) {
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw std::invalid_argument(
        "study sim: the scene's motion must be the butterfly (motion.kind)");
  sim::require_palm_and_back(spec.hand, *sim::build_problem(spec)->hand,
                             "study sim (its search for k)");
}

SimStudyResult run_sim_study(const sim::SimulationSpec& spec, const SimStudyOptions& options) {
  check_sim_study(spec);
  const std::vector<IntegratorSetting> settings = sim_study_settings(options.quick);
  const double start = cpu_now();
  SimStudyResult out;
  for (std::size_t i = 0; i < settings.size(); ++i) {
    out.rows.push_back(measure(spec, settings[i], options.min_cpu));
    if (options.progress)
      options.progress(static_cast<long>(i + 1), static_cast<long>(settings.size()));
  }
  out.reference_reduced = tightest(out.rows, sim::Formulation::kReduced);
  out.reference_general = tightest(out.rows, sim::Formulation::kGeneral);
  for (SimStudyRow& r : out.rows) {
    const SimStudyRow& ref = r.setting.formulation == sim::Formulation::kReduced
                                 ? out.reference_general
                                 : out.reference_reduced;
    r.err_s_T = std::abs(r.s_T - ref.s_T);
    r.err_k = std::abs(r.k - ref.k);
  }
  out.cpu_seconds = cpu_now() - start;
  return out;
}

std::string sim_study_csv(const SimStudyResult& result) {
  std::string out =
      "method,formulation,rtol,atol,step,steps,rhs_evals,s_T,err_s_T,cpu_s_T,k,err_k,cpu_k,"
      "simulations,energy_error\n";
  for (const SimStudyRow& r : result.rows) {
    const bool rk4 = r.setting.method == sim::Method::kRungeKutta4;
    out += sim::to_string(r.setting.method) + "," + sim::to_string(r.setting.formulation) + "," +
           (rk4 ? "nan" : format_number(r.setting.rtol)) + "," +
           (rk4 ? "nan" : format_number(r.setting.rtol * 1e-2)) + "," +
           (rk4 ? format_number(r.setting.step) : "nan") + "," + std::to_string(r.steps) + "," +
           std::to_string(r.rhs_evals) + "," + format_number(r.s_T) + "," +
           format_number(r.err_s_T) + "," + format_number(r.cpu_s_T) + "," + format_number(r.k) +
           "," + format_number(r.err_k) + "," + format_number(r.cpu_k) + "," +
           std::to_string(r.simulations) + "," + format_number(r.energy_error) + "\n";
  }
  return out;
}

}  // namespace flatland::studies
