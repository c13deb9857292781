// The fit's report: residuals, chi^2, the covariance of the unknowns and the refusal of those the
// data do not determine (docs/IDENTIFY.md, "What is reported").
#pragma once

#include "shooting.hpp"

#include <ceres/problem.h>

#include <array>
#include <vector>

namespace flatland::identify::detail {

/// Fill result's parameters, correlation, chi2, degrees of freedom, fits and segments from the
/// solved problem: w (the unknowns) and states (each segment's s_h, sdot_h) as Ceres left them.
/// std::runtime_error if the simulator fails at the solution.
void report_fit(const ShootingProblem& problem, ceres::Problem& solved, std::vector<double>& w,
                std::vector<std::array<double, 2>>& states, const IdentifyOptions& options,
                IdentifyResult& result);

}  // namespace flatland::identify::detail
