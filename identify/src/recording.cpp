// Recordings' checks, the joint log's spline motion, and the parameters' names and bounds.
#include "flatland/identify/identify.hpp"
#include "flatland/sim/format.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

namespace flatland::identify {
namespace {

void check_series(const std::string& where, const std::vector<double>& values, bool increasing,
                  bool positive) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::string field = where + "[" + std::to_string(i) + "]";
    if (!std::isfinite(values[i])) {
      throw std::invalid_argument(field + ": not a finite number");
    }
    if (positive && !(values[i] > 0)) {
      throw std::invalid_argument(field + ": must be > 0, got " + sim::format_number(values[i]));
    }
    if (increasing && i > 0 && !(values[i] > values[i - 1])) {
      throw std::invalid_argument(field + ": times must increase strictly (" +
                                  sim::format_number(values[i]) + " after " +
                                  sim::format_number(values[i - 1]) + ")");
    }
  }
}

void check_joint_log(const std::string& where, const std::vector<double>& t,
                     const std::vector<double>& theta) {
  if (t.size() != theta.size()) {
    throw std::invalid_argument(where + "joint_theta: " + std::to_string(theta.size()) +
                                " angles for " + std::to_string(t.size()) + " times");
  }
  if (t.size() < 4) {
    throw std::invalid_argument(where + "joint_t: at least 4 entries are needed, got " +
                                std::to_string(t.size()));
  }
  check_series(where + "joint_t", t, true, false);
  check_series(where + "joint_theta", theta, false, false);
}

}  // namespace

void check_recording(const Recording& r) {
  const std::string where = (r.name.empty() ? std::string("recording") : r.name) + ": ";
  if (r.s_h.size() != r.t.size() || r.sigma.size() != r.t.size()) {
    throw std::invalid_argument(where + "t, s_h and sigma differ in length (" +
                                std::to_string(r.t.size()) + ", " + std::to_string(r.s_h.size()) +
                                ", " + std::to_string(r.sigma.size()) + ")");
  }
  if (r.t.size() < 4) {
    throw std::invalid_argument(where + "t: at least 4 samples are needed, got " +
                                std::to_string(r.t.size()));
  }
  check_series(where + "t", r.t, true, false);
  check_series(where + "s_h", r.s_h, false, false);
  check_series(where + "sigma", r.sigma, false, true);
  check_joint_log(where, r.joint_t, r.joint_theta);
}

