#include "flatland/control/rolling_filter.hpp"
#include "flatland/sim/format.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace flatland::control {

namespace {

// Longest RK4 step on the mean: 2 ms keeps the local error far below the measurement noise even
// near the fingertip (docs/ESTIMATOR.md); longer intervals are split evenly.
constexpr double kMaxSubstep = 2e-3;
// Tolerance on "capture time after the current time": loop clocks are sums of doubles.
constexpr double kTimeSlack = 1e-9;

void require_positive(const char* field, double v) {
  if (!(v > 0) || !std::isfinite(v))
    throw std::invalid_argument(std::string("estimator.") + field + ": must be positive, got " +
                                sim::format_significant(v));
}

void require_finite(const char* what, double v) {
  if (!std::isfinite(v))
    throw std::invalid_argument(std::string("estimator.") + what + ": must be finite, got " +
                                sim::format_significant(v));
}

const EstimatorConfig& checked(const EstimatorConfig& config) {
  require_positive("process_noise", config.process_noise);
  require_positive("history", config.history);
  require_positive("initial_sigma_s", config.initial_sigma_s);
  require_positive("initial_sigma_sdot", config.initial_sigma_sdot);
  return config;
}

}  // namespace

std::string to_string(EstimatorModel m) {
  switch (m) {
    case EstimatorModel::kRolling:
      return "rolling";
    case EstimatorModel::kConstantVelocity:
      return "constant-velocity";
  }
  return "unknown";
}

EstimatorModel parse_estimator_model(const std::string& name) {
  if (name == "rolling") return EstimatorModel::kRolling;
  if (name == "constant-velocity") return EstimatorModel::kConstantVelocity;
  throw std::invalid_argument("estimator.model: expected 'rolling' or 'constant-velocity', got '" +
                              name + "'");
}

HandInput advance(const HandInput& u, double tau) {
  return {u.theta + tau * (u.theta_dot + 0.5 * tau * u.theta_ddot),
          u.theta_dot + tau * u.theta_ddot, u.theta_ddot};
}

Eigen::Matrix2d process_covariance(double q2, double h) {
  Eigen::Matrix2d Q;
  Q << h * h * h / 3.0, 0.5 * h * h, 0.5 * h * h, h;
  return q2 * Q;
}

// ---------------------------------------------------------------------------------------------
// DiskOnHand

DiskOnHand::DiskOnHand(std::shared_ptr<const sim::RollingProblem> model)
    : model_(std::move(model)) {
  if (!model_ || !model_->hand)
    throw std::invalid_argument("estimator.model: a hand outline and a disk are required");
  if (!model_->object.disk_radius)
    throw std::invalid_argument("estimator.model: the object must be a disk, got " +
                                model_->object.kind);
  hand_ = model_->hand.get();
  // ReducedDiskRolling insists on a motion although acceleration() never uses it; give it a
  // still hand when the caller's model has none.
  std::shared_ptr<const sim::RollingProblem> for_rolling = model_;
  if (!model_->motion) {
    auto copy = std::make_shared<sim::RollingProblem>(*model_);
    copy->motion = std::make_shared<sim::FixedHand>(0.0);
    for_rolling = std::move(copy);
  }
  rolling_ = std::make_shared<const sim::ReducedDiskRolling>(std::move(for_rolling));
}

int DiskOnHand::piece_at(double s, double sdot) const {
  return hand_->piece_at(s, sdot >= 0 ? +1 : -1);
}

double DiskOnHand::acceleration(const sim::HandKinematics& h, double s, double sdot,
                                int piece) const {
  return rolling_->acceleration(h, s, sdot, piece);
}

double DiskOnHand::acceleration(const HandInput& u, double tau, double s, double sdot,
                                int piece) const {
  const HandInput a = advance(u, tau);
  sim::HandKinematics h;  // pivot fixed: position, velocity, acceleration zero
  h.angle = a.theta;
  h.angular_velocity = a.theta_dot;
  h.angular_acceleration = a.theta_ddot;
  return rolling_->acceleration(h, s, sdot, piece);
}

void DiskOnHand::rk4(const HandInput& u, double tau0, double h, int piece,
                     Eigen::Vector2d& x) const {
  const double s = x[0], v = x[1];
  const double a1 = acceleration(u, tau0, s, v, piece);
  const double s2 = s + 0.5 * h * v, v2 = v + 0.5 * h * a1;
  const double a2 = acceleration(u, tau0 + 0.5 * h, s2, v2, piece);
  const double s3 = s + 0.5 * h * v2, v3 = v + 0.5 * h * a2;
  const double a3 = acceleration(u, tau0 + 0.5 * h, s3, v3, piece);
  const double s4 = s + h * v3, v4 = v + h * a3;
  const double a4 = acceleration(u, tau0 + h, s4, v4, piece);
  x[0] = s + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4);
  x[1] = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4);
}

