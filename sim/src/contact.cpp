#include "flatland/sim/contact.hpp"
#include "infinity.hpp"

#include "flatland/sim/format.hpp"

#include <Eigen/Cholesky>

#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace flatland::sim {

namespace {

void require(bool ok, const std::string& field, const std::string& what, double v) {
  if (!ok)
    throw std::invalid_argument("contact." + field + ": " + what + ", got " +
                                format_significant(v));
}

double sign(double v) { return v > 0 ? 1.0 : v < 0 ? -1.0 : 0.0; }
}  // namespace

std::string to_string(ContactMode m) {
  switch (m) {
    case ContactMode::kRolling:
      return "rolling";
    case ContactMode::kRest:
      return "rest";
    case ContactMode::kSliding:
      return "sliding";
    case ContactMode::kFlight:
      return "flight";
  }
  return "?";
}

std::string to_string(ContactModel m) { return m == ContactModel::kHybrid ? "hybrid" : "rolling"; }

double ContactLaw::mu_static() const { return mu ? *mu : kInf; }
double ContactLaw::kinetic() const { return mu_kinetic ? *mu_kinetic : mu_static(); }

void ContactLaw::validate() const {
  if (mu) require(std::isfinite(*mu) && *mu >= 0, "mu", "must be finite and >= 0", *mu);
  if (mu_kinetic) {
    if (!mu)
      throw std::invalid_argument(
          "contact.mu_kinetic: needs contact.mu (the static coefficient it may not exceed)");
    require(std::isfinite(*mu_kinetic) && *mu_kinetic >= 0, "mu_kinetic", "must be finite and >= 0",
            *mu_kinetic);
    require(*mu_kinetic <= *mu, "mu_kinetic",
            "must not exceed the static coefficient contact.mu = " + format_significant(*mu),
            *mu_kinetic);
  }
  require(restitution >= 0 && restitution <= 1, "restitution", "must be in [0, 1]", restitution);
  require(std::isfinite(capture_velocity) && capture_velocity >= 0, "capture_velocity",
          "must be finite and >= 0 (m/s)", capture_velocity);
  require(std::isfinite(rolling_resistance) && rolling_resistance >= 0, "rolling_resistance",
          "must be finite and >= 0 (m)", rolling_resistance);
  require(std::isfinite(drag) && drag >= 0, "drag", "must be finite and >= 0 (N s/m)", drag);
  require(std::isfinite(drag_angular) && drag_angular >= 0, "drag_angular",
          "must be finite and >= 0 (N m s/rad)", drag_angular);
}

Eigen::Matrix2d inverse_effective_mass(double m, double inertia, const Vec2& r, const Vec2& n,
                                       const Vec2& t, std::optional<double> hand_inertia,
                                       const Vec2& rho) {
  // An impulse P on the object at r changes its contact point's velocity by P/m + perp(r)
  // (perp(r) . P)/I; the reaction -P on a hand turning about its pivot changes the hand's
  // contact point's velocity by -perp(rho) (perp(rho) . P)/J, which adds to the relative one.
  Eigen::Matrix2d world = Eigen::Matrix2d::Identity() / m + perp(r) * perp(r).transpose() / inertia;
  if (hand_inertia) world += perp(rho) * perp(rho).transpose() / *hand_inertia;
  Eigen::Matrix2d basis;
  basis.col(0) = n;
  basis.col(1) = t;
  return basis.transpose() * world * basis;
}

namespace {

// The impulse of the law for an effective restitution e (Newton on the normal velocity, Coulomb
// at the impulse level): sticking inside the static cone; else sliding, the kinetic friction
// impulse against the slip that remains after the impact; if neither is consistent (possible
// only when W couples the directions), plastic and sticking.
Eigen::Vector2d impulse_for(const Eigen::Matrix2d& W, const Eigen::Vector2d& v, double e,
                            const ContactLaw& law, bool& sticking) {
  const Eigen::Vector2d stick = W.ldlt().solve(Eigen::Vector2d(-(1.0 + e) * v[0], -v[1]));
  const double mu_s = law.mu_static(), mu_k = law.kinetic();
  sticking = true;
  if (stick[0] >= 0 && std::abs(stick[1]) <= mu_s * stick[0]) return stick;
  sticking = false;
  const double first = v[1] != 0 ? -sign(v[1]) : sign(stick[1]);
  for (const double d : {first, -first}) {
    const double denominator = W(0, 0) + mu_k * d * W(0, 1);
    if (!(denominator > 0)) continue;
    Eigen::Vector2d p(-(1.0 + e) * v[0] / denominator, 0.0);
    p[1] = mu_k * d * p[0];
    const double vt_after = v[1] + W(1, 0) * p[0] + W(1, 1) * p[1];
    if (vt_after * d <= 0) return p;
  }
  sticking = true;
  return W.ldlt().solve(-v);
}

}  // namespace

ImpactResult impact(const Eigen::Matrix2d& W, double vn, double vt, const ContactLaw& law) {
  if (!(vn < 0)) throw std::logic_error("impact: the contact is not approaching (vn >= 0)");
  const Eigen::Vector2d v(vn, vt);
  const auto energy_change = [&](const Eigen::Vector2d& p) {
    return p.dot(v) + 0.5 * p.dot(W * p);  // = 0.5 P . (v_before + v_after)
  };
  bool sticking = false;
  Eigen::Vector2d p = impulse_for(W, v, law.restitution, law, sticking);
  if (energy_change(p) > 0) {
    // Only a coupled W can get here. Lower the restitution until no energy is created; the
    // plastic sticking impulse always dissipates (it takes the whole relative velocity away).
    double lo = 0, hi = law.restitution;
    for (int i = 0; i < 60; ++i) {
      const double mid = 0.5 * (lo + hi);
      bool st = false;
      (energy_change(impulse_for(W, v, mid, law, st)) > 0 ? hi : lo) = mid;
    }
    p = impulse_for(W, v, lo, law, sticking);
    if (energy_change(p) > 0) {
      p = W.ldlt().solve(-v);  // plastic and sticking: takes the whole relative velocity
      sticking = true;
    }
  }
  ImpactResult r;
  r.impulse_normal = p[0];
  r.impulse_tangential = p[1];
  r.vn_before = vn;
  r.vt_before = vt;
  const Eigen::Vector2d after = v + W * p;
  r.vn_after = after[0];
  r.vt_after = sticking ? 0.0 : after[1];
  r.sticking = sticking;
  r.energy_change = std::min(0.0, energy_change(p));
  return r;
}

}  // namespace flatland::sim
