// The hybrid model (sim/hybrid.hpp) over many random worlds: random friction, restitution,
// capture velocity and losses, random start states, the hand held still at a random angle or
// running the paper's butterfly with a random period and dip. No run may fail, the forces must
// agree with the contact mode at every recorded step and at every event, a located transition is
// not undone at the same instant, and with the hand held still the energy never increases.
// Plus the slip onset that used to abort a run (a slip start located a rounding error inside the
// friction cone re-stuck at once): the disk slides there, as Coulomb's law says.
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/spec.hpp"

#include "test_scale.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <numbers>
#include <random>
#include <sstream>
#include <string>

using namespace flatland::sim;

namespace {

using flatland_test::kDeg;

/// The i-th random world: even i the hand held still, odd i the butterfly.
SimulationSpec random_world(int i, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  SimulationSpec spec;
  spec.tilt = u(rng) < 0.5 ? 90 * kDeg : (5 + 85 * u(rng)) * kDeg;
  spec.object.radius = 0.051;
  ContactLaw& law = spec.contact;
  law.mu = 0.05 + 0.95 * u(rng);
  law.mu_kinetic = *law.mu * (0.4 + 0.6 * u(rng));
  law.restitution = u(rng) < 0.4 ? 0.0 : 0.9 * u(rng);
  law.capture_velocity = std::pow(10.0, -4 + 2 * u(rng));
  // Below mu_k r, as the model requires, and below half of it: a couple that large (a rolling
  // resistance coefficient delta / r of up to 0.5, where rubber on metal has ~0.001-0.01) can
  // hold the disk's rotation through a slip from rest, which the sliding model approximates by
  // dropping the couple (docs/DYNAMICS.md, "Losses"); the slip then runs against its own
  // direction and no contact mode is consistent.
  law.rolling_resistance =
      u(rng) < 0.5 ? 0.5 * *law.mu_kinetic * spec.object.radius * u(rng) * u(rng) : 0.0;
  law.drag = u(rng) < 0.5 ? 0.2 * u(rng) : 0.0;
  law.drag_angular = u(rng) < 0.5 ? 2e-4 * u(rng) : 0.0;
  if (i % 2 == 0) {
    spec.motion.kind = MotionSpec::Kind::kFixed;
    spec.motion.angle = (u(rng) - 0.5) * 70 * kDeg;  // the palm up, tilted either way
    spec.initial.s_h = -1.6 + 1.2 * u(rng);
    spec.initial.sdot_h = 8 * (u(rng) - 0.5);
    spec.duration = 1.5 + 1.5 * u(rng);
  } else {
    spec.motion.kind = MotionSpec::Kind::kButterfly;
    spec.motion.period = 1.181 * (0.85 + 0.3 * u(rng));
    spec.motion.k = -1.1393 * (0.9 + 0.2 * u(rng));
    spec.initial.t0 = -0.2 * u(rng);
    spec.initial.s_h = -1.3 + 0.6 * u(rng);
    spec.initial.sdot_h = 2 * (u(rng) - 0.5);
    spec.duration = spec.motion.period + 0.5 * u(rng);
  }
  spec.run.model = ContactModel::kHybrid;
  const double tight = u(rng);
  spec.run.integrator.rtol = tight < 0.3 ? 1e-10 : tight < 0.7 ? 1e-11 : 1e-12;
  spec.run.integrator.atol = 1e-2 * spec.run.integrator.rtol;
  if (u(rng) < 0.15) spec.run.integrator.method = Method::kDormandPrince853;
  return spec;
}

std::string describe(const SimulationSpec& s) {
  std::ostringstream os;
  os.precision(17);
  os << (s.motion.kind == MotionSpec::Kind::kFixed ? "fixed angle " : "butterfly period ")
     << (s.motion.kind == MotionSpec::Kind::kFixed ? s.motion.angle : s.motion.period) << " k "
     << s.motion.k << " tilt " << s.tilt << " mu " << *s.contact.mu << " mu_k "
     << *s.contact.mu_kinetic << " e " << s.contact.restitution << " capture "
     << s.contact.capture_velocity << " delta " << s.contact.rolling_resistance << " drag "
     << s.contact.drag << " drag_w " << s.contact.drag_angular << " t0 " << s.initial.t0 << " s_h "
     << s.initial.s_h << " sdot_h " << s.initial.sdot_h << " duration " << *s.duration << " rtol "
     << s.run.integrator.rtol << " method " << to_string(s.run.integrator.method);
  return os.str();
}

double energy(const Sample& s, const SimulationSpec& spec) {
  const double m = spec.object.mass, r = spec.object.radius;
  return 0.5 * m * s.object_velocity.squaredNorm() +
         0.25 * m * r * r * s.object_angular_velocity * s.object_angular_velocity +
         m * spec.effective_gravity() * s.object_position.y();
}

bool in_contact(ContactMode m) { return m != ContactMode::kFlight; }

std::vector<RecordedEvent> events_of_kind(const RunResult& r, EventKind kind) {
  std::vector<RecordedEvent> out;
  for (const RecordedEvent& e : r.events)
    if (e.kind == kind) out.push_back(e);
  return out;
}

struct Tally {
  int slips = 0, sticks = 0, reverses = 0, rests = 0, releases = 0, lift_offs = 0, impacts = 0;
};

/// The forces agree with the contact mode at every recorded step and at every event, and no
/// located transition is undone at the same instant.
void check_consistent(const RunResult& r, const SimulationSpec& spec, Tally& tally) {
  // At the motion's breakpoints the hand's acceleration and so the forces jump: the segment that
  // reaches one records the forces after the jump in its own mode, and the mode changes there.
  const std::shared_ptr<const RollingProblem> pb = build_problem(spec);
  const std::vector<double> jumps = pb->motion->breakpoints();
  const auto at_jump = [&](double t) {
    return std::find(jumps.begin(), jumps.end(), t) != jumps.end();
  };
  const double weight = spec.object.mass * spec.effective_gravity();
  // The guards' own boundary tolerance: a value within it is on the boundary (a located event
  // sits within about time_tolerance x the guard's rate of it, far less).
  const double tol_f = 1e-9 * weight, tol_v = 1e-9;
  const double mu = *spec.contact.mu, mu_k = *spec.contact.mu_kinetic;
  const double delta = spec.contact.rolling_resistance, radius = spec.object.radius;
  for (const Sample& s : r.steps) {
    SCOPED_TRACE("t = " + std::to_string(s.t) + " s, mode " + to_string(s.mode));
    if (!in_contact(s.mode) || at_jump(s.t)) continue;
    ASSERT_GE(s.force_normal, -tol_f);
    switch (s.mode) {
      case ContactMode::kRolling:
        ASSERT_LE(std::abs(s.force_tangential), mu * s.force_normal + tol_f);
        break;
      case ContactMode::kRest:
        ASSERT_LE(std::abs(s.force_tangential), mu * s.force_normal + tol_f);
        ASSERT_LE(std::abs(s.rolling_couple), delta * s.force_normal + tol_f * radius);
        break;
      case ContactMode::kSliding:
        // Coulomb: mu_k f_n, against the slip.
        ASSERT_NEAR(std::abs(s.force_tangential), mu_k * s.force_normal, 1e-9 * weight);
        if (std::abs(s.slip_velocity) > tol_v) {
          ASSERT_LE(s.force_tangential * (s.slip_velocity > 0 ? 1 : -1), tol_f)
              << "f_n " << s.force_normal << " slip " << s.slip_velocity;
        }
        break;
      case ContactMode::kFlight:
        break;
    }
  }
  // Whether a sample recorded at exactly time t in `mode` says `ok`, or none was recorded there
  // (a segment's last step and the next one's start share the event's time; at a jump of the
  // forces both sides of it are recorded in the same mode).
  const auto any_at = [&](double t, ContactMode mode, const auto& ok) {
    bool seen = false;
    for (const Sample& s : r.steps) {
      if (s.t != t || s.mode != mode) continue;
      if (ok(s)) return true;
      seen = true;
    }
    return !seen;
  };
  double t_prev = -std::numeric_limits<double>::infinity();
  EventKind k_prev = EventKind::kJunction;
  for (const RecordedEvent& e : r.events) {
    SCOPED_TRACE("event " + to_string(e.kind) + " at t = " + std::to_string(e.t));
    if (e.kind == EventKind::kJunction || e.kind == EventKind::kApex) continue;
    ASSERT_GE(e.t, t_prev);  // in time order
    const bool same_instant = e.t == t_prev;
    switch (e.kind) {
      case EventKind::kSlipStart: {
        ++tally.slips;
        // Rolling or at rest, the friction needed has reached the cone. Where the rolling has
        // just stopped and the rolling-resistance couple could not hold the disk, it rolls back
        // the way the couple turns it, and the couple turns too: that rolling's friction, not
        // recorded, is the one that reached the cone.
        bool recorded = false, reached = false;
        for (const Sample& s : r.steps) {
          if (s.t != e.t || (s.mode != ContactMode::kRolling && s.mode != ContactMode::kRest))
            continue;
          recorded = true;
          if (std::abs(s.force_tangential) >= mu * s.force_normal - tol_f) reached = true;
          if (s.mode == ContactMode::kRolling && std::abs(s.sdot_h) <= tol_v && delta > 0) {
            HybridState x;
            x.t = s.t;
            x.mode = ContactMode::kRest;
            x.s_h = s.s_h;
            x.angle = s.object_angle;
            x.hand_piece = pb->hand->piece_at(s.s_h, +1);
            const Sample rest = sample_state(pb, x);
            x.mode = ContactMode::kRolling;
            x.sign = pb->hand->normal_side() * (rest.rolling_couple > 0 ? 1 : -1);
            x.hand_piece = pb->hand->piece_at(s.s_h, x.sign);
            const Sample back = sample_state(pb, x);
            if (std::abs(back.force_tangential) >= mu * back.force_normal - tol_f) reached = true;
          }
        }
        // (Not recorded: the instant's checks right after an impact.)
        EXPECT_TRUE(reached || !recorded);
        break;
      }
      case EventKind::kStick:
        ++tally.sticks;
        // Not a slip undone at the instant it started (at a jump of the forces, the instant's
        // checks may go through sliding to find the rolling that holds: not a located slip).
        EXPECT_FALSE(same_instant && k_prev == EventKind::kSlipStart && !at_jump(e.t));
        EXPECT_TRUE(any_at(e.t, ContactMode::kSliding,
                           [&](const Sample& s) { return std::abs(s.slip_velocity) <= tol_v; }));
        EXPECT_TRUE(any_at(e.t, ContactMode::kRolling, [&](const Sample& s) {
          return std::abs(s.force_tangential) <= mu * s.force_normal + tol_f;
        }));
        break;
      case EventKind::kSlipReverse:
        ++tally.reverses;
        break;
      case EventKind::kRest:
        ++tally.rests;
        EXPECT_FALSE(same_instant && k_prev == EventKind::kRelease && !at_jump(e.t));
        EXPECT_TRUE(any_at(e.t, ContactMode::kRest, [&](const Sample& s) {
          return std::abs(s.rolling_couple) <= delta * s.force_normal + tol_f * radius;
        }));
        break;
      case EventKind::kRelease:
        ++tally.releases;
        EXPECT_FALSE(same_instant && k_prev == EventKind::kRest && !at_jump(e.t));
        EXPECT_TRUE(any_at(e.t, ContactMode::kRest, [&](const Sample& s) {
          return std::abs(s.rolling_couple) >= delta * s.force_normal - tol_f * radius;
        }));
        break;
      case EventKind::kLiftOff:
        ++tally.lift_offs;
        for (ContactMode m : {ContactMode::kRolling, ContactMode::kRest, ContactMode::kSliding})
          EXPECT_TRUE(any_at(e.t, m, [&](const Sample& s) { return s.force_normal <= tol_f; }));
        break;
      case EventKind::kImpact:
        ++tally.impacts;
        break;
      default:
        break;
    }
    t_prev = e.t;
    k_prev = e.kind;
  }
}

}  // namespace

