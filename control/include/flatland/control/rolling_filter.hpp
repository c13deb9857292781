// What the contact estimators share (estimator.hpp's extended Kalman filter, ukf.hpp's unscented
// filter): the nominal model they propagate with (a disk rolling on the hand, driven by the hand
// input; or the constant-velocity baseline), their config, and a Kalman filter on (s_h, sdot_h)
// that stores its recent steps so that a late measurement is folded in at its capture time
// (rewind, correct, re-propagate with the stored inputs). A filter type supplies only how the
// mean and covariance cross one short step; the checks, the history, the update and the errors
// are the same for every type (docs/ESTIMATOR.md).
#pragma once

#include "flatland/control/interfaces.hpp"
#include "flatland/control/types.hpp"
#include "flatland/sim/rolling.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

namespace flatland::control {

enum class EstimatorModel {
  kRolling,           ///< sddot_h from the rolling dynamics (ReducedDiskRolling)
  kConstantVelocity,  ///< sddot_h = 0 (baseline)
};
std::string to_string(EstimatorModel m);                        ///< "rolling", "constant-velocity"
EstimatorModel parse_estimator_model(const std::string& name);  ///< invalid_argument otherwise

struct EstimatorConfig {
  EstimatorModel model = EstimatorModel::kRolling;
  bool latency_compensation = true;
  /// White acceleration noise on sddot_h (1/s^2 per sqrt(Hz)): the model's mismatch (table tilt,
  /// disk size, the joint's tracking error) the filter admits. Q over a step dt is
  /// q^2 [dt^3/3, dt^2/2; dt^2/2, dt]. The default makes the filter consistent (time-averaged
  /// NEES ~2) on the air-table butterfly with the table's tilt off by 0.1 deg (docs/ESTIMATOR.md).
  double process_noise = 0.0043;
  double history = 0.3;  ///< s of stored steps for re-propagation (must exceed the latency)
  double initial_sigma_s = 0.02;     ///< 1-sigma of the initial s_h
  double initial_sigma_sdot = 0.02;  ///< 1/s, of the initial sdot_h
};

/// The hand input advanced by tau within its step: the angle and rate evolve exactly under the
/// held acceleration.
HandInput advance(const HandInput& u, double tau);

/// Q of white acceleration noise of density q2 over h (the exact integral for a double
/// integrator; the standard choice when the mismatch enters as an unmodelled acceleration).
Eigen::Matrix2d process_covariance(double q2, double h);

/// The nominal disk on the hand as the filters see it: sddot_h of a state with the hand's
/// kinematics from a held HandInput, and the mean's step over a short interval.
class DiskOnHand {
 public:
  /// `model`: the nominal hand, disk and in-plane gravity (its motion is not used). Throws
  /// std::invalid_argument naming `estimator.model` if there is no hand or the object is not a
  /// disk.
  explicit DiskOnHand(std::shared_ptr<const sim::RollingProblem> model);

  /// The hand's smooth piece a state is on (moving toward larger s_h when sdot >= 0).
  int piece_at(double s, double sdot) const;
  /// sddot_h with the hand's angle, rate and acceleration `h` (pivot fixed), on a hand piece.
  double acceleration(const sim::HandKinematics& h, double s, double sdot, int piece) const;
  /// sddot_h at a state with the hand at offset tau into a step driven by u, on a hand piece.
  double acceleration(const HandInput& u, double tau, double s, double sdot, int piece) const;
  /// The mean over h (<= a few ms) from the start of a step driven by u, starting on `piece`:
  /// one RK4 step; a step that leaves the piece is cut where it reaches the junction (located on
  /// the RK4 step map itself) and finished on the next piece.
  void step(double h, const HandInput& u, int piece, Eigen::Vector2d& x) const;

 private:
  /// One classical RK4 step of the mean over [tau0, tau0 + h] of a step driven by u, on one piece.
  void rk4(const HandInput& u, double tau0, double h, int piece, Eigen::Vector2d& x) const;

  std::shared_ptr<const sim::RollingProblem> model_;
  std::shared_ptr<const sim::ReducedDiskRolling> rolling_;  // shared: the filters are copyable
  const sim::Curve* hand_ = nullptr;
};

/// A Kalman filter on (s_h, sdot_h) over the nominal model, with latency compensation through a
/// stored history: everything of Estimator but how the belief crosses one short step
/// (substep()), which each filter type supplies.
class RollingFilter : public Estimator {
 public:
  /// Throws std::invalid_argument if the object is not a disk or a config field is invalid (the
  /// message names the field, e.g. "estimator.history: ..."). The belief starts at t = 0, (0, 0)
  /// with the initial covariance; call reset().
  RollingFilter(std::shared_ptr<const sim::RollingProblem> model, EstimatorConfig config);