void DiskOnHand::step(double h, const HandInput& u, int piece, Eigen::Vector2d& x) const {
  // RK4 on one smooth piece of the hand. At a junction (odd s_h on the paper's hand) sddot_h
  // jumps (d|J|/ds does), and an RK4 step straddling it makes an O(h) error in sdot_h, ~1e-3 in
  // s_h after one crossing of the palm well at 1 ms. So, as the simulator does, the step that
  // leaves the piece is cut where it reaches the junction (located on the RK4 step map itself, so
  // the first part ends exactly there) and finished on the next piece.
  const double s = x[0];
  Eigen::Vector2d end = x;
  rk4(u, 0.0, h, piece, end);
  const sim::PieceInterval span = hand_->piece_interval(piece);
  if (end[0] >= span.lo && end[0] <= span.hi) {
    x = end;
    return;
  }
  const bool down = end[0] < span.lo;
  const double junction = down ? span.lo : span.hi;
  const int next = hand_->piece_at(junction, down ? -1 : +1);
  // Illinois (modified regula falsi) on g(tau) = s(tau) - junction over [0, h]: g changes sign
  // there, and it converges superlinearly even where sdot_h ~ 0 (a disk resting on the junction,
  // as the butterfly's starts).
  double t_lo = 0.0, g_lo = s - junction, t_hi = h, g_hi = end[0] - junction;
  Eigen::Vector2d at = x;
  double tau = 0.0;
  if (g_lo != 0.0) {
    int side = 0;
    for (int it = 0; it < 60; ++it) {
      tau = (t_lo * g_hi - t_hi * g_lo) / (g_hi - g_lo);
      at = x;
      rk4(u, 0.0, tau, piece, at);
      const double g = at[0] - junction;
      if (g == 0.0 || t_hi - t_lo < 1e-15 || std::abs(g) < 1e-15) break;
      if ((g < 0) == (g_lo < 0)) {
        t_lo = tau, g_lo = g;
        if (side == -1) g_hi *= 0.5;
        side = -1;
      } else {
        t_hi = tau, g_hi = g;
        if (side == +1) g_lo *= 0.5;
        side = +1;
      }
    }
  }
  at[0] = junction;
  rk4(u, tau, h - tau, next, at);
  x = at;
}

// ---------------------------------------------------------------------------------------------
// Ring

void RollingFilter::Ring::push_back(const Stored& s) {
  if (size_ == slots_.size()) {
    // Grow by re-laying the entries out oldest first; only while the history fills up.
    std::vector<Stored> bigger;
    bigger.reserve(std::max<std::size_t>(64, 2 * slots_.size()));
    for (std::size_t i = 0; i < size_; ++i) bigger.push_back((*this)[i]);
    bigger.resize(bigger.capacity());
    slots_ = std::move(bigger);
    head_ = 0;
  }
  slots_[(head_ + size_) % slots_.size()] = s;
  ++size_;
}

void RollingFilter::Ring::pop_front() {
  head_ = (head_ + 1) % slots_.size();
  --size_;
}

void RollingFilter::Ring::insert(std::size_t i, const Stored& s) {
  push_back(s);  // makes room (and grows if needed)
  for (std::size_t j = size_ - 1; j > i; --j) (*this)[j] = (*this)[j - 1];
  (*this)[i] = s;
}

// ---------------------------------------------------------------------------------------------
// RollingFilter

RollingFilter::RollingFilter(std::shared_ptr<const sim::RollingProblem> model,
                             EstimatorConfig config)
    : config_(checked(config)), disk_(std::move(model)) {
  P_initial_ = Eigen::Vector2d(config_.initial_sigma_s * config_.initial_sigma_s,
                               config_.initial_sigma_sdot * config_.initial_sigma_sdot)
                   .asDiagonal();
  reset(0.0, 0.0, 0.0);
}

void RollingFilter::reset(double t, double s_h, double sdot_h) {
  require_finite("reset.t", t);
  require_finite("reset.s_h", s_h);
  require_finite("reset.sdot_h", sdot_h);
  t_ = t;
  x_ = {s_h, sdot_h};
  P_ = P_initial_;
  history_.clear();
}

Estimate RollingFilter::estimate() const { return {t_, x_[0], x_[1], P_}; }

void RollingFilter::step(double t0, double t1, const HandInput& u, Eigen::Vector2d& x,
                         Eigen::Matrix2d& P) const {
  const double dt = t1 - t0;
  // (The slack keeps a 2 ms step computed as a difference of times from becoming two.)
  const int n = std::max(1, static_cast<int>(std::ceil(dt / kMaxSubstep - 1e-9)));
  const double h = dt / n;
  for (int i = 0; i < n; ++i) {
    substep(t0 + i * h, h, i == 0 ? u : advance(u, i * h), x, P);
    check_finite(t0 + (i + 1) * h, x);
  }
  // Keep P exactly symmetric: the products above round differently in the two off-diagonals.
  const double off = 0.5 * (P(0, 1) + P(1, 0));
  P(0, 1) = P(1, 0) = off;
  if (!P.allFinite()) {
    std::ostringstream out;
    out << "estimator: non-finite covariance at t = " << t1 << " (s_h = " << x[0] << ")";
    throw std::runtime_error(out.str());
  }
}

