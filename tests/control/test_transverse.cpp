// The transverse-linearisation controller (control/transverse.hpp) on the paper's air-table plan:
// its closed-form partials and its transverse linearisation against central finite differences of
// the simulator's own rolling dynamics (sim::ReducedDiskRolling) and of the definition of the
// transverse coordinates; the Riccati solution (symmetric, positive definite, and a solution of
// the Riccati equation by finite differences of its own grid); the linear closed loop's decay;
// the bad config fields.
#include "flatland/control/transverse.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>

using namespace flatland;
using control::OrbitPoint;
using control::TransverseConfig;
using control::TransverseController;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

// The paper's air-table butterfly as the loop plans it (assets/scenes/airtable-feedback.yaml):
// tilt 5 deg, 2T = 4 s, k = -1.1393, the rolling model without losses.
sim::SimulationSpec air_table_plan() {
  sim::SimulationSpec spec;
  spec.tilt = 5.0 * kDeg;
  spec.motion.period = 4.0;
  spec.motion.k = -1.1393;
  spec.duration = 4.0;
  spec.run.record = true;
  spec.run.events.stop_on_contact_loss = false;
  spec.run.events.stop_on_slip = false;
  return sim::paper_model(spec);
}

struct PlanFixture {
  std::shared_ptr<const sim::RollingProblem> model;
  std::shared_ptr<const control::Plan> plan;
};

const PlanFixture& fixture() {
  static const PlanFixture f = [] {
    const sim::SimulationSpec spec = air_table_plan();
    PlanFixture out;
    out.model = sim::build_problem(spec);
    const sim::RunResult run = sim::run_spec(spec);
    auto motion = std::make_shared<sim::ButterflyMotion>(spec.motion.period, spec.motion.k);
    out.plan = std::make_shared<control::Plan>(motion, spec.motion.period, run, -0.9, 0.9);
    return out;
  }();
  return f;
}

control::ControllerContext context() {
  control::ControllerContext c;
  c.plan = fixture().plan;
  c.model = fixture().model;
  c.dt = 1e-3;
  c.t_start = -0.25;
  c.s_h_start = -1.0;
  return c;
}

std::unique_ptr<TransverseController> started(TransverseConfig config = {}) {
  auto c = std::make_unique<TransverseController>(config, control::PaperConfig{});
  c->start(context());
  return c;
}

/// sddot_h by the simulator's reduced rolling dynamics, the pivot fixed.
double simulated_sddot(const sim::ReducedDiskRolling& rolling, const sim::RollingProblem& model,
                       double theta, double theta_dot, double u, double s, double sdot) {
  sim::HandKinematics h;
  h.angle = theta;
  h.angular_velocity = theta_dot;
  h.angular_acceleration = u;
  return rolling.acceleration(h, s, sdot, model.hand->piece_at(s, +1));
}

}  // namespace

// The closed-form sddot_h and its partials against the simulator's equation and its central
// differences, at orbit points across the servo stretch and at states off the orbit.
TEST(Transverse, RollingPartialsMatchTheSimulatorsDynamics) {
  const auto ctrl = started();
  const sim::RollingProblem& model = *fixture().model;
  const sim::ReducedDiskRolling rolling(fixture().model);
  const double t0 = ctrl->gains().front().tau, t1 = ctrl->gains().back().tau;
  for (int i = 0; i <= 20; ++i) {
    const OrbitPoint p = ctrl->orbit(t0 + (t1 - t0) * i / 20.0);
    for (const double offset : {0.0, 0.03}) {
      const double th = p.theta + offset, thd = p.theta_dot - 2 * offset,
                   u = p.theta_ddot + 10 * offset;
      const double s = p.s_h, sd = p.sdot_h + offset;
      SCOPED_TRACE("tau " + std::to_string(p.tau) + ", offset " + std::to_string(offset));
      const auto f = [&](double a, double b, double c, double e) {
        return simulated_sddot(rolling, model, a, b, c, s, e);
      };
      const control::RollingPartials got = control::rolling_partials(model, th, thd, u, s, sd);
      const double f0 = f(th, thd, u, sd);
      EXPECT_NEAR(got.f, f0, 1e-12 * (1 + std::abs(f0)));
      constexpr double h = 1e-5;
      const double d_theta = (f(th + h, thd, u, sd) - f(th - h, thd, u, sd)) / (2 * h);
      const double d_theta_dot = (f(th, thd + h, u, sd) - f(th, thd - h, u, sd)) / (2 * h);
      const double d_u = (f(th, thd, u + h, sd) - f(th, thd, u - h, sd)) / (2 * h);
      const double d_sdot = (f(th, thd, u, sd + h) - f(th, thd, u, sd - h)) / (2 * h);
      EXPECT_NEAR(got.d_theta, d_theta, 1e-7 * (1 + std::abs(d_theta)));
      EXPECT_NEAR(got.d_theta_dot, d_theta_dot, 1e-7 * (1 + std::abs(d_theta_dot)));
      EXPECT_NEAR(got.d_u, d_u, 1e-7 * (1 + std::abs(d_u)));
      EXPECT_NEAR(got.d_sdot, d_sdot, 1e-7 * (1 + std::abs(d_sdot)));
    }
  }
}

