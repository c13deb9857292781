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
#include <memory>
#include <optional>
#include <string_view>

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
  /// The same for the state at the motion's end 2T, which moves with the period (its column adds
  /// the state's rate there): set when the run ends at 2T (t_end = the motion's period) in contact.
  std::optional<ButterflyJacobian> motion_end;
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

}  // namespace flatland::sim
