// The JSON reports of the simulator's results: the keys that `flatland COMMAND --json` prints and
// that the Python module returns as dicts, written once for both. Numbers are SI; a value that is
// not finite is null (JSON has no inf or NaN).
#pragma once

#include "flatland/design/design.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_spec.hpp"
#include "flatland/sim/spec.hpp"

#include <nlohmann/json.hpp>

#include <array>
#include <string>
#include <vector>

namespace flatland::api {

using Json = nlohmann::ordered_json;

/// A JSON number, or null when it is inf/NaN.
Json number(double v);

/// The events of a run that change the contact (junction crossings and the apex left out), in
/// time order, with the impacts' impulses and velocities.
Json contact_events_json(const std::vector<sim::RecordedEvent>& events);
/// Each flight: lift-off, landing (time, s_h, point), first impulse, bounces, catch or drop.
Json flights_json(const std::vector<sim::FlightReport>& flights);
/// Seconds in each mode, changes, impacts, flights and events: what the contact did.
Json contact_summary_json(const std::array<double, 4>& mode_time, int mode_changes, int impacts,
                          const std::vector<sim::RecordedEvent>& events,
                          const sim::Sample& initial);

/// Keys shared by the solve and time-optimal reports.
/// A run's energy audit (flatland/sim/energy.hpp): its terms, balance, bound and whether it held.
Json energy_json(const sim::EnergyAudit& audit);
/// The one line that says where and by how much a broken energy balance broke.
std::string energy_failure_text(const sim::EnergyAudit& audit);
Json solve_report_json(const sim::SolveReport& r);
/// `design --json`: the start, the best design, what binds there, every evaluation and why the
/// search stopped.
Json design_json(const design::DesignResult& r, const sim::SimulationSpec& spec);
/// One evaluation of a design (its parameters by name, the objective and the constraints).
Json design_iterate_json(const design::Iterate& it);

/// `time-optimal --json` without its files.
Json time_optimal_json(const sim::TimeOptimalReport& r, const sim::SimulationSpec& spec);

/// `locus --json`'s points and mu (without its files and timing).
Json locus_json(const std::vector<sim::SolveReport>& points, const sim::SimulationSpec& spec);

/// s_h(T) from the dense output (NaN when the run does not cover t = T or the motion is not the
/// butterfly).
double s_at_half_period(const sim::SimulationSpec& spec, const sim::RunResult& r);
/// The object as the run used it: `type`, `mass`, `radius` (the description's: a disk's or
/// ring's outer, a ball's own), `rolling_radius` (centre to contact in the plane: below `radius`
/// for a ball on rails) and `inertia` about the centre (given, or the uniform body's); an
/// ellipse has null radii.
Json object_json(const sim::ObjectSpec& object);
/// `simulate --json` without its csv key: the run's end, extrema, integrator statistics and
/// contact (modes, flights, events).
Json simulate_json(const sim::SimulationSpec& spec, const sim::RunResult& r);

/// `simulate --json` of a spatial scene without its files: where and why the run stopped
/// (`success` only when it reached its end time), the final state, the extrema of the forces,
/// the energy's change and the integrator's statistics.
Json spatial_simulate_json(const sim::SpatialSpec& spec, const sim::SpatialRunResult& r);

}  // namespace flatland::api
