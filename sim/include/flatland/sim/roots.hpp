// Scalar root finding and minimisation on a bracket (Brent's methods).
#pragma once

#include <functional>

namespace flatland::sim {

struct RootResult {
  double x = 0;   ///< the root
  double fx = 0;  ///< f at the root
  int evaluations = 0;
  bool converged = false;
};

/// Brent's root finder on [a, b] with f(a) f(b) <= 0 (throws std::invalid_argument otherwise).
/// Stops when the bracket is narrower than 2 (xtol + 4 eps |x|) or f(x) == 0.
RootResult brent_root(const std::function<double(double)>& f, double a, double b, double fa,
                      double fb, double xtol, int max_evaluations = 200);

struct MinResult {
  double x = 0, fx = 0;
  int evaluations = 0;
};

/// Brent's minimiser (golden section + parabolic steps) of f on [a, b].
MinResult brent_minimize(const std::function<double(double)>& f, double a, double b, double xtol,
                         int max_evaluations = 200);

}  // namespace flatland::sim