// Random worlds, half with the hand held still, half on the butterfly: none fails, every one is
// consistent with its forces and keeps its energy balance. With the hand held still no energy comes in: the disk's
// mechanical energy never increases (the hand does no work; sliding, impacts and the losses only
// take energy away).
TEST(HybridWorlds, RandomWorldsRunAndAgreeWithTheirForces) {
  std::mt19937_64 rng(20260611);
  const int worlds = flatland::test::short_tests() ? 60 : 500;
  int failed = 0;
  Tally tally;
  for (int i = 0; i < worlds; ++i) {
    const SimulationSpec spec = random_world(i, rng);
    SCOPED_TRACE("world " + std::to_string(i) + ": " + describe(spec));
    RunResult r;
    try {
      r = run_spec(spec);
    } catch (const std::exception& e) {
      ++failed;
      ADD_FAILURE() << e.what();
      continue;
    }
    check_consistent(r, spec, tally);
    // Every energy balance holds (sim/energy.hpp): no run is a numerical failure, the losses and
    // impacts only take energy, and a hand held still does no work at all.
    EXPECT_NE(r.reason, StopReason::kNumericalFailure);
    EXPECT_FALSE(r.audit.broken);
    EXPECT_LE(std::abs(r.audit.balance), r.audit.bound());
    EXPECT_LE(r.audit.work_losses, 0.0);
    EXPECT_LE(r.audit.impact_losses, 0.0);
    if (spec.motion.kind == MotionSpec::Kind::kFixed) {
      EXPECT_EQ(r.audit.work_hand, 0.0);
      const double scale = spec.object.mass * spec.effective_gravity() * 0.3;
      for (std::size_t k = 1; k < r.steps.size(); ++k) {
        const double gain = energy(r.steps[k], spec) - energy(r.steps[k - 1], spec);
        ASSERT_LE(gain, 1e-8 * scale)
            << "at t = " << r.steps[k].t << " s, mode " << to_string(r.steps[k].mode);
      }
      for (const RecordedEvent& e : r.events)
        if (e.kind == EventKind::kImpact) {
          EXPECT_LE(e.energy_change, 1e-12 * scale);
        }
    }
  }
  EXPECT_EQ(failed, 0) << "of " << worlds << " worlds";
  // The worlds went through every kind of transition.
  EXPECT_GT(tally.slips, 0);
  EXPECT_GT(tally.sticks, 0);
  EXPECT_GT(tally.reverses, 0);
  EXPECT_GT(tally.rests, 0);
  EXPECT_GT(tally.releases, 0);
  EXPECT_GT(tally.lift_offs, 0);
  EXPECT_GT(tally.impacts, 0);
  std::cout << "[          ] " << worlds << " worlds, " << failed << " failed; " << tally.slips
            << " slips, " << tally.sticks << " sticks, " << tally.reverses << " reversals, "
            << tally.rests << " rests, " << tally.releases << " releases, " << tally.lift_offs
            << " lift-offs, " << tally.impacts << " impacts\n";
}

