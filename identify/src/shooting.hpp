// The multiple-shooting problem's pieces that do not depend on Ceres: the world's parameters as
// a vector, the recordings cut into segments, and one segment simulated from its initial state
// (docs/IDENTIFY.md, "Method").
#pragma once

#include "flatland/identify/identify.hpp"
#include "flatland/sim/simulate.hpp"

#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace flatland::identify::detail {

/// The fitted parameters' layout: unknowns[j] is the world block's j-th value.
struct Unknown {
  std::string name;
  Bounds bounds;
  double initial = 0;
  /// The size below which the parameter hardly matters, for the difference steps (SI units).
  double typical = 0;
};

/// The world at given values of the unknowns: the contact law, the tilt and the offsets.
struct WorldValues {
  sim::ContactLaw law;
  double tilt = 0;
  double angle_offset = 0, time_offset = 0;
};

/// One shooting segment: samples [first, end) of a recording, simulated from t[first] to t_end
/// (the next segment's start, or its own last sample).
struct Segment {
  std::size_t recording = 0;
  std::size_t first = 0, end = 0;
  double t0 = 0, t_end = 0;
  bool has_next = false;  ///< a continuity condition joins it to the following segment
  double guess_s = 0, guess_sdot = 0;
};

/// What a simulated segment gives: s_h at its samples and the state at t_end.
struct SegmentOutput {
  std::vector<double> s_h;
  double s_end = 0, sdot_end = 0;
  sim::ContactMode end_mode = sim::ContactMode::kRolling;  ///< the contact's mode at t_end
};

class ShootingProblem {
 public:
  /// Checks the options and recordings (std::invalid_argument naming the field) and cuts the
  /// recordings into segments.
  /// The offsets that are not among the unknowns take `angle_offset` and `time_offset`.
  ShootingProblem(const sim::SimulationSpec& world, const std::vector<Recording>& recordings,
                  const IdentifyOptions& options, double angle_offset = 0, double time_offset = 0);

  const std::vector<Unknown>& unknowns() const { return unknowns_; }
  const std::vector<Segment>& segments() const { return segments_; }
  const std::vector<Recording>& recordings() const { return recordings_; }
  /// The continuity residuals' scales for segments of recording r: s_h and sdot_h.
  double continuity_scale_s(std::size_t r) const { return continuity_s_[r]; }
  double continuity_scale_sdot(std::size_t r) const { return continuity_sdot_[r]; }

  /// The world at the unknowns' values `w` (unknowns().size() values; may be null when none).
  WorldValues values(const double* w) const;
  /// Simulate segment k from (s, sdot) at its start with world values `w`. Returns false, with
  /// `why`, when the simulator refuses or fails (the disk dropped, the energy audit broke).
  bool simulate(std::size_t k, double s, double sdot, const double* w, SegmentOutput& out,
                std::string* why = nullptr) const;
  /// Simulate recording `recording` from (s, sdot) at t0 to t_end (default: its last sample):
  /// s_h at each sample in [t0, t_end], and the state at t_end. Returns false, with `why`, when
  /// the run fails or stops early (then s_h holds the samples reached, for the prediction check).
  bool simulate_span(std::size_t recording, double t0, double s, double sdot, const double* w,
                     std::vector<double>& s_h, std::string* why,
                     std::optional<double> t_end = std::nullopt, double* s_end = nullptr,
                     double* sdot_end = nullptr, sim::ContactMode* end_mode = nullptr) const;

  /// a - b for two values of s_h, taken modulo the closed outline's period (the same point of
  /// the outline has s and s + period; a flight's nearest point can come back a period on).
  double s_difference(double a, double b) const {
    return std::isfinite(period_) ? std::remainder(a - b, period_) : a - b;
  }

  long simulations() const { return simulations_.load(); }
  double simulation_time() const { return 1e-9 * static_cast<double>(simulation_ns_.load()); }

 private:
  sim::RunResult run(std::size_t recording, double t0, double t_end, double s, double sdot,
                     const WorldValues& v) const;

  sim::SimulationSpec world_;
  std::shared_ptr<const sim::RollingProblem> base_;
  std::vector<Recording> recordings_;
  std::vector<std::shared_ptr<const JointLogMotion>> joints_;
  std::vector<Unknown> unknowns_;
  std::vector<Segment> segments_;
  std::vector<double> continuity_s_, continuity_sdot_;
  sim::RunOptions run_;
  double angle_offset_ = 0, time_offset_ = 0;
  double period_ = std::numeric_limits<double>::infinity();
  mutable std::atomic<long> simulations_{0};
  mutable std::atomic<long long> simulation_ns_{0};
};

/// Fit the problem's unknowns and segment states with Ceres, and report (identify() without the
/// checks; validate() fits an initial state with it).
IdentifyResult solve(const ShootingProblem& problem, const sim::SimulationSpec& world,
                     const IdentifyOptions& options);

}  // namespace flatland::identify::detail
