// The energy audit every run keeps (docs/DYNAMICS.md, "Energy audit"). The object's mechanical
// energy E (kinetic + potential in the field of gravity) changes only by the work of the forces
// on it besides gravity: the hand's contact force and couple through the hand's own motion
// (W_hand: a moving hand gives and takes energy), friction, rolling resistance and drag
// (W_losses <= 0), and the impacts (the impact law's dissipation, <= 0; an impulse's work through
// the hand's velocity is the hand's). The works are integrated beside the state with the run's
// own Runge-Kutta weights (flights: Gauss-Legendre on the closed form), so
//
//   balance = E(t) - E(0) - W_hand - W_losses - dE_impacts
//
// is zero up to the integrator's error. A run whose balance exceeds its bound (the relative
// tolerance times the energy the run moved) ends as a numerical failure, never a success: a
// state that jumps (a chart change, a mode switch, an impulse applied wrongly) shows there.
#pragma once

#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>

namespace flatland::sim {

/// The power of the forces on the object besides gravity, W.
struct Power {
  double hand = 0;    ///< the hand's contact force and couple, through the hand's velocity there
  double losses = 0;  ///< friction on the slip, the rolling-resistance couple, drag (<= 0)
};

/// A run's energy balance and its bound, J.
struct EnergyAudit {
  double initial = 0;        ///< E at the start
  double final = 0;          ///< E at the end (of the run, or where the balance broke)
  double work_hand = 0;      ///< by the hand (impulses at impacts included)
  double work_losses = 0;    ///< by friction, rolling resistance and drag (<= 0)
  double impact_losses = 0;  ///< the impact law's dissipation (<= 0)
  /// final - initial - work_hand - work_losses - impact_losses.
  double balance = 0;
  double worst = 0;  ///< the largest |balance| at a check
  double t_worst = std::numeric_limits<double>::quiet_NaN();
  /// The energy the run moved: max(largest kinetic energy, m |g| size of the object) + the
  /// integrals of |power| + the impacts' |work|. The bound is tolerance x scale.
  double scale = 0;
  double tolerance = 0;  ///< relative (IntegratorSettings::energy_tolerance, or its default)
  double magnitude = 0;  ///< the largest |E| (the potential's origin is arbitrary: rounding)
  long checks = 0;       ///< where the balance was compared with the bound
  bool broken = false;   ///< the balance exceeded the bound: the run stopped there
  double t_broken = std::numeric_limits<double>::quiet_NaN();
  /// tolerance x scale, plus the rounding of E itself (1e-12 |E|).
  double bound() const { return tolerance * scale + 1e-12 * magnitude; }
};

/// A run's numbers are wrong (its energy balance broke, sim/energy.hpp): what a caller that uses
/// a run (a search, a plan, frames) throws, so that a sweep can record it and go on.
class NumericalFailure : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Where and by how much a broken balance broke: "the energy balance broke at t = ... s (... J,
/// bound ... J)".
std::string breach_text(const EnergyAudit& audit);

/// The relative tolerance of a run's energy balance: `given`, else 1e3 x rtol for the adaptive
/// methods (their global error stays within a few hundred local tolerances over the runs the
/// tests measure: docs/DYNAMICS.md) and 1e-6 for fixed-step RK4 (which has no error estimate:
/// set integrator.energy_tolerance to what its step achieves). Never below 1e-12 (rounding of
/// E itself over long runs).
inline double energy_tolerance(std::optional<double> given, bool fixed_step, double rtol) {
  if (given) return *given;
  return fixed_step ? 1e-6 : std::fmax(1e3 * rtol, 1e-12);
}

}  // namespace flatland::sim
