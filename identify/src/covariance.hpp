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

/// Fill result's parameters, correlation, chi2, degrees of freedom, chi2_limit, sigma_scale,
/// fits and segments from the solved problem: w (the unknowns) and states (each segment's s_h,
/// sdot_h) as Ceres left them. `held[j]`, when not empty, is why unknown j was held at its
/// starting value (its Jacobian column is zero; it is reported as not determined with that
/// reason and counts as no degree of freedom). std::runtime_error if the simulator fails at the
/// solution.
void report_fit(const ShootingProblem& problem, ceres::Problem& solved, std::vector<double>& w,
                std::vector<std::array<double, 2>>& states, const IdentifyOptions& options,
                const std::vector<std::string>& held, IdentifyResult& result);

}  // namespace flatland::identify::detail