JointLogMotion::JointLogMotion(std::vector<double> t, const std::vector<double>& theta,
                               double time_offset, double angle_offset)
    : t_(std::move(t)), time_offset_(time_offset), angle_offset_(angle_offset) {
  check_joint_log("", t_, theta);
  if (!std::isfinite(time_offset) || !std::isfinite(angle_offset)) {
    throw std::invalid_argument("JointLogMotion: offsets must be finite");
  }
  // Not-a-knot cubic spline: second derivatives M_i from the tridiagonal system of continuity
  // of the first derivative, with the third derivative continuous across t_1 and t_{n-2}.
  const std::size_t n = t_.size();
  std::vector<double> h(n - 1), slope(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    h[i] = t_[i + 1] - t_[i];
    slope[i] = (theta[i + 1] - theta[i]) / h[i];
  }
  // Unknowns M_0..M_{n-1}; rows 1..n-2: h_{i-1} M_{i-1} + 2 (h_{i-1} + h_i) M_i + h_i M_{i+1}
  // = 6 (slope_i - slope_{i-1}); row 0 and n-1: not-a-knot, eliminated into rows 1 and n-2.
  std::vector<double> sub(n, 0), diag(n, 0), sup(n, 0), rhs(n, 0);
  for (std::size_t i = 1; i + 1 < n; ++i) {
    sub[i] = h[i - 1];
    diag[i] = 2 * (h[i - 1] + h[i]);
    sup[i] = h[i];
    rhs[i] = 6 * (slope[i] - slope[i - 1]);
  }
  // Not-a-knot at the start: M_0 = ((h0 + h1) M_1 - h0 M_2) / h1.
  diag[1] += sub[1] * (h[0] + h[1]) / h[1];
  sup[1] -= sub[1] * h[0] / h[1];
  sub[1] = 0;
  // At the end: M_{n-1} = ((h_{n-3} + h_{n-2}) M_{n-2} - h_{n-2} M_{n-3}) / h_{n-3}.
  const std::size_t m = n - 2;
  diag[m] += sup[m] * (h[m - 1] + h[m]) / h[m - 1];
  sub[m] -= sup[m] * h[m] / h[m - 1];
  sup[m] = 0;
  // Thomas algorithm over rows 1..n-2.
  for (std::size_t i = 2; i <= m; ++i) {
    const double w = sub[i] / diag[i - 1];
    diag[i] -= w * sup[i - 1];
    rhs[i] -= w * rhs[i - 1];
  }
  std::vector<double> M(n, 0);
  M[m] = rhs[m] / diag[m];
  for (std::size_t i = m - 1; i >= 1; --i) {
    M[i] = (rhs[i] - sup[i] * M[i + 1]) / diag[i];
  }
  M[0] = ((h[0] + h[1]) * M[1] - h[0] * M[2]) / h[1];
  M[n - 1] = ((h[m - 1] + h[m]) * M[m] - h[m] * M[m - 1]) / h[m - 1];
  a_.resize(n - 1);
  b_.resize(n - 1);
  c_.resize(n - 1);
  d_.resize(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    a_[i] = theta[i];
    b_[i] = slope[i] - h[i] * (2 * M[i] + M[i + 1]) / 6;
    c_[i] = M[i] / 2;
    d_[i] = (M[i + 1] - M[i]) / (6 * h[i]);
  }
}

sim::HandKinematics JointLogMotion::at(double t, int) const {
  const double tj = t + time_offset_;
  // The piece whose left knot is the last one <= tj (the end pieces extrapolate).
  const auto it = std::upper_bound(t_.begin(), t_.end(), tj);
  std::size_t i = it == t_.begin() ? 0 : static_cast<std::size_t>(it - t_.begin()) - 1;
  i = std::min(i, a_.size() - 1);
  const double u = tj - t_[i];
  sim::HandKinematics k;
  k.angle = a_[i] + u * (b_[i] + u * (c_[i] + u * d_[i])) + angle_offset_;
  k.angular_velocity = b_[i] + u * (2 * c_[i] + 3 * u * d_[i]);
  k.angular_acceleration = 2 * c_[i] + 6 * u * d_[i];
  return k;
}

const std::vector<std::string>& parameter_names() {
  static const std::vector<std::string> names = {
      "mu_static",    "mu_kinetic", "restitution",  "rolling_resistance", "drag",
      "drag_angular", "tilt",       "angle_offset", "time_offset"};
  return names;
}

Bounds default_bounds(const std::string& name) {
  if (name == "mu_static" || name == "mu_kinetic") return {0.0, 3.0};
  if (name == "restitution") return {0.0, 1.0};
  if (name == "rolling_resistance") return {0.0, 5e-3};  // m: a tenth of a 5 cm disk's radius
  if (name == "drag") return {0.0, 10.0};                // N s/m
  if (name == "drag_angular") return {0.0, 0.1};         // N m s/rad
  if (name == "tilt") return {1e-3, 0.5 * std::numbers::pi};
  if (name == "angle_offset") return {-0.2, 0.2};  // rad, about 11 degrees
  if (name == "time_offset") return {-0.2, 0.2};   // s
  throw std::invalid_argument("unknowns: unknown parameter '" + name +
                              "' (mu_static, mu_kinetic, restitution, rolling_resistance, drag, "
                              "drag_angular, tilt, angle_offset, time_offset)");
}

}  // namespace flatland::identify
