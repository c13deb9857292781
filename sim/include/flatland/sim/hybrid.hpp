// The hybrid model: the object on the hand rolls, rests, slides, flies and is caught again
// (docs/DYNAMICS.md, "Contact modes"). A run is a sequence of segments, each in one mode and
// integrated by its own equations; every change of mode is an event located to the event
// tolerance, and a violation present at the start of a segment (the start of a run, a jump of the
// hand's acceleration, the instant after an impact) is an event at that instant.
//
//   rolling --(f_n = 0)--> flight      rolling --(|f_t| = mu_s f_n)--> sliding
//   sliding --(slip speed 0, |f_t| <= mu_s f_n)--> rolling (else the slip reverses)
//   rolling --(sdot_h = 0, |couple| <= delta f_n)--> rest --(|couple| = delta f_n)--> rolling
//   flight --(gap 0, approaching)--> impact --> flight (bounce) or contact (caught)
//
// Flight, impacts and the catch are modelled for a disk; another object's run stops where it
// loses contact (StopReason::kContactLost).
#pragma once

#include "flatland/sim/simulate.hpp"

#include <memory>
#include <optional>
#include <vector>

namespace flatland::sim {

/// Where a disk is relative to the hand outline.
struct HandGap {
  double distance = 0;  ///< m, from the disk's rim to the outline (< 0: they overlap)
  double s_h = 0;       ///< parameter of the outline's point nearest to the disk's centre
};
/// The gap of a disk centred at `centre` (world) to the whole closed hand outline at pose `h`.
HandGap disk_gap(const RollingProblem& problem, const HandKinematics& h, const Vec2& centre);

/// The hybrid state of an initial contact: rolling at init.s_h (before the instant's checks,
/// which the run makes).
HybridState hybrid_state(const RollingProblem& problem, const InitialContact& init);

/// Everything at a hybrid state at its time x.t, with the forces of its mode, by `formulation`
/// (kAuto: reduced for a disk); the hand's kinematics from the problem's motion.
Sample sample_state(std::shared_ptr<const RollingProblem> problem, const HybridState& x,
                    Formulation formulation = Formulation::kAuto);

/// The free object at time t from a state in flight (closed form, drag included; no contact is
/// looked for): for an object known to be out of the hand's reach.
HybridState fly(const RollingProblem& problem, const HybridState& x, double t);

/// One flight of a hybrid run, from its events: where the object left the hand, where it first
/// came down, what the impact did, and how it ended.
struct FlightReport {
  double t_lift_off = 0;
  double s_lift_off = 0;
  std::optional<double> t_landing;                    ///< the first impact
  double s_landing = 0;                               ///< hand parameter there
  Vec2 landing_position = Vec2::Zero();               ///< object centre, world, m
  double impulse_normal = 0, impulse_tangential = 0;  ///< N s, of the first impact
  int bounces = 0;                                    ///< impacts after which it flew on
  std::optional<double> t_caught;  ///< the impact after which it stayed in contact
  bool dropped = false;            ///< it left the hand's reach
};
std::vector<FlightReport> flight_reports(const RunResult& run);
/// The same from a list of events (in any order) of a run that started at `initial`.
std::vector<FlightReport> flight_reports(const std::vector<RecordedEvent>& events,
                                         const Sample& initial);

/// The hybrid model from an initial contact or from a state a previous run ended in
/// (RunResult::final_state). Called by simulate() for options.model == kHybrid.
RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                          const RunOptions& options);
RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const HybridState& start,
                          const RunOptions& options);

}  // namespace flatland::sim
