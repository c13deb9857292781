// Design search (paper section 4.3): butterfly solutions in motion space (k, 2T) and shape space.
//
// A solution rolls the disk from the palm (s_h = -1) to rest on the back (s_h = +1). Hand shape
// and motion are symmetric, so a solution has s_h(T) = 0; the searches find that root with
// Brent's bracketing method, simulating only to T, and then evaluate the found solution with one
// full recorded run. Search runs enforce rolling (they do not stop where contact is lost) so that
// s_h(T) and the minimum normal force are continuous in the parameters.
#pragma once

#include "flatland/sim/parallel.hpp"

#include "flatland/sim/spec.hpp"

#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace flatland::sim {

/// Called with (done, total) as work completes; may be called from worker threads (serialised).
using Progress = std::function<void(long done, long total)>;

struct SearchSettings {
  double tolerance = 1e-9;  ///< bracket width in the solved-for parameter (k or d)
  int max_evaluations = 100;
};

struct SolveReport {
  double period = 0;  ///< 2T, s
  double k = 0;
  double d = 0;                    ///< hand shape parameter d, m
  double s_T = 0;                  ///< s_h at t = T (0 at a solution)
  double s_end = 0, sdot_end = 0;  ///< s_h and its rate at t = 2T
  // A solution is symmetric about T (its second half mirrors the first), so its forces are taken
  // over [0, T], where they are well conditioned even for slow motions.
  double fn_apex_ratio = 0;  ///< normal force / weight at t = T (the apex of a solution)
  double fn_min_ratio = 0;   ///< minimum over [0, T]
  double mu_required = 0;    ///< max |f_t| / f_n over [0, T] (inf if f_n <= 0 somewhere)
  /// With the spec's contact.mu: min (mu f_n - |f_t|) / (m g sin tilt) over [0, T], the friction
  /// to spare (< 0: the motion needs more than mu somewhere); NaN without mu.
  double friction_margin = std::numeric_limits<double>::quiet_NaN();
  int simulations = 0;  ///< runs the search made
  long rhs_evals = 0;   ///< right-hand-side evaluations over all of them
  RunResult run;        ///< the full recorded run of the solution
  /// A locus point whose runs failed numerically (NumericalFailure): why; its numbers are NaN.
  std::string failure;
};

/// s_h at the half period T for the spec with (period, k) set; one unrecorded run.
/// std::runtime_error where that run fails numerically (its energy balance breaks).
double half_period_s_h(const SimulationSpec& spec, double period, double k,
                       long* rhs_evals = nullptr);

/// k such that s_h(T) = 0 for 2T = period. Brackets from spec.motion.k outwards.
/// Throws std::runtime_error when no bracket is found in (-2, 2].
SolveReport solve_k(const SimulationSpec& spec, double period, const SearchSettings& s = {});
/// Shape parameter d such that s_h(T) = 0 for the motion (period, k); a, b, c from the spec.
SolveReport solve_d(const SimulationSpec& spec, double period, double k,
                    const SearchSettings& s = {});
/// Evaluate a motion with one full recorded run (rolling enforced); forces over [0, T].
SolveReport evaluate(const SimulationSpec& spec, double period, double k);

/// The locus k(2T) for n periods evenly spaced over [from, to] (paper Fig. 7). A period whose
/// runs fail numerically is a point with NaN numbers and its `failure`; the locus goes on.
std::vector<SolveReport> locus(const SimulationSpec& spec, double from, double to, int n,
                               const SearchSettings& s = {}, const Progress& progress = {});

struct SurfaceResult {
  std::vector<double> k, period;
  std::vector<double> s_T;  ///< s_T[i * period.size() + j] at (k[i], period[j])
  long rhs_evals = 0;
  /// Grid points whose run failed numerically (its energy balance broke): s_T is NaN there.
  struct Failure {
    int i = 0, j = 0;  ///< k[i], period[j]
    std::string what;
  };
  std::vector<Failure> numerical_failures;
};
/// s_h(T) on a k x 2T grid (paper Fig. 6), in parallel over `threads` (0 = all cores).
SurfaceResult surface(const SimulationSpec& spec, double k_lo, double k_hi, int nk, double p_lo,
                      double p_hi, int np, int threads = 0, const Progress& progress = {});
/// The same on a sweep engine (this process's threads, or an MPI job's ranks).
SurfaceResult surface(const SimulationSpec& spec, double k_lo, double k_hi, int nk, double p_lo,
                      double p_hi, int np, const SweepEngine& engine,
                      const Progress& progress = {});

/// What limits the fastest motion.
enum class SpeedLimit {
  kNormalForce,  ///< the normal force reaches 0 (the hand would throw the disk)
  kFriction,     ///< the friction needed reaches contact.mu (the disk would slip)
};
std::string to_string(SpeedLimit l);

struct TimeOptimalReport {
  double period = 0, k = 0, fn_min_ratio = 0;
  double friction_margin = std::numeric_limits<double>::quiet_NaN();  ///< as in SolveReport
  SpeedLimit limit = SpeedLimit::kNormalForce;
  int solves = 0;
  SolveReport solution;
};
/// The fastest 2T in [lo, hi] whose solution keeps f_n >= 0 and, when the spec has contact.mu,
/// |f_t| <= mu f_n throughout [0, T] (the smaller of the minimum normal force ratio and the
/// friction margin crosses zero there). Throws std::runtime_error if [lo, hi] does not bracket
/// it.
TimeOptimalReport time_optimal(const SimulationSpec& spec, double lo, double hi,
                               double period_tolerance = 1e-7, const SearchSettings& s = {});

}  // namespace flatland::sim
