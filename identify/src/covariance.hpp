// The fit's report: residuals, chi^2, the covariance of the unknowns and the refusal of those the
// data do not determine (docs/IDENTIFY.md, "What is reported").
#pragma once

#include "shooting.hpp"

#include <ceres/problem.h>

#include <array>
#include <vector>

namespace flatland::identify::detail {

/// The quantile of chi^2 beyond which the fit's chi^2 is taken as inconsistent with the sigma
/// given, and every sigma is scaled by sqrt(chi^2 / dof) (docs/IDENTIFY.md, "Covariance").
constexpr double kConsistentChi2Quantile = 0.99;
/// A fit whose Gauss-Newton step at the solution moves a determined parameter by more than this
/// many of its sigma has not reached the minimum (IdentifyResult::step_in_sigma): at the minima
/// found by the continuation it was 0.06-0.23 on the closed-loop experiment of tests/cli, at the
/// stops short of them that Ceres called convergence 0.6-8.6 (docs/IDENTIFY.md, "Convergence").
constexpr double kConvergedStepInSigma = 0.3;

/// Fill result's parameters (with their step_to_minimum), correlation, chi2, degrees of freedom,
/// chi2_limit, sigma_scale, step_in_sigma, chi2_decrease_expected, fits and segments from the
/// solved problem: w (the unknowns) and states (each segment's s_h,
/// sdot_h) as Ceres left them. `held[j]`, when not empty, is why unknown j was held at its
/// starting value (its Jacobian column is zero; it is reported as not determined with that
/// reason and counts as no degree of freedom). std::runtime_error if the simulator fails at the
/// solution.
void report_fit(const ShootingProblem& problem, ceres::Problem& solved, std::vector<double>& w,
                std::vector<std::array<double, 2>>& states, const IdentifyOptions& options,
                const std::vector<std::string>& held, IdentifyResult& result);

}  // namespace flatland::identify::detail
