// The contact between the object and the hand beyond perfect rolling: Coulomb friction, the
// planar impact law, the losses, and the modes a contact can be in (docs/DYNAMICS.md, "Contact
// modes").
#pragma once

#include "flatland/sim/curve.hpp"

#include <Eigen/Core>

#include <optional>
#include <string>

namespace flatland::sim {

/// What the contact is doing. An impact is an instant between two of these, not a mode.
enum class ContactMode {
  kRolling,  ///< no slip; the paper's equations
  kRest,     ///< no slip and no rolling: held by the rolling-resistance couple (|tau| <= delta f_n)
  kSliding,  ///< Coulomb friction mu_k f_n opposing the slip velocity
  kFlight,   ///< no contact: the free object in the table plane
};
std::string to_string(ContactMode m);

/// How a run treats the contact.
enum class ContactModel {
  /// The paper's simulation: rolling is enforced; contact loss and slip (at contact.mu) can only
  /// stop the run (EventSettings).
  kRolling,
  /// Rolling, rest, sliding, flight and impacts, with the losses: what a real table does.
  kHybrid,
};
std::string to_string(ContactModel m);

/// The physical law of the contact and the losses (the scene's `contact` section). SI units.
struct ContactLaw {
  /// Static friction coefficient; absent = unlimited friction (the object never slips).
  std::optional<double> mu;
  /// Kinetic friction coefficient, <= mu; absent = mu.
  std::optional<double> mu_kinetic;
  /// Newton's coefficient of restitution of the normal relative velocity, in [0, 1].
  double restitution = 0.0;
  /// m/s: an impact whose rebound (normal separation speed) is at most this ends in contact
  /// instead of another bounce (the rule that ends a chattering sequence of bounces).
  double capture_velocity = 1e-3;
  /// m: rolling resistance, the lever arm of the couple delta f_n that opposes rolling (the
  /// normal force's shift ahead of the contact point); 0 = none.
  double rolling_resistance = 0.0;
  /// N s/m: viscous drag on the object's centre, force -drag v (v relative to the table).
  double drag = 0.0;
  /// N m s/rad: viscous drag couple, -drag_angular omega.
  double drag_angular = 0.0;

  double mu_static() const;  ///< mu, or +infinity when absent
  double kinetic() const;    ///< mu_kinetic, or mu, or +infinity
  bool has_losses() const { return rolling_resistance > 0 || drag > 0 || drag_angular > 0; }
  /// std::invalid_argument naming the field ("contact.mu_kinetic: ...") for mu < 0, mu_k > mu,
  /// mu_kinetic without mu, restitution outside [0, 1], a negative or non-finite loss or
  /// capture velocity.
  void validate() const;
};

/// One impact: relative velocities of the object's contact point with respect to the hand's,
/// along the hand's outward normal n and its tangent t (direction of increasing s_h), before and
/// after, and the impulse on the object.
struct ImpactResult {
  double impulse_normal = 0, impulse_tangential = 0;  ///< N s, on the object
  double vn_before = 0, vt_before = 0;                ///< m/s (vn < 0: approaching)
  double vn_after = 0, vt_after = 0;
  bool sticking = false;  ///< the tangential slip was stopped within the friction cone
  /// J: change of kinetic energy of the relative motion, 0.5 P . (v_before + v_after); <= 0.
  double energy_change = 0;
};

/// The planar impact law at one contact: Newton's restitution on the normal relative velocity
/// and Coulomb friction at the impulse level. `W` is the inverse effective mass (the relative
/// velocity change per unit impulse) in the (n, t) basis, symmetric positive definite. First a
/// sticking impulse (normal rebound -e vn, no tangential slip) is tried; if it needs more than
/// mu P_n, the impulse slides, P_t = mu_k P_n against the slip left after the impact (for a disk
/// on a prescribed hand, -mu_k sgn(vt) P_n). When neither is consistent (possible only when the
/// hand's inertia couples the normal and tangential directions in W), the impact is plastic and
/// sticking. The energy of the relative motion never increases: a law that would create some
/// (possible with coupling) has its restitution lowered until it does not. Requires vn < 0.
ImpactResult impact(const Eigen::Matrix2d& W, double vn, double vt, const ContactLaw& law);

/// The inverse effective mass of a rigid object (mass m, inertia I about its centre) touched at
/// `r` (from its centre to the contact point, world axes), in the basis (n, t); plus, when
/// `hand_inertia` is given, that of a hand turning about a fixed pivot and touched at `rho`
/// (from the pivot to the contact point).
Eigen::Matrix2d inverse_effective_mass(double m, double inertia, const Vec2& r, const Vec2& n,
                                       const Vec2& t, std::optional<double> hand_inertia = {},
                                       const Vec2& rho = Vec2::Zero());

}  // namespace flatland::sim
