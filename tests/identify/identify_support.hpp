// Synthetic recordings for identify's tests and benchmark: the air-table world (5 degrees, the
// paper's hand, the 5.1 cm disk) run by the simulator from a joint log, sampled like a camera,
// with Gaussian noise of the tracker's measured size.
#pragma once

#include "flatland/identify/identify.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/spec.hpp"

#include <cmath>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

namespace flatland_test {

/// The tracker's error in s_h, measured on rendered frames of the air-table experiment (noise
/// 2 DN, exposure blur; docs/VISION.md, "Mapping pixel -> s_h": RMS 4e-5). A recording's sigma.
constexpr double kTrackerSigmaSh = 4e-5;

/// The truth of the synthetic world of identify's tests besides the scene's friction (mu = 0.8):
/// the scene's kinetic friction, a restitution that bounces, and losses large enough that 4 s of
/// rocking show them (the scene's own, drag 0.015 N s/m and 5e-5 m, damp the rocking over
/// minutes).
constexpr double kMuKinetic = 0.6, kRestitution = 0.4, kRollingResistance = 2e-4, kDrag = 0.1;

/// The air-table world of assets/scenes/airtable-5deg.yaml with the given losses (hybrid model).
inline flatland::sim::SimulationSpec air_table_world(double mu, double mu_kinetic,
                                                     double restitution, double rolling_resistance,
                                                     double drag) {
  flatland::sim::SimulationSpec w;
  w.tilt = 5.0 * std::numbers::pi / 180.0;
  w.run.model = flatland::sim::ContactModel::kHybrid;
  w.contact.mu = mu;
  w.contact.mu_kinetic = mu_kinetic;
  w.contact.restitution = restitution;
  w.contact.rolling_resistance = rolling_resistance;
  w.contact.drag = drag;
  w.contact.drag_angular = drag * 0.051 * 0.051 / 2;
  return w;
}

/// A joint's log: the hand angle every `dt` over [t0, t1] of a function of time.
struct JointLog {
  std::vector<double> t, theta;
};
template <class AngleOf>
JointLog joint_log(double t0, double t1, double dt, AngleOf angle_of) {
  JointLog log;
  const int n = static_cast<int>(std::ceil((t1 - t0) / dt));
  for (int i = 0; i <= n; ++i) {
    const double t = t0 + i * dt;
    log.t.push_back(t);
    log.theta.push_back(angle_of(t));
  }
  return log;
}

/// A hand held still palm up, logged at 1 kHz over [-0.5, t_end + 0.5].
inline JointLog still_hand(double t_end) {
  return joint_log(-0.5, t_end + 0.5, 1e-3, [](double) { return 0.0; });
}

/// The paper's butterfly motion (period 2T, dip k), logged at 1 kHz over [-0.5, t_end + 0.5].
inline JointLog butterfly_hand(double period, double k, double t_end) {
  const flatland::sim::ButterflyMotion m(period, k);
  return joint_log(-0.5, t_end + 0.5, 1e-3, [&](double t) { return m.at(t).angle; });
}

/// The world's run from (s0, sdot0) at t = 0, driven by the log's spline (what identify
/// simulates), sampled at `rate` Hz over [0, t_end], with N(0, sigma) noise unless rng is null.
inline flatland::identify::Recording record(const std::string& name,
                                            const flatland::sim::SimulationSpec& world,
                                            const JointLog& log, double s0, double sdot0,
                                            double t_end, double rate, double sigma,
                                            std::mt19937_64* rng) {
  using namespace flatland;
  auto pb = std::make_shared<sim::RollingProblem>(*sim::build_problem(world));
  pb->motion = std::make_shared<identify::JointLogMotion>(log.t, log.theta);
  sim::RunOptions o = sim::run_options(world);
  o.model = sim::ContactModel::kHybrid;
  o.t_end = t_end;
  o.integrator.rtol = 1e-12;
  o.integrator.atol = 1e-14;
  o.integrator.energy_tolerance = 1e-7;  // the balance's bound at the fit's rtol of 1e-10
  sim::InitialContact init;
  init.s_h = s0;
  init.sdot_h = sdot0;
  const sim::RunResult run = sim::simulate(pb, init, o);
  if (run.reason != sim::StopReason::kEndTime)
    throw std::runtime_error(name + ": the synthetic run stopped: " + sim::to_string(run.reason));
  identify::Recording r;
  r.name = name;
  std::normal_distribution<double> noise(0.0, sigma);
  const int n = static_cast<int>(std::floor(t_end * rate + 1e-9));
  for (int i = 0; i <= n; ++i) {
    const double t = i / rate;
    r.t.push_back(t);
    r.s_h.push_back(run.trajectory.s_h(t) + (rng ? noise(*rng) : 0.0));
    r.sigma.push_back(sigma);
  }
  r.joint_t = log.t;
  r.joint_theta = log.theta;
  return r;
}

}  // namespace flatland_test