  /// Start at time t from (s_h, sdot_h) with the configured initial covariance; clears history.
  void reset(double t, double s_h, double sdot_h) override;
  /// Advance the belief from its current time to t_next (> current time) with the hand input
  /// held over the interval (angle and rate at the start, acceleration constant). Stored for
  /// re-propagation. Throws std::invalid_argument if t_next is not after the current time (or
  /// anything is non-finite), std::runtime_error if the state becomes non-finite (the estimator
  /// must then be reset).
  void propagate(double t_next, const HandInput& input) override;
  /// Fold in a measurement. z.t_capture <= the current time. With latency compensation the
  /// update is made at t_capture (rewind + re-propagate); without, at the current time. A
  /// capture older than the stored history is not applied (report.applied = false). Throws
  /// std::invalid_argument for a capture after the current time, sigma <= 0 or non-finite data.
  UpdateReport update(const Measurement& z) override;
  Estimate estimate() const override;
  EstimatorCounts counts() const override { return {steps_, repropagated_, updates_}; }
  const EstimatorConfig& config() const { return config_; }

  long steps() const { return steps_; }                      ///< propagation steps taken
  long repropagated_steps() const { return repropagated_; }  ///< of which re-propagations
  long updates() const { return updates_; }

 protected:
  /// Advance (x, P) over h (<= 2 ms) from time t with `u` held from t (the input already
  /// advanced to t). Throws std::runtime_error when the belief cannot be carried on.
  virtual void substep(double t, double h, const HandInput& u, Eigen::Vector2d& x,
                       Eigen::Matrix2d& P) const = 0;
  const DiskOnHand& disk() const { return disk_; }

 private:
  /// One propagation step as it was taken: enough to rewind to its start and redo it.
  struct Stored {
    double t0 = 0, t1 = 0;  ///< the step
    HandInput input;        ///< held over the step (angle and rate at t0)
    Eigen::Vector2d x0;     ///< state at t0 (before the step)
    Eigen::Matrix2d P0;
  };
  /// Stored steps, oldest first, in a ring over a vector: it grows (allocates) only until it
  /// holds `history` seconds of steps, then push/pop reuse the slots. A std::deque would allocate
  /// a block every few hundred steps for ever.
  class Ring {
   public:
    std::size_t size() const { return size_; }
    bool empty() const { return size_ == 0; }
    Stored& operator[](std::size_t i) { return slots_[(head_ + i) % slots_.size()]; }
    const Stored& operator[](std::size_t i) const { return slots_[(head_ + i) % slots_.size()]; }
    Stored& front() { return (*this)[0]; }
    Stored& back() { return (*this)[size_ - 1]; }
    void push_back(const Stored& s);
    void pop_front();
    /// Insert before position i (0 <= i <= size), shifting the later entries back by one.
    void insert(std::size_t i, const Stored& s);
    void clear() { head_ = size_ = 0; }

   private:
    std::vector<Stored> slots_;
    std::size_t head_ = 0, size_ = 0;
  };

  /// Advance (x, P) from t0 to t1 with `u` held from t0: substeps of at most 2 ms.
  void step(double t0, double t1, const HandInput& u, Eigen::Vector2d& x, Eigen::Matrix2d& P) const;
  /// Joseph-form update of (x, P) with a measurement of s_h; fills the report's innovation. The
  /// measurement is linear (H = [1 0]), so this is every filter type's update.
  void correct(const Measurement& z, Eigen::Vector2d& x, Eigen::Matrix2d& P,
               UpdateReport& report) const;
  void check_finite(double t, const Eigen::Vector2d& x) const;
  void prune();

  EstimatorConfig config_;  // checked before the model, so a bad field is reported first
  DiskOnHand disk_;
  double t_ = 0;
  Eigen::Vector2d x_ = Eigen::Vector2d::Zero();
  Eigen::Matrix2d P_ = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d P_initial_ = Eigen::Matrix2d::Zero();
  Ring history_;
  long steps_ = 0, repropagated_ = 0, updates_ = 0;
};

}  // namespace flatland::control
