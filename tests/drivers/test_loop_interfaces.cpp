// The loop runs any controller and estimator behind control/interfaces.hpp: a wrapped paper
// controller or EKF gives the very run the scene's own choice gives; a controller's stop request,
// exception or non-finite command is handled by the loop as documented.
#include "drivers/loop_support.hpp"
#include "flatland/drivers/experiment.hpp"
#include "flatland/model/model.hpp"
#include "flatland/scene/scene.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>

using namespace flatland;

namespace {

using flatland_test::feedback_scene;

/// What a wrapper saw of the loop.
struct Seen {
  int starts = 0;
  long steps = 0;
  control::ControllerContext context;
  double last_t = -1e9;
  bool times_increase = true;
  long resets = 0, propagations = 0, updates = 0;
};

/// Forwards to a real controller and records the calls; `fault` replaces the output from
/// t >= fault_at on.
class Wrapped final : public control::Controller {
 public:
  enum class Fault { kNone, kStop, kThrow, kNaN };
  Wrapped(std::unique_ptr<control::Controller> inner, Seen& seen, Fault fault = Fault::kNone,
          double fault_at = 0)
      : inner_(std::move(inner)), seen_(seen), fault_(fault), fault_at_(fault_at) {}
  void start(const control::ControllerContext& c) override {
    ++seen_.starts;
    seen_.context = c;
    inner_->start(c);
  }
  control::ControlOutput step(const control::ControlInput& in) override {
    ++seen_.steps;
    seen_.times_increase = seen_.times_increase && in.t > seen_.last_t;
    seen_.last_t = in.t;
    control::ControlOutput out = inner_->step(in);
    if (in.t < fault_at_) return out;
    switch (fault_) {
      case Fault::kNone:
        break;
      case Fault::kStop:
        out.stop = control::StopReason{control::StopCause::kController,
                                       "controller: the test asked to stop"};
        break;
      case Fault::kThrow:
        throw std::runtime_error("the test's controller failed");
      case Fault::kNaN:
        out.theta_ddot = std::numeric_limits<double>::quiet_NaN();
        break;
    }
    return out;
  }
  std::string name() const override { return "wrapped"; }

 private:
  std::unique_ptr<control::Controller> inner_;
  Seen& seen_;
  Fault fault_;
  double fault_at_;
};

class WrappedEstimator final : public control::Estimator {
 public:
  WrappedEstimator(std::unique_ptr<control::Estimator> inner, Seen& seen,
                   double fail_at = std::numeric_limits<double>::infinity())
      : inner_(std::move(inner)), seen_(seen), fail_at_(fail_at) {}
  void reset(double t, double s, double sdot) override {
    ++seen_.resets;
    inner_->reset(t, s, sdot);
  }
  void propagate(double t_next, const control::HandInput& u) override {
    ++seen_.propagations;
    if (t_next >= fail_at_) throw std::runtime_error("the test's estimator diverged");
    inner_->propagate(t_next, u);
  }
  control::UpdateReport update(const control::Measurement& z) override {
    ++seen_.updates;
    return inner_->update(z);
  }
  control::Estimate estimate() const override { return inner_->estimate(); }
  control::EstimatorCounts counts() const override { return inner_->counts(); }
  std::string name() const override { return "wrapped-" + inner_->name(); }

 private:
  std::unique_ptr<control::Estimator> inner_;
  Seen& seen_;
  double fail_at_;
};

drivers::SyntheticResult run_wrapped(
    const Scene& scene, Seen& seen, Wrapped::Fault fault = Wrapped::Fault::kNone,
    double fault_at = 0, double estimator_fails_at = std::numeric_limits<double>::infinity()) {
  const auto model = model::compile(scene);
  const control::ControllerChoice choice = model->controller;
  const control::EstimatorChoice estimator = model->estimator;
  const drivers::LoopSetup setup(
      model,
      [&seen, choice, fault, fault_at] {
        return std::make_unique<Wrapped>(control::make_controller(choice), seen, fault, fault_at);
      },
      [&seen, estimator, estimator_fails_at](std::shared_ptr<const sim::RollingProblem> nominal) {
        return std::make_unique<WrappedEstimator>(control::make_estimator(estimator, nominal), seen,
                                                  estimator_fails_at);
      });
  return drivers::run_synthetic(setup, model);
}

bool same_row(const drivers::TickLog& a, const drivers::TickLog& b) {
  const auto same = [](double x, double y) { return x == y || (std::isnan(x) && std::isnan(y)); };
  return same(a.t, b.t) && same(a.theta, b.theta) && same(a.command, b.command) &&
         a.mode == b.mode && same(a.s_est, b.s_est) && same(a.var_s, b.var_s) &&
         same(a.s_true, b.s_true) && same(a.theta_plan, b.theta_plan) && a.measured == b.measured;
}

}  // namespace