// The transverse linearisation against central differences of the transverse error's rate,
// computed from its definition: the state (theta* + e1, theta_dot* + e2, s*(tau), sdot* + e3)
// moves by the simulator's dynamics, its projection tau advances at sdot_h / sdot_h*(tau), and
// e' = x' (less s_h) - (theta_dot*, u*, sddot*) tau' with sddot* the simulator's on the orbit.
TEST(Transverse, LinearisationMatchesFiniteDifferencesOfTheSimulator) {
  const auto ctrl = started();
  const sim::RollingProblem& model = *fixture().model;
  const sim::ReducedDiskRolling rolling(fixture().model);
  const double t0 = ctrl->gains().front().tau, t1 = ctrl->gains().back().tau;
  for (int i = 0; i <= 12; ++i) {
    const OrbitPoint p = ctrl->orbit(t0 + (t1 - t0) * i / 12.0);
    SCOPED_TRACE("tau " + std::to_string(p.tau) + ", s_h " + std::to_string(p.s_h));
    const double sddot_star =
        simulated_sddot(rolling, model, p.theta, p.theta_dot, p.theta_ddot, p.s_h, p.sdot_h);
    const auto rate = [&](const Eigen::Vector3d& e, double v) {
      const double th = p.theta + e[0], thd = p.theta_dot + e[1], sd = p.sdot_h + e[2];
      const double u = p.theta_ddot + v;
      const double tau_rate = sd / p.sdot_h;
      const double sdd = simulated_sddot(rolling, model, th, thd, u, p.s_h, sd);
      return Eigen::Vector3d(thd - p.theta_dot * tau_rate, u - p.theta_ddot * tau_rate,
                             sdd - sddot_star * tau_rate);
    };
    EXPECT_LT(rate(Eigen::Vector3d::Zero(), 0).norm(), 1e-9);  // the orbit is an equilibrium
    const control::TransverseSystem sys = control::transverse_linearisation(model, p);
    constexpr double h = 1e-6;
    for (int j = 0; j < 3; ++j) {
      const Eigen::Vector3d d = h * Eigen::Vector3d::Unit(j);
      const Eigen::Vector3d column = (rate(d, 0) - rate(-d, 0)) / (2 * h);
      for (int k = 0; k < 3; ++k)
        EXPECT_NEAR(sys.A(k, j), column[k], 1e-6 * (1 + std::abs(column[k])))
            << "A(" << k << ", " << j << ")";
    }
    const Eigen::Vector3d b =
        (rate(Eigen::Vector3d::Zero(), h) - rate(Eigen::Vector3d::Zero(), -h)) / (2 * h);
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(sys.B[k], b[k], 1e-6 * (1 + std::abs(b[k]))) << "B(" << k << ")";
  }
}

