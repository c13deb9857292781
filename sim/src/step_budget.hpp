// The step budget's forecast, for the planar runs (integration.hpp) and the spatial run. Internal
// to sim/.
#pragma once

#include <algorithm>
#include <sstream>
#include <stdexcept>

namespace flatland::sim::detail {

/// A run that has used a hundredth of its step budget and, at the rate so far, would need more
/// than four times the budget to reach its end is refused now (std::invalid_argument naming the
/// duration: an input too long for the budget) instead of after minutes and gigabytes. Checked
/// every 1024 steps.
inline void forecast_step_budget(long used, long budget, double t_start, double t, double t_end) {
  if (used < std::max(1000L, budget / 100) || used % 1024 != 0 || !(t > t_start)) return;
  const double forecast = static_cast<double>(used) * (t_end - t_start) / (t - t_start);
  if (!(forecast > 4.0 * static_cast<double>(budget))) return;
  std::ostringstream os;
  os.precision(3);
  os << "duration: " << (t_end - t_start) << " s would take about " << forecast
     << " integrator steps at the rate of its first " << (t - t_start)
     << " s, beyond the step budget of " << budget
     << " (integrator.max_steps; or a shorter duration, or a looser rtol)";
  throw std::invalid_argument(os.str());
}

}  // namespace flatland::sim::detail
