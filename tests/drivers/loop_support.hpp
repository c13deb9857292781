// Helpers of the closed-loop tests: the scene they run and the bounds of a mean of chi-square
// samples (the estimator's consistency).
#pragma once

#include "flatland/scene/scene.hpp"

#include <cmath>
#include <utility>

namespace flatland_test {

/// The air table under feedback (assets/scenes/airtable-feedback.yaml).
inline flatland::Scene feedback_scene() {
  return flatland::load_scene(FLATLAND_ASSET_DIR "/scenes/airtable-feedback.yaml");
}

/// Two-sided 95 % bounds of the mean of n chi-square(dof) samples (Wilson-Hilferty).
inline std::pair<double, double> mean_chi2_bounds(long n, int dof) {
  const double k = static_cast<double>(n) * dof;
  const auto quantile = [&](double z) {
    const double c = 2.0 / (9.0 * k);
    return k * std::pow(1.0 - c + z * std::sqrt(c), 3.0);
  };
  return {quantile(-1.959964) / static_cast<double>(n),
          quantile(1.959964) / static_cast<double>(n)};
}

}  // namespace flatland_test
