// The bookkeeping of a run's energy audit (flatland/sim/energy.hpp), for the planar runs
// (integration.hpp, hybrid.cpp) and the spatial run. Internal to sim/.
#pragma once

#include "flatland/sim/energy.hpp"

#include <algorithm>
#include <cmath>

namespace flatland::sim::detail {

class EnergyLedger {
 public:
  /// `floor`: the smallest energy scale, J (m |g| times the object's size: a run that barely
  /// moves is still measured against the energies its weight can exchange).
  EnergyLedger(EnergyAudit& audit, double tolerance, double floor) : a_(audit), floor_(floor) {
    a_.tolerance = tolerance;
    a_.scale = floor;
  }

  /// The energy at the start (the first call only; later segments continue the run).
  void start(double energy, double kinetic) {
    if (started_) return;
    started_ = true;
    a_.initial = a_.final = energy;
    note(energy, kinetic);
  }
  /// The works of one step (its increments), J.
  void add_work(double hand, double losses) {
    a_.work_hand += hand;
    a_.work_losses += losses;
    moved_ += std::abs(hand) + std::abs(losses);
    rescale();
  }
  /// An impact: the law's dissipation (<= 0) and the work of the impulse through the hand.
  void add_impact(double dissipation, double hand_work) {
    a_.impact_losses += dissipation;
    a_.work_hand += hand_work;
    moved_ += std::abs(dissipation) + std::abs(hand_work);
    rescale();
  }
  /// Compare the balance at t (energy E, kinetic part K) with the bound; false once it broke
  /// (the first breach is kept: time and size).
  bool check(double t, double energy, double kinetic) {
    note(energy, kinetic);
    a_.final = energy;
    a_.balance = energy - a_.initial - a_.work_hand - a_.work_losses - a_.impact_losses;
    ++a_.checks;
    const double size = std::abs(a_.balance);
    if (!(size <= a_.worst)) {  // NaN too
      a_.worst = size;
      a_.t_worst = t;
    }
    if (!a_.broken && !(size <= a_.bound())) {
      a_.broken = true;
      a_.t_broken = t;
    }
    return !a_.broken;
  }
  const EnergyAudit& audit() const { return a_; }

 private:
  void note(double energy, double kinetic) {
    a_.magnitude = std::max(a_.magnitude, std::abs(energy));
    kinetic_ = std::max(kinetic_, kinetic);
    rescale();
  }
  void rescale() { a_.scale = std::max(kinetic_, floor_) + moved_; }

  EnergyAudit& a_;
  double floor_;
  double kinetic_ = 0, moved_ = 0;
  bool started_ = false;
};

}  // namespace flatland::sim::detail