namespace {

/// The reported world whose slip onset aborted the run ("keeps changing mode without time
/// advancing"): the hand held still 5.6 degrees from palm up, the disk rolling fast across the
/// palm until the friction it needs reaches mu.
SimulationSpec reported_world() {
  SimulationSpec spec;
  spec.motion.kind = MotionSpec::Kind::kFixed;
  spec.motion.angle = 5.600648559784744 * kDeg;
  spec.object.radius = 0.051;
  spec.initial.s_h = -1.2149473820291945;
  spec.initial.sdot_h = 3.841581281774104;
  spec.duration = 2.9783974432314877;
  spec.run.model = ContactModel::kHybrid;
  spec.run.integrator.rtol = 1e-11;
  spec.run.integrator.atol = 1e-13;
  spec.run.events.time_tolerance = 1e-12;
  spec.contact.mu = 0.561896211712412;
  spec.contact.mu_kinetic = 0.36480699334758493;
  spec.contact.restitution = 0.0;
  spec.contact.capture_velocity = 1e-3;
  return spec;
}

}  // namespace

// It slides from where rolling needs mu, as Coulomb's law says: while it slides the friction is
// mu_k f_n against the slip, and its moment about the centre is the disk's only torque (no losses),
// I |omega'| = r mu_k f_n; it leaves the hand over the fingertip and falls away.
TEST(HybridWorlds, ReportedSlipOnsetSlidesByCoulomb) {
  const SimulationSpec spec = reported_world();
  RunResult r;
  ASSERT_NO_THROW(r = run_spec(spec));
  const double mu = *spec.contact.mu, mu_k = *spec.contact.mu_kinetic, radius = 0.051;
  const double weight = spec.object.mass * spec.effective_gravity();
  const double inertia = 0.5 * spec.object.mass * radius * radius;
  std::vector<RecordedEvent> modes;
  for (const RecordedEvent& e : r.events)
    if (e.kind != EventKind::kJunction && e.kind != EventKind::kApex) modes.push_back(e);
  ASSERT_GE(modes.size(), 2u);
  // Rolling until the friction it needs reaches the cone, then sliding.
  const RecordedEvent& slip = modes[0];
  ASSERT_EQ(slip.kind, EventKind::kSlipStart);
  int on_cone = 0;
  for (const Sample& s : r.steps) {
    if (s.t < slip.t) {
      ASSERT_EQ(s.mode, ContactMode::kRolling);
      ASSERT_LE(std::abs(s.force_tangential), mu * s.force_normal + 1e-9 * weight);
    } else if (s.t == slip.t && s.mode == ContactMode::kRolling) {
      EXPECT_NEAR(std::abs(s.force_tangential), mu * s.force_normal, 1e-9 * weight);
      ++on_cone;
    }
  }
  EXPECT_EQ(on_cone, 1);
  EXPECT_GT(modes[1].t, slip.t);  // not undone at the instant it started
  int sliding = 0;
  for (const Sample& s : r.steps) {
    if (s.mode != ContactMode::kSliding) continue;
    ++sliding;
    EXPECT_NEAR(std::abs(s.force_tangential), mu_k * s.force_normal, 1e-9 * weight);
    EXPECT_NEAR(inertia * std::abs(s.object_angular_acceleration), radius * mu_k * s.force_normal,
                1e-9 * weight * radius);
    if (std::abs(s.slip_velocity) > 1e-9) {
      EXPECT_LE(s.force_tangential * (s.slip_velocity > 0 ? 1 : -1), 1e-9 * weight);
    }
  }
  EXPECT_GT(sliding, 1);
  EXPECT_GT(r.stats.mode_time[static_cast<int>(ContactMode::kSliding)], 0.0);
  EXPECT_EQ(r.trajectory.sample(slip.t + 1e-6).mode, ContactMode::kSliding);
  // It leaves the hand: lifts off, and flies out of its reach.
  EXPECT_FALSE(events_of_kind(r, EventKind::kLiftOff).empty());
  EXPECT_EQ(r.reason, StopReason::kDropped);
}