// The scene's own choice and the same laws behind the caller's factories: the same run, bit for
// bit, with every tick passed through the interfaces.
TEST(LoopInterfaces, TheCallersFactoriesRunTheSameLawsIdentically) {
  const Scene scene = feedback_scene();
  const auto model = model::compile(scene);
  const drivers::LoopSetup own(model);
  const drivers::SyntheticResult reference = drivers::run_synthetic(own, model);
  ASSERT_TRUE(reference.success) << reference.failure;
  EXPECT_EQ(reference.loop.controller, "paper");
  EXPECT_EQ(reference.loop.estimator, "ekf");

  Seen seen;
  const drivers::SyntheticResult r = run_wrapped(scene, seen);
  ASSERT_EQ(r.loop.log.size(), reference.loop.log.size());
  for (std::size_t i = 0; i < r.loop.log.size(); ++i)
    ASSERT_TRUE(same_row(r.loop.log[i], reference.loop.log[i])) << "tick " << i;
  EXPECT_TRUE(r.success);
  EXPECT_EQ(r.loop.controller, "wrapped");
  EXPECT_EQ(r.loop.estimator, "wrapped-ekf");
  EXPECT_EQ(r.loop.duration_s, reference.loop.duration_s);
  EXPECT_EQ(r.loop.t_stage2, reference.loop.t_stage2);
  EXPECT_EQ(r.loop.t_stage3, reference.loop.t_stage3);

  // Started once, with the loop's clock and the scene's start; stepped at every tick, in order.
  EXPECT_EQ(seen.starts, 1);
  EXPECT_EQ(seen.steps, static_cast<long>(r.loop.log.size()));
  EXPECT_TRUE(seen.times_increase);
  EXPECT_DOUBLE_EQ(seen.context.dt, 1.0 / scene.joint.rate);
  EXPECT_DOUBLE_EQ(seen.context.t_start, r.loop.log.front().t);
  EXPECT_EQ(seen.context.s_h_start, scene.sim.initial.s_h);
  ASSERT_TRUE(seen.context.plan);
  EXPECT_DOUBLE_EQ(seen.context.plan->duration(), scene.sim.motion.period);
  ASSERT_TRUE(seen.context.model);
  // The estimator: reset once (at the first measurement), every other measurement an update,
  // and propagated over every tick from then on but the last.
  EXPECT_EQ(seen.resets, 1);
  EXPECT_EQ(seen.updates + seen.resets, r.loop.measurements);
  long estimating_ticks = 0;
  for (const drivers::TickLog& row : r.loop.log) estimating_ticks += row.estimating;
  EXPECT_GE(seen.propagations, estimating_ticks - 1);
  EXPECT_LE(seen.propagations, estimating_ticks + 1);
  EXPECT_EQ(r.loop.estimator_updates, seen.updates);

  // The modes, in the order the paper's controller goes through them.
  std::vector<std::string> modes;
  for (const auto& [t, mode] : r.loop.mode_starts) modes.push_back(mode);
  EXPECT_EQ(modes, (std::vector<std::string>{"waiting", "dip", "servo", "finish", "done"}));
}

