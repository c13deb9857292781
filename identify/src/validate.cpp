// validate(): a held-out recording predicted from its first state (docs/IDENTIFY.md,
// "Prediction check").
#include "flatland/identify/identify.hpp"
#include "flatland/sim/format.hpp"

#include "shooting.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace flatland::identify {

PredictionCheck validate(const sim::SimulationSpec& world, const Recording& held_out,
                         const ValidateOptions& options) {
  if (!(options.initial_window > 0) || !std::isfinite(options.initial_window))
    throw std::invalid_argument("initial_window: must be positive and finite, got " +
                                sim::format_number(options.initial_window));
  if (!std::isfinite(options.angle_offset) || !std::isfinite(options.time_offset))
    throw std::invalid_argument("angle_offset, time_offset: must be finite");
  check_recording(held_out);
  // The initial state: the world fixed, one segment over the window's samples.
  Recording window = held_out;
  std::size_t n = 0;
  while (n < held_out.t.size() && held_out.t[n] - held_out.t[0] <= options.initial_window) ++n;
  if (n < 4)
    throw std::invalid_argument(
        "initial_window: " + std::to_string(n) + " samples of " + held_out.name + " in its first " +
        sim::format_number(options.initial_window) + " s; at least 4 are needed");
  window.t.resize(n);
  window.s_h.resize(n);
  window.sigma.resize(n);
  IdentifyOptions io;
  io.segment_duration = 2 * options.initial_window + 1;
  io.rtol = options.rtol;
  const detail::ShootingProblem start_problem(world, {window}, io, options.angle_offset,
                                              options.time_offset);
  const IdentifyResult start = detail::solve(start_problem, world, io);

  PredictionCheck out;
  out.name = held_out.name;
  out.s_h0 = start.segments.front().s_h;
  out.sdot_h0 = start.segments.front().sdot_h;
  io.segment_duration = std::numeric_limits<double>::max();
  const detail::ShootingProblem whole(world, {held_out}, io, options.angle_offset,
                                      options.time_offset);
  std::vector<double> predicted;
  std::string why;
  if (!whole.simulate_span(0, held_out.t[0], out.s_h0, out.sdot_h0, nullptr, predicted, &why))
    out.stopped = why;
  double sum2 = 0;
  for (std::size_t i = 0; i < predicted.size(); ++i) {
    const double e = whole.s_difference(predicted[i], held_out.s_h[i]);
    out.t.push_back(held_out.t[i]);
    out.measured.push_back(held_out.s_h[i]);
    out.predicted.push_back(predicted[i]);
    out.error.push_back(e);
    out.normalised_error.push_back(e / held_out.sigma[i]);
    sum2 += e * e;
    out.max_abs_error = std::max(out.max_abs_error, std::abs(e));
  }
  const std::size_t m = out.normalised_error.size();
  for (std::size_t i = 0; i < m && !out.time_to_3_sigma; ++i) {
    const std::size_t lo = i >= 2 ? i - 2 : 0, hi = std::min(m, i + 3);
    double z2 = 0;
    for (std::size_t j = lo; j < hi; ++j) z2 += out.normalised_error[j] * out.normalised_error[j];
    if (z2 > 9.0 * static_cast<double>(hi - lo)) out.time_to_3_sigma = out.t[i] - out.t[0];
  }
  out.rms_error = predicted.empty() ? 0.0 : std::sqrt(sum2 / static_cast<double>(predicted.size()));
  return out;
}

}  // namespace flatland::identify