// The orbit the controller linearises about is the plan's: its sdot_h and sddot_h are the rates
// of its s_h and sdot_h (central differences over 2 ms of the plan's own tables).
TEST(Transverse, OrbitIsThePlansRollingMotion) {
  const auto ctrl = started();
  const control::Plan& plan = *fixture().plan;
  const double t0 = ctrl->gains().front().tau, t1 = ctrl->gains().back().tau;
  EXPECT_NEAR(ctrl->orbit(t0).s_h, -0.9, 1e-9);
  EXPECT_NEAR(ctrl->orbit(t1).s_h, 0.9, 1e-9);
  constexpr double h = 1e-3;
  for (int i = 1; i < 10; ++i) {
    const double tau = t0 + (t1 - t0) * i / 10.0;
    const OrbitPoint p = ctrl->orbit(tau);
    EXPECT_GT(p.sdot_h, 0);
    EXPECT_NEAR(p.sdot_h, (plan.s_h_at(tau + h) - plan.s_h_at(tau - h)) / (2 * h),
                1e-4 * std::abs(p.sdot_h));
    const double sddot_fd = (plan.sdot_h_at(tau + h) - plan.sdot_h_at(tau - h)) / (2 * h);
    EXPECT_NEAR(p.sddot_h, sddot_fd, 2e-3 * (1 + std::abs(sddot_fd)));
  }
}

// P(tau) is symmetric and positive definite at every grid point, and it solves the Riccati
// equation: its central difference between grid points matches the equation's right-hand side
// at the midpoint (to the grid's O(h^2)).
TEST(Transverse, RiccatiSolutionIsSymmetricPositiveDefiniteAndSolvesTheEquation) {
  TransverseConfig config;
  config.grid_step = 5e-4;  // the central difference's O(h^2) well below the bound
  const auto ctrl = started(config);
  const auto& gains = ctrl->gains();
  ASSERT_GT(gains.size(), 4000u);  // ~2.3 s of plan time at 0.5 ms
  const Eigen::Matrix3d Q = Eigen::Vector3d(config.q[0], config.q[1], config.q[2]).asDiagonal();
  // The residual of each grid interval, and the largest rate of P along the orbit as its scale
  // (P' passes through zero where the gains change sign, so a pointwise relative residual would
  // divide by nothing there).
  double worst_residual = 0, largest_rate = 0;
  for (std::size_t i = 0; i < gains.size(); ++i) {
    const Eigen::Matrix3d& P = gains[i].P;
    ASSERT_TRUE(P.allFinite());
    EXPECT_LE((P - P.transpose()).norm(), 1e-12 * P.norm()) << "at " << i;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(P);
    EXPECT_GT(eig.eigenvalues().minCoeff(), 0) << "at " << i;
    const control::TransverseSystem sys =
        control::transverse_linearisation(*fixture().model, ctrl->orbit(gains[i].tau));
    const Eigen::RowVector3d K = sys.B.transpose() * P / config.r;
    EXPECT_LE((K - gains[i].K).norm(), 1e-11 * K.norm());
    if (i + 1 < gains.size()) {
      const double h = gains[i + 1].tau - gains[i].tau;
      const Eigen::Matrix3d Pm = 0.5 * (P + gains[i + 1].P);
      const control::TransverseSystem mid =
          control::transverse_linearisation(*fixture().model, ctrl->orbit(gains[i].tau + h / 2));
      const Eigen::Matrix3d rhs = -(mid.A.transpose() * Pm + Pm * mid.A -
                                    Pm * mid.B * mid.B.transpose() * Pm / config.r + Q);
      const Eigen::Matrix3d dP = (gains[i + 1].P - P) / h;
      worst_residual = std::max(worst_residual, (dP - rhs).norm());
      largest_rate = std::max(largest_rate, rhs.norm());
    }
  }
  worst_residual /= largest_rate;
  EXPECT_LT(worst_residual, 1e-4);
  std::fprintf(stderr, "[ transverse ] Riccati residual (relative) at most %.2e over %zu points\n",
               worst_residual, gains.size());
}

