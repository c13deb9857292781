// Exact sensitivities of a butterfly's rolling run (the paper's question of shape and motion
// designed together): the derivatives of the disk's contact parameter s_h and its rate at the
// run's end with respect to the polynomial hand's coefficients a, b, c, d and the butterfly
// motion's k and period 2T.
//
// They are integrated beside the state by the run's own integrator (forward sensitivity
// equations, S' = f_x S + f_p), the right-hand side's partial derivatives taken by forward
// automatic differentiation (Ceres' Jets) of the very formulas the run evaluates
// (sim/src/rolling_terms.hpp). Where the right-hand side jumps, the sensitivities jump too
// (the saltation matrix): at each junction of the hand's pieces (s_h = +-1, 3, ..., where the
// outline's curvature derivative jumps, so s_h'' does) and at the motion's end 2T, which moves
// with the period. The events are located to the integrator's time tolerance, so the sensitivities
// are exact to the integration's accuracy: docs/DESIGN.md shows them against central differences.
#pragma once

#include "flatland/sim/simulate.hpp"

#include <Eigen/Core>

#include <array>
#include <limits>
#include <memory>
#include <optional>
#include <string_view>
#include <vector>

namespace flatland::sim {

/// The parameters, in the order of the sensitivities' columns.
inline constexpr std::array<std::string_view, 6> kButterflyParameters = {"a", "b", "c",
                                                                         "d", "k", "period"};

using ButterflyJacobian = Eigen::Matrix<double, 2, 6>;

struct SensitivityOptions {
  /// Whether the step-size control measures the sensitivities' error too, or the state's alone
  /// (the default: the steps are the run's own, and the sensitivities are integrated on them).
  /// Measured on the paper's butterfly at rtol 1e-10 (docs/BENCHMARKS.md): 826 steps with it,
  /// 518 without (the run's own); at rtol 1e-12 both agree with central differences to 4e-7.
  bool control_error = false;
};

struct RunSensitivities {
  RunResult run;  ///< the run itself (the same run simulate() gives, its state unchanged)
  /// d(s_h, sdot_h)/dp at the run's end, t_end held fixed: rows s_h and sdot_h, columns
  /// kButterflyParameters.
  ButterflyJacobian end = ButterflyJacobian::Zero();
  /// The same at an end that moves in proportion to the period, t_end (2T)' / 2T: at 2T for
  /// t_end = the period (the outcome the paper designs for, s_h(2T) = 1, sdot_h(2T) = 0), at T for
  /// half of it (a symmetric solution's s_h(T) = 0). The period's column adds t_end / 2T times
  /// the state's rate at t_end. Set when the run reaches t_end > 0 in contact.
  std::optional<ButterflyJacobian> scaled_end;
  int junction_jumps = 0;    ///< junction crossings whose jump was applied
  int breakpoint_jumps = 0;  ///< motion breakpoints crossed that move with the period
};

/// The run and its sensitivities. The problem must be the paper's kind: a polynomial hand, a
/// disk, the butterfly motion and lossless rolling (RunOptions::model rolling, the reduced
/// formulation); anything else is refused with std::invalid_argument naming what is not
/// supported. A run that crosses a junction at zero speed (where s_h is not differentiable) ends
/// with std::runtime_error.
RunSensitivities simulate_with_sensitivities(std::shared_ptr<const RollingProblem> problem,
                                             const InitialContact& init, const RunOptions& options,
                                             const SensitivityOptions& sensitivity = {});

using ParameterGradient = Eigen::Matrix<double, 1, 6>;

/// One extremum of a contact-force ratio over a run's window and its derivative in each
/// parameter (columns kButterflyParameters). The window's ends are held fixed, so the derivative
/// is the ratio's own at the extremum's time (Danskin's theorem: where the extremum is inside
/// the window the ratio's rate is zero there, and where it is at an end that end does not move).
/// It is the derivative wherever the extremum is unique; where two extrema tie it is that of the
/// one found, a one-sided derivative.
struct MarginSensitivity {
  double value = std::numeric_limits<double>::quiet_NaN();
  double t = std::numeric_limits<double>::quiet_NaN();  ///< where it is, s
  /// NaN where the value is not finite (mu_required where f_n <= 0) or was not asked for.
  ParameterGradient gradient =
      ParameterGradient::Constant(std::numeric_limits<double>::quiet_NaN());
  /// f_n and f_t / (m g sin tilt) at t (the friction margin's derivative in mu is fn_ratio).
  double fn_ratio = std::numeric_limits<double>::quiet_NaN();
  double ft_ratio = std::numeric_limits<double>::quiet_NaN();
};

/// The margins over one part of the window.
struct WindowMargins {
  double t_from = 0, t_to = 0;  ///< s
  MarginSensitivity fn_min_ratio, mu_required, friction_margin;
};

/// A butterfly's force margins over a window of its run (find_extrema's), with their
/// sensitivities: what a design keeps away from contact loss and slip.
struct ForceMarginSensitivities {
  MarginSensitivity fn_min_ratio;     ///< min f_n / (m g sin tilt): the contact-loss margin
  MarginSensitivity mu_required;      ///< max |f_t| / f_n: the least friction that rolls
  MarginSensitivity friction_margin;  ///< with mu: min (mu f_n - |f_t|) / (m g sin tilt)
  /// The same over each of `pieces` equal parts of the window (the whole window's are the
  /// extrema of these): an optimiser constrains each part's extremum on its own, so that each
  /// constraint stays smooth where the whole window's extremum jumps from one local extremum to
  /// another (the friction the paper's butterflies need peaks twice before T).
  std::vector<WindowMargins> windows;
  RunResult run;  ///< the recorded run they were found on
  /// d(s_h, sdot_h)/dp at the run's end, its time held (RunSensitivities::end of that run).
  ButterflyJacobian end = ButterflyJacobian::Zero();
  int runs = 0;        ///< runs integrated: the recorded one and one to each extremum's time
  long rhs_evals = 0;  ///< over all of them
};

/// The force margins over [t_from, t_to] of the run simulate_with_sensitivities() makes (recorded
/// here whatever `options` says), located to options.events.time_tolerance, and their
/// sensitivities: for each extremum, one more run with sensitivities to its time (once per time)
/// gives d(s_h, sdot_h)/dp there, and the ratio's derivatives in (s_h, sdot_h) and the parameters
/// come from Jets of the run's own formulas (rolling_terms.hpp). `mu` > 0 asks for the friction
/// margin. The problem and options are refused as simulate_with_sensitivities() refuses them; a
/// window outside the run (or empty), a mu that is not positive and finite, or pieces outside [1,
/// 1000] is std::invalid_argument.
ForceMarginSensitivities force_margin_sensitivities(std::shared_ptr<const RollingProblem> problem,
                                                    const InitialContact& init,
                                                    const RunOptions& options, double t_from,
                                                    double t_to,
                                                    std::optional<double> mu = std::nullopt,
                                                    int pieces = 1);

}  // namespace flatland::sim
