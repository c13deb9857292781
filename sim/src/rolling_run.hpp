// The rolling model's run (simulate() with model: rolling), for any formulation of the rolling
// contact: ReducedDiskRolling, GeneralRolling, and the reduced disk with its sensitivities
// (sensitivity.cpp). Internal to sim/.
#pragma once

#include "flatland/sim/rolling.hpp"
#include "flatland/sim/simulate.hpp"
#include "integration.hpp"

#include <cmath>
#include <memory>
#include <stdexcept>
#include <utility>
#include <vector>

namespace flatland::sim::detail {

/// The initial contact's numbers, checked before a model is built from the problem.
inline void require_finite(const InitialContact& init) {
  if (!std::isfinite(init.s_h) || !std::isfinite(init.sdot_h) || !std::isfinite(init.t0))
    throw std::invalid_argument("initial: s_h, sdot_h and t0 must be finite");
}

/// The rolling model: one segment from the initial contact; contact loss and slip (when asked)
/// stop it, at once if the initial state already violates them. With `final_state`, the state
/// where the run ended.
template <class Model>
RunResult run_rolling(const Model& model, const InitialContact& init, const RunOptions& options,
                      typename Model::State* final_state = nullptr) {
  const RollingProblem* problem = &model.problem();
  require_finite(init);
  validate_run_options(options, init.t0);
  if (problem->contact.has_losses())
    throw std::invalid_argument(
        "contact: the losses (rolling_resistance, drag, drag_angular) need contact.model: hybrid "
        "(the rolling model is the paper's lossless simulation)");
  RunResult res;
  res.method = options.integrator.method;
  const double weight = problem->object.mass * problem->gravity;
  std::vector<Guard> guards;
  if (options.events.stop_on_contact_loss)
    guards.push_back(
        {EventKind::kContactLost, [](const Sample& s) { return s.force_normal; }, 0.0});
  if (options.events.stop_on_slip && problem->contact.mu) {
    const double mu = *problem->contact.mu;
    guards.push_back(
        {EventKind::kSlip,
         [mu](const Sample& s) { return mu * s.force_normal - std::abs(s.force_tangential); },
         1e-12 * weight});
  }
  EnergyLedger ledger = planar_ledger(res.audit, *problem, options);

  double t = init.t0;
  typename Model::State y = model.initial_state(init);
  // Direction of travel decides which piece is active when starting on a junction; at rest the
  // initial acceleration decides.
  int dir = Model::sdot_h(y) < 0 ? -1 : +1;
  const int motion_segment = problem->motion->segment_at(t);
  if (Model::sdot_h(y) == 0) {
    Pieces p = model.pieces_for(y, +1);
    p.motion = motion_segment;
    typename Model::State dy;
    model.derivative(t, y, p, dy);
    ++res.stats.rhs_evals;
    dir = Model::sdot_h(dy) < 0 ? -1 : +1;  // the rate slot of the derivative holds sddot_h
  }
  Pieces pieces = model.pieces_for(y, dir);
  pieces.motion = motion_segment;
  model.project(t, y, pieces);
  const auto end =
      options.audit
          ? Integration<Model, true>(model, options, res, std::move(guards), ledger, init.t0)
                .run_from(t, y, pieces)
          : Integration<Model, false>(model, options, res, std::move(guards), ledger, init.t0)
                .run_from(t, y, pieces);
  res.initial = end.first;
  res.final = end.last;
  if (final_state) *final_state = end.y;
  if (end.fired) {
    res.reason = *end.fired == EventKind::kContactLost        ? StopReason::kContactLost
                 : *end.fired == EventKind::kSlip             ? StopReason::kSlip
                 : *end.fired == EventKind::kNumericalFailure ? StopReason::kNumericalFailure
                                                              : StopReason::kLeftBounds;
    RecordedEvent e;
    e.kind = *end.fired;
    e.t = end.t;
    e.s_h = Model::s_h(end.y);
    e.position = end.last.object_position;
    res.events.push_back(e);
  }
  finish_run(res, options);
  return res;
}

}  // namespace flatland::sim::detail