// The linear transverse system under its LQR, e' = (A - B K) e, integrated along the orbit from a
// sizeable error: the cost-to-go e^T P e falls at every step (dV/dtau = -e^T (Q + K^T R K) e) and
// the error decays by an order of magnitude over the stretch; without feedback it grows.
TEST(Transverse, LinearClosedLoopTransverseErrorDecays) {
  const auto ctrl = started();
  const auto& gains = ctrl->gains();
  const sim::RollingProblem& model = *fixture().model;
  const auto simulate = [&](bool feedback, bool& monotone) {
    Eigen::Vector3d e(0.02, 0.1, 0.05);
    monotone = true;
    double v_prev = e.dot(gains.front().P * e);
    for (std::size_t i = 0; i + 1 < gains.size(); ++i) {
      const double tau = gains[i].tau, h = gains[i + 1].tau - tau;
      const auto f = [&](double at, const Eigen::Vector3d& x) {
        const control::TransverseSystem sys =
            control::transverse_linearisation(model, ctrl->orbit(at));
        const Eigen::Matrix3d M =
            feedback ? Eigen::Matrix3d(sys.A - sys.B * ctrl->gain(at)) : sys.A;
        return Eigen::Vector3d(M * x);
      };
      const Eigen::Vector3d k1 = f(tau, e), k2 = f(tau + h / 2, e + h / 2 * k1),
                            k3 = f(tau + h / 2, e + h / 2 * k2), k4 = f(tau + h, e + h * k3);
      e += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
      const double v = e.dot(gains[i + 1].P * e);
      if (!(v < v_prev)) monotone = false;
      v_prev = v;
    }
    return e;
  };
  const Eigen::Vector3d e0(0.02, 0.1, 0.05);
  bool monotone = false;
  const Eigen::Vector3d closed = simulate(true, monotone);
  EXPECT_TRUE(monotone);
  EXPECT_LT(closed.norm(), 0.1 * e0.norm());
  bool unused = false;
  const Eigen::Vector3d open = simulate(false, unused);
  EXPECT_GT(open.norm(), e0.norm());
  std::fprintf(stderr, "[ transverse ] |e| from %.3g to %.3g with the LQR, %.3g without\n",
               e0.norm(), closed.norm(), open.norm());
}

// On the orbit (zero transverse error) the servo commands the plan's acceleration at the
// disk's phase; off it, the gain's correction.
TEST(Transverse, ServoCommandsFeedforwardPlusGainTimesError) {
  const auto ctrl = started();
  const control::Plan& plan = *fixture().plan;
  const double tau = plan.time_at(0.2);
  const sim::HandKinematics h = plan.hand(tau);
  control::ControlInput in;
  in.t = 1.0;
  in.joint = {1.0, h.angle, h.angular_velocity};
  in.estimate.t = 1.0;
  in.estimate.s_h = 0.2;
  in.estimate.sdot_h = plan.sdot_h_at(tau);
  in.estimating = true;
  control::ControlOutput out = ctrl->step(in);
  EXPECT_EQ(out.mode, "servo");
  EXPECT_NEAR(out.theta_ddot, h.angular_acceleration, 1e-9);
  EXPECT_NEAR(out.theta_reference, h.angle, 1e-12);
  in.joint.theta += 0.01;
  in.estimate.sdot_h += 0.02;
  out = ctrl->step(in);
  const Eigen::RowVector3d K = ctrl->gain(tau);
  EXPECT_NEAR(out.theta_ddot, h.angular_acceleration - K[0] * 0.01 - K[2] * 0.02,
              1e-9 * (1 + std::abs(out.theta_ddot)));
}

TEST(Transverse, BadConfigFieldsAreNamed) {
  const auto message = [](TransverseConfig c) {
    try {
      TransverseController ctrl(c, control::PaperConfig{});
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("(accepted)");
  };
  TransverseConfig c;
  c.r = 0;
  EXPECT_EQ(message(c).rfind("controller.transverse.r: ", 0), 0u) << message(c);
  c = {};
  c.q[1] = -1;
  EXPECT_EQ(message(c).rfind("controller.transverse.q[1]: ", 0), 0u) << message(c);
  c = {};
  c.terminal[2] = NAN;
  EXPECT_EQ(message(c).rfind("controller.transverse.terminal[2]: ", 0), 0u) << message(c);
  c = {};
  c.grid_step = 0.02;
  EXPECT_EQ(message(c).rfind("controller.transverse.grid_step: ", 0), 0u) << message(c);
}

// The closed form is the lossless model's: a nominal model with losses is refused at start.
TEST(Transverse, RefusesALossyNominalModel) {
  auto lossy = std::make_shared<sim::RollingProblem>(*fixture().model);
  lossy->contact.drag = 0.01;
  control::ControllerContext c = context();
  c.model = lossy;
  TransverseController ctrl(TransverseConfig{}, control::PaperConfig{});
  try {
    ctrl.start(c);
    FAIL() << "a lossy model was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("lossless"), std::string::npos) << e.what();
  }
}
