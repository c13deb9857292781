// The simulator's work-precision study: for every integrator setting and both formulations, the
// error in s_h(T) and in the solved k* against the CPU time they cost (docs/ACCURACY.md).
#pragma once

#include "flatland/sim/search.hpp"
#include "flatland/sim/spec.hpp"

#include <cmath>
#include <string>
#include <vector>

namespace flatland::studies {

/// One integrator setting: rtol (atol = rtol / 100) for the adaptive methods, the step for RK4.
struct IntegratorSetting {
  sim::Method method = sim::Method::kDormandPrince54;
  sim::Formulation formulation = sim::Formulation::kReduced;
  double rtol = 0, step = 0;  ///< step in s
};
/// "dopri5 reduced rtol=1e-06", "rk4 general h=0.001 s".
std::string label(const IntegratorSetting& s);

struct SimStudyRow {
  IntegratorSetting setting;
  long steps = 0, rhs_evals = 0;                   ///< of the run to T
  double s_T = NAN, err_s_T = NAN, cpu_s_T = NAN;  ///< s_h(T), its error, CPU s per run
  double k = NAN, err_k = NAN, cpu_k = NAN;        ///< k*, its error, CPU s per solve
  int simulations = 0;                             ///< runs of one solve
  /// The run to T's energy balance relative to the energy it moved, |balance| / scale (its
  /// audit: sim/energy.hpp); the study measures it rather than stopping runs on it.
  double energy_error = NAN;
  std::string failure;  ///< the integrator's or the search's error, if any
};

struct SimStudyOptions {
  bool quick = false;      ///< a few points of each curve (the tightest always among them)
  double min_cpu = 0.02;   ///< s: each timing repeats until this much CPU time has passed
  sim::Progress progress;  ///< (settings done, settings)
};

struct SimStudyResult {
  std::vector<SimStudyRow> rows;  ///< in settings order: per formulation, rk4, dopri5, dop853
  /// The references: the tightest DOP853 run of each formulation. A row's error is against the
  /// other formulation's reference, so that a formulation's own systematic error cannot cancel.
  SimStudyRow reference_reduced, reference_general;
  double cpu_seconds = 0;  ///< the whole study
};

/// The settings the study measures: RK4 at 7 steps (2 with quick) from 1e-2 to 1e-4 s, DOPRI5 and
/// DOP853 at rtol 1e-3 to 1e-13 (4 with quick), each in both formulations.
std::vector<IntegratorSetting> sim_study_settings(bool quick);

/// What the study needs of a scene, checked before any work: a butterfly motion, a spec that
/// builds, and a hand with the palm and back wells that its search for k plans between
/// (sim::require_palm_and_back). std::invalid_argument, one line naming the field.
void check_sim_study(const sim::SimulationSpec& spec);

/// The study on a butterfly motion (check_sim_study's std::invalid_argument otherwise);
/// std::runtime_error if no DOP853 reference run succeeds.
SimStudyResult run_sim_study(const sim::SimulationSpec& spec, const SimStudyOptions& options = {});

/// sim.csv: one row per setting (method, formulation, rtol, atol, step, steps, rhs_evals, s_T,
/// err_s_T, cpu_s_T, k, err_k, cpu_k, simulations).
std::string sim_study_csv(const SimStudyResult& result);

}  // namespace flatland::studies
