// Shape and motion designed together (the paper's closing question; docs/DESIGN.md): the
// polynomial hand's a, b, c, d and the butterfly's k optimised at once, with the exact
// sensitivities of flatland/sim/sensitivity.hpp, by NLopt's SLSQP (sequential quadratic
// programming with the design's equality and inequality constraints).
#pragma once

#include "flatland/sim/spec.hpp"

#include <array>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace flatland::design {

/// A butterfly's design variables, in sim::kButterflyParameters' order: the hand's a, b, c, d (m)
/// and the motion's k and period 2T (s).
using Parameters = std::array<double, 6>;

/// What a design optimises (docs/DESIGN.md; the shortest period, objective 2, is not built yet).
enum class Objective {
  /// 1: the least friction coefficient a butterfly of the period needs, keeping fn_margin.
  kLeastFriction,
  /// 3: the largest robustness margin at the period and `mu`: the smallest, over [t0, T], of
  /// (mu f_n - |f_t|) / (m g sin tilt) and of f_n / (m g sin tilt).
  kRobustness,
};
std::string to_string(Objective o);  ///< "least-friction", "robustness"

struct DesignOptions {
  Objective objective = Objective::kLeastFriction;
  double period = 0;  ///< 2T, s, held
  double mu = 0;      ///< kRobustness: the friction coefficient (> 0)
  /// The hand's a, b, c, d free, each within `shape_range` of its starting size; false: the
  /// spec's hand held, k alone free (the motion-only design, the paper's own search).
  bool shape_free = true;
  double shape_range = 0.25;         ///< in (0, 1)
  double k_min = -1.9, k_max = 1.9;  ///< k's bounds (k = -2 is singular: P(1) = 0)
  /// kLeastFriction: the contact-loss margin kept, f_n / (m g sin tilt) >= this over [t0, T].
  double fn_margin = 0.05;
  /// The window [t0, T] is cut into this many equal parts, each with its own friction and
  /// contact-loss constraints (sim::ForceMarginSensitivities::windows): the friction needed
  /// peaks more than once, and a constraint on the whole window's peak is not smooth.
  int pieces = 6;
  int max_evaluations = 100;  ///< of each search (each evaluation one set of runs)
  double tolerance = 1e-7;    ///< relative change of the variables that ends the search
};

/// One evaluation: the variables, the objective and the constraints there.
struct Iterate {
  int evaluation = 0;
  Parameters parameters{};
  double mu_required = 0;   ///< max |f_t| / f_n over [t0, T]
  double s_T = 0;           ///< s_h(T): 0 at a solution (it then ends at rest on the back)
  double fn_min_ratio = 0;  ///< min f_n / (m g sin tilt) over [t0, T]
  /// kRobustness: min over [t0, T] of (mu f_n - |f_t|) and f_n, / (m g sin tilt); NaN otherwise.
  double robustness = std::numeric_limits<double>::quiet_NaN();
  /// |s_T| <= the feasibility tolerance, and (kLeastFriction) fn_min_ratio >= the margin.
  bool feasible = false;
};

struct DesignResult {
  Objective objective = Objective::kLeastFriction;
  double mu = 0;        ///< kRobustness's friction coefficient
  Parameters start{};   ///< the spec's hand with k solved for s_h(T) = 0
  Iterate start_point;  ///< the start evaluated
  /// The feasible iterate with the least mu_required (kLeastFriction) or the largest robustness;
  /// not feasible (the start) when none was.
  Iterate best;
  /// The bounds and constraints that hold with equality at the best design, in words ("a at its
  /// lower bound", "the wells' radius of curvature"): what limits it.
  std::vector<std::string> active;
  std::vector<Iterate> iterates;  ///< every evaluation, the start's first
  int simulations = 0;            ///< runs, sensitivities' and the start's search included
  /// Where the start came within fn_margin of contact loss: whether the margin was restored
  /// first (maximising it under the same constraints), and why that search stopped.
  bool restored = false;
  std::string restore_stop;
  std::string stop;  ///< why the objective's search stopped, in words
};

/// The spec with a design's parameters set: its hand's a, b, c, d and its motion's k and period.
sim::SimulationSpec spec_with(sim::SimulationSpec spec, const Parameters& p);

/// A design from the spec's hand and motion (a polynomial hand and the butterfly): solves k for
/// s_h(T) = 0 at the period first (std::runtime_error if no k does), then, subject to s_h(T) = 0,
/// the outline staying a hand (2a + c >= 1 mm) and its wells holding the disk (their radius of
/// curvature >= 1.1 times the disk's): kLeastFriction restores the contact-loss margin if that
/// start lacks it and minimises the friction needed keeping the margin; kRobustness maximises the
/// robustness margin.
/// `progress` is called after each evaluation. std::invalid_argument, one line naming the option,
/// for bad options or a spec that is not the paper's kind.
DesignResult optimise(const sim::SimulationSpec& spec, const DesignOptions& options,
                      const std::function<void(const Iterate&)>& progress = {});

}  // namespace flatland::design