void RollingFilter::check_finite(double t, const Eigen::Vector2d& x) const {
  if (x.allFinite()) return;
  std::ostringstream out;
  out << "estimator: non-finite state at t = " << t << ": s_h = " << x[0] << ", sdot_h = " << x[1];
  throw std::runtime_error(out.str());
}

void RollingFilter::prune() {
  // Keep the steps that overlap [t - history, t].
  while (!history_.empty() && history_.front().t1 <= t_ - config_.history) history_.pop_front();
}

void RollingFilter::propagate(double t_next, const HandInput& input) {
  if (!std::isfinite(t_next) || !(t_next > t_)) {
    std::ostringstream out;
    out << "estimator.propagate: t_next = " << t_next << " must be after the current time " << t_;
    throw std::invalid_argument(out.str());
  }
  require_finite("propagate.theta", input.theta);
  require_finite("propagate.theta_dot", input.theta_dot);
  require_finite("propagate.theta_ddot", input.theta_ddot);
  history_.push_back({t_, t_next, input, x_, P_});
  step(t_, t_next, input, x_, P_);
  t_ = t_next;
  ++steps_;
  prune();
}

void RollingFilter::correct(const Measurement& z, Eigen::Vector2d& x, Eigen::Matrix2d& P,
                            UpdateReport& report) const {
  // H = [1 0]: P H^T is P's first column, H P H^T its (0, 0) entry.
  const double R = z.sigma * z.sigma;
  const double S = P(0, 0) + R;
  const Eigen::Vector2d K = P.col(0) / S;
  const double innovation = z.s_h - x[0];
  x += K * innovation;
  // Joseph form (I - K H) P (I - K H)^T + K R K^T: stays symmetric positive definite under
  // round-off, unlike (I - K H) P, when the measurement is much more precise than the prior.
  Eigen::Matrix2d IKH = Eigen::Matrix2d::Identity();
  IKH.col(0) -= K;
  P = IKH * P * IKH.transpose() + R * K * K.transpose();
  report.innovation = innovation;
  report.innovation_sigma = std::sqrt(S);
  report.nis = innovation * innovation / S;
}

UpdateReport RollingFilter::update(const Measurement& z) {
  require_finite("update.t_capture", z.t_capture);
  require_finite("update.s_h", z.s_h);
  require_positive("update.sigma", z.sigma);
  if (z.t_capture > t_ + kTimeSlack) {
    std::ostringstream out;
    out << "estimator.update: capture time " << z.t_capture << " is after the current time " << t_;
    throw std::invalid_argument(out.str());
  }
  UpdateReport report;
  if (!config_.latency_compensation || z.t_capture >= t_) {
    correct(z, x_, P_, report);
    report.applied = true;
    ++updates_;
    return report;
  }
  if (history_.empty() || z.t_capture < history_.front().t0) return report;  // too old

  // The stored step containing the capture: the last one with t0 <= t_capture (binary search;
  // the steps are contiguous and sorted).
  std::size_t lo = 0, hi = history_.size() - 1;
  while (lo < hi) {
    const std::size_t mid = (lo + hi + 1) / 2;
    if (history_[mid].t0 <= z.t_capture)
      lo = mid;
    else
      hi = mid - 1;
  }
  std::size_t i = lo;
  const int redone = static_cast<int>(history_.size() - i);

  Eigen::Vector2d x = history_[i].x0;
  Eigen::Matrix2d P = history_[i].P0;
  const double tau = z.t_capture - history_[i].t0;
  if (tau > 0) {
    // Propagate exactly to the capture, correct there, and split the step at the capture so the
    // corrected state is stored: a later measurement captured in the rest of this step rewinds
    // to it instead of to the uncorrected start.
    const Stored& s = history_[i];
    step(s.t0, z.t_capture, s.input, x, P);
    correct(z, x, P, report);
    Stored rest{z.t_capture, s.t1, advance(s.input, tau), x, P};
    history_[i].t1 = z.t_capture;
    history_.insert(i + 1, rest);
    ++i;
  } else {
    correct(z, x, P, report);
  }
  // Re-propagate with the stored inputs, rewriting each step's start state.
  for (std::size_t j = i; j < history_.size(); ++j) {
    Stored& s = history_[j];
    s.x0 = x;
    s.P0 = P;
    step(s.t0, s.t1, s.input, x, P);
  }
  x_ = x;
  P_ = P;
  report.applied = true;
  report.repropagated_steps = redone;
  steps_ += redone;
  repropagated_ += redone;
  ++updates_;
  return report;
}

}  // namespace flatland::control