// The same onset where the closed forms hold: a disk rolling from rest down a straight incline of
// angle alpha, slowed by an angular drag c_w (the palm's curvature is replaced by a line, the
// hand's spin by the drag: the friction it needs then grows over time, as on the palm). Rolling,
// (m + I / r^2) v' = m g sin(alpha) - c_w v / r^2, so v = v_inf (1 - e^(-t / tau)) with
// v_inf = m g sin(alpha) r^2 / c_w, tau = (m + I / r^2) r^2 / c_w, and the friction it needs,
// m g sin(alpha) - m v' = m g sin(alpha) (1 - m / (m + I / r^2) e^(-t / tau)), reaches
// mu m g cos(alpha) at t* = tau ln((2/3) / (1 - mu cot(alpha))) for a uniform disk.
// Sliding from there, the centre accelerates at g (sin(alpha) - mu_k cos(alpha)), the drag does not
// act on it, and the spin follows I omega' = mu_k m g cos(alpha) r - c_w omega. A slow onset, and
// a fast one (18 ms) whose located slip start the stick test used to undo (the run aborted).
TEST(HybridWorlds, GradualSlipOnsetOnAnInclineFollowsTheClosedForms) {
  struct Case {
    double alpha, mu, c_w, t_end;
  };
  for (const Case c : {Case{0.3, 0.2, 0.0075, 0.8}, Case{0.5, 0.35, 0.12772595859193503, 0.3}}) {
    SCOPED_TRACE(c.alpha);
    const double alpha = c.alpha, mu = c.mu, mu_k = 0.15, c_w = c.c_w, m = 1.0, r = 0.05, g = 9.8;
    const double inertia = 0.5 * m * r * r;
    auto pb = std::make_shared<RollingProblem>();
    pb->hand = std::make_shared<LineCurve>(Vec2::Zero(), Vec2(std::cos(alpha), -std::sin(alpha)));
    pb->object = make_uniform_disk(r, m);
    pb->motion = std::make_shared<FixedHand>(0.0);
    pb->gravity = g;
    pb->contact.mu = mu;
    pb->contact.mu_kinetic = mu_k;
    pb->contact.drag_angular = c_w;
    RunOptions o;
    o.t_end = c.t_end;
    o.model = ContactModel::kHybrid;
    o.integrator.rtol = 1e-12;
    o.integrator.atol = 1e-14;
    InitialContact start;
    start.s_h = 0;
    RunResult run;
    ASSERT_NO_THROW(run = simulate(pb, start, o));

    const double tau = (m + inertia / (r * r)) * r * r / c_w;
    const double v_inf = m * g * std::sin(alpha) * r * r / c_w;
    const double t_slip = tau * std::log((2.0 / 3.0) / (1 - mu / std::tan(alpha)));
    ASSERT_LT(t_slip, 0.5 * o.t_end);
    const auto slips = events_of_kind(run, EventKind::kSlipStart);
    ASSERT_EQ(slips.size(), 1u);
    EXPECT_NEAR(slips[0].t / t_slip - 1, 0, 1e-8);
    EXPECT_TRUE(events_of_kind(run, EventKind::kStick).empty());
    // Rolling before: s = v_inf (t - tau (1 - e^(-t / tau))).
    const auto s_rolling = [&](double t) { return v_inf * (t - tau * (1 - std::exp(-t / tau))); };
    const Sample before = run.trajectory.sample(0.5 * t_slip);
    EXPECT_EQ(before.mode, ContactMode::kRolling);
    EXPECT_NEAR(before.s_h / s_rolling(0.5 * t_slip) - 1, 0, 1e-8);
    // Sliding after.
    const double s0 = s_rolling(t_slip), v0 = v_inf * (1 - std::exp(-t_slip / tau));
    const double a = g * (std::sin(alpha) - mu_k * std::cos(alpha));
    const double k = c_w / inertia, w_inf = mu_k * m * g * std::cos(alpha) * r / c_w;
    for (double t : {1.2 * t_slip, 0.5 * (t_slip + o.t_end), o.t_end}) {
      SCOPED_TRACE(t);
      const Sample s = run.trajectory.sample(t);
      ASSERT_EQ(s.mode, ContactMode::kSliding);
      const double dt = t - t_slip;
      EXPECT_NEAR(s.s_h / (s0 + v0 * dt + 0.5 * a * dt * dt) - 1, 0, 1e-8);  // arc length
      EXPECT_NEAR(s.sdot_h / (v0 + a * dt) - 1, 0, 1e-8);
      // Rolling downhill turns the disk clockwise (negative).
      const double w = w_inf + (v0 / r - w_inf) * std::exp(-k * dt);
      EXPECT_NEAR(-s.object_angular_velocity / w - 1, 0, 1e-8);
    }
  }
}