// A controller's stop request and its exception both end in the loop's safe stop, with the cause
// and the message; the hand comes to rest within the safe stop's deceleration.
TEST(LoopInterfaces, AStopRequestOrAnExceptionStopsSafely) {
  const Scene scene = feedback_scene();
  const double stop_deceleration = scene.controller.stop_deceleration;
  for (const auto fault : {Wrapped::Fault::kStop, Wrapped::Fault::kThrow}) {
    Seen seen;
    const drivers::SyntheticResult r = run_wrapped(scene, seen, fault, 1.0);
    EXPECT_FALSE(r.success);
    ASSERT_TRUE(r.loop.safe_stop);
    ASSERT_TRUE(r.loop.stop_reason);
    EXPECT_EQ(r.loop.stop_reason->cause, control::StopCause::kController);
    EXPECT_NE(r.loop.stop_reason->detail.find(fault == Wrapped::Fault::kStop
                                                  ? "the test asked to stop"
                                                  : "the test's controller failed"),
              std::string::npos)
        << r.loop.stop_reason->detail;
    EXPECT_EQ(r.loop.stop_reason->detail.rfind("controller: ", 0), 0u);
    EXPECT_EQ(r.outcome, drivers::Outcome::kSafeStop);
    // Not asked again after the stop; the rest of the log is the loop's safe stop.
    bool stopping = false;
    long after = 0;
    for (const drivers::TickLog& row : r.loop.log) {
      if (row.t >= 1.0) {
        stopping = stopping || row.mode == "safe-stop";
        if (stopping) {
          EXPECT_EQ(row.mode, "safe-stop");
          EXPECT_LE(std::abs(row.command), stop_deceleration + 1e-12);
          ++after;
        }
      }
    }
    EXPECT_GT(after, 0);
    EXPECT_LE(seen.steps, static_cast<long>(r.loop.log.size()) - after + 1);
    EXPECT_LT(std::abs(r.loop.log.back().theta_dot), 1e-3);
  }
}

// A non-finite command is the caller's bug, not a world's outcome: std::invalid_argument naming
// the controller and the time.
TEST(LoopInterfaces, ANonFiniteCommandIsRefused) {
  Seen seen;
  try {
    run_wrapped(feedback_scene(), seen, Wrapped::Fault::kNaN, 0.5);
    FAIL() << "a NaN command was accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("controller 'wrapped'"), std::string::npos) << what;
    EXPECT_NE(what.find("non-finite"), std::string::npos) << what;
    EXPECT_NE(what.find("t = 0.5"), std::string::npos) << what;
  }
}

// Unknown types name the field and list the known ones (at compile time, before any run).
TEST(LoopInterfaces, UnknownTypesListTheKnownOnes) {
  Scene scene = feedback_scene();
  scene.controller.type = "lqr";
  try {
    model::compile(scene);
    FAIL();
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("controller.type: unknown type 'lqr' (known: paper"), std::string::npos)
        << what;
  }
  scene = feedback_scene();
  scene.estimator.type = "particle";
  try {
    model::compile(scene);
    FAIL();
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("estimator.type: unknown type 'particle' (known: ekf"), std::string::npos)
        << what;
  }
}

// An estimator that fails (its belief non-finite, a user's filter raising) ends the estimation:
// the loop stops safely with cause "estimator" and the message, the run is a safe stop (not a
// numerical failure of the world), and the estimator is not asked again.
TEST(LoopInterfaces, AFailingEstimatorStopsSafely) {
  Seen seen;
  const drivers::SyntheticResult r =
      run_wrapped(feedback_scene(), seen, Wrapped::Fault::kNone, 0, 1.0);
  ASSERT_TRUE(r.loop.safe_stop);
  ASSERT_TRUE(r.loop.stop_reason);
  EXPECT_EQ(r.loop.stop_reason->cause, control::StopCause::kEstimator);
  EXPECT_EQ(r.loop.stop_reason->detail, "estimator: the test's estimator diverged");
  EXPECT_EQ(r.outcome, drivers::Outcome::kSafeStop);
  EXPECT_EQ(seen.resets, 1);
  long estimating_after = 0;
  for (const drivers::TickLog& row : r.loop.log)
    if (row.t >= 1.0) estimating_after += row.estimating;
  EXPECT_EQ(estimating_after, 0);
  EXPECT_LT(std::abs(r.loop.log.back().theta_dot), 1e-3);
}
