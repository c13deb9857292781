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

/// The hybrid model from an initial contact or from a state a previous run ended in
/// (RunResult::final_state). Called by simulate() for options.model == kHybrid.
RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const InitialContact& init,
                          const RunOptions& options);
RunResult simulate_hybrid(std::shared_ptr<const RollingProblem> problem, const HybridState& start,
                          const RunOptions& options);

}  // namespace flatland::sim
