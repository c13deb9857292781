// The spatial rolling equations (11 x 10) at one state, against closed forms: a ball at rest and
// rolling down an incline, a ball on a turntable (Weltner: the centre's acceleration is
// (2/7) Omega z x v), the planar model reproduced by a ball on the extruded hand in its plane, and
// a conforming contact refused.
#include "flatland/sim/rolling.hpp"
#include "flatland/sim/spatial.hpp"
#include "flatland/sim/spec.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace flatland::sim {
namespace {

Eigen::Matrix3d rot_z(double a) { return Eigen::AngleAxisd(a, Vec3::UnitZ()).toRotationMatrix(); }

/// A ball of radius r rolling on the horizontal plane z = 0 of a hand spinning at `spin_rate`
/// about the world z axis through the origin (at this instant the hand frame is the world's):
/// centre above (px, py) moving at (vx, vy), spinning at `spin` about the vertical. The ball's
/// chart puts the contact at s_o = (0, 0) (body +x turned to world -z).
struct BallOnPlate {
  SpatialRollingProblem problem;
  HandPose3 hand;
  SpatialState state;
};

BallOnPlate ball_on_plate(double r, double px, double py, double vx, double vy, double spin,
                          double spin_rate, const Vec3& gravity = Vec3(0, 0, -9.8)) {
  BallOnPlate b;
  b.problem.hand = std::make_shared<PlaneSurface>(Vec3::Zero(), Vec3::UnitX(), Vec3::UnitY());
  b.problem.object = uniform_ball(r, 0.3);
  b.problem.gravity = gravity;
  b.hand.angular_velocity = Vec3(0, 0, spin_rate);
  SpatialState& s = b.state;
  s.position = Vec3(px, py, r);
  s.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(std::numbers::pi / 2, Vec3::UnitY()));
  s.velocity = Vec3(vx, vy, 0);
  const Vec3 contact(px, py, 0);
  // The contact point's velocity over both surfaces: the centre's, less the plate's there.
  const Vec3 w = s.velocity - b.hand.angular_velocity.cross(contact);
  s.s_h = SurfaceParam(px, py);
  s.sdot_h = SurfaceParam(w.x(), w.y());
  // Over the ball: its chart's u runs along world +y at the contact, v along world +x.
  s.s_o = SurfaceParam::Zero();
  s.sdot_o = SurfaceParam(w.y() / r, w.x() / r);
  // Rolling: v + omega x (-r z) = the plate's velocity at the contact, i.e. omega x z = w / r.
  s.angular_velocity = Vec3(-w.y() / r, w.x() / r, spin);
  return b;
}

TEST(SpatialRolling, BallAtRestOnAPlaneIsHeldByItsWeight) {
  const BallOnPlate b = ball_on_plate(0.02, 0.1, -0.03, 0, 0, 0, 0);
  const SpatialSolution s = solve_spatial_rolling(b.problem, b.hand, b.state);
  EXPECT_LT(s.acceleration.norm(), 1e-12);
  EXPECT_LT(s.angular_acceleration.norm(), 1e-10);
  EXPECT_NEAR(s.force_normal, 0.3 * 9.8, 1e-12);
  EXPECT_LT(s.force_tangential.norm(), 1e-12);
  EXPECT_LT(s.residual, 1e-12);
  EXPECT_EQ(s.rank, 10);
}

TEST(SpatialRolling, BallRollsDownAnInclineAtFiveSevenths) {
  // Gravity tilted by theta towards +x: a = (5/7) g sin(theta) down the slope, alpha = a / r,
  // friction (2/7) m g sin(theta) up the slope, normal force m g cos(theta).
  const double theta = 0.3, g = 9.8, r = 0.02, m = 0.3;
  const BallOnPlate b = ball_on_plate(r, 0.05, 0.02, 0.4, -0.1, 2.0, 0,
                                      Vec3(g * std::sin(theta), 0, -g * std::cos(theta)));
  const SpatialSolution s = solve_spatial_rolling(b.problem, b.hand, b.state);
  const double a = 5.0 / 7.0 * g * std::sin(theta);
  EXPECT_LT((s.acceleration - Vec3(a, 0, 0)).norm(), 1e-12);
  EXPECT_LT((s.angular_acceleration - Vec3(0, a / r, 0)).norm(), 1e-9);
  EXPECT_NEAR(s.force_normal, m * g * std::cos(theta), 1e-12);
  EXPECT_LT((s.force_tangential - Vec3(-2.0 / 7.0 * m * g * std::sin(theta), 0, 0)).norm(), 1e-12);
  EXPECT_LT(s.residual, 1e-12);
}

TEST(SpatialRolling, BallOnATurntableTurnsAtTwoSeventhsOfItsRate) {
  // Weltner (Am. J. Phys. 47, 984, 1979): on a plate spinning at Omega about the vertical, a
  // uniform ball's centre accelerates at (2/7) Omega z x v, whatever its own spin about the
  // vertical (which stays constant). The terms omega x w of the rolling row make this hold.
  const double omega = 3.0, r = 0.02;
  for (const double spin : {0.0, 0.7, -5.0}) {
    const BallOnPlate b = ball_on_plate(r, 0.1, -0.05, 0.2, 0.1, spin, omega);
    const SpatialSolution s = solve_spatial_rolling(b.problem, b.hand, b.state);
    const Vec3 expected = 2.0 / 7.0 * omega * Vec3::UnitZ().cross(b.state.velocity);
    EXPECT_LT((s.acceleration - expected).norm(), 1e-12 * omega) << "spin " << spin;
    EXPECT_NEAR(s.angular_acceleration.z(), 0.0, 1e-9) << "spin " << spin;
    EXPECT_NEAR(s.force_normal, 0.3 * 9.8, 1e-12);
    EXPECT_LT(s.residual, 1e-12);
  }
}

TEST(SpatialRolling, BallOnTheExtrudedHandInItsPlaneIsThePlanarModel) {
  // A ball (I = 2/5 m r^2) on the paper's hand extruded along z, in the plane z = 0 with no
  // out-of-plane motion, has the planar general model's accelerations with a disk of the same
  // inertia, and none out of the plane.
  SimulationSpec spec;
  spec.object.inertia = 0.4 * spec.object.mass * spec.object.radius * spec.object.radius;
  spec.run.formulation = Formulation::kGeneral;
  const auto planar = build_problem(spec);
  const GeneralRolling general(planar);
  SpatialRollingProblem pb;
  pb.object = uniform_ball(spec.object.radius, spec.object.mass);
  pb.gravity = Vec3(0, -planar->gravity, 0);
  for (const double t : {0.1, 0.35, 0.6}) {
    for (const double s_h : {-0.9, -0.4, 0.2}) {
      InitialContact init;
      init.t0 = t;
      init.s_h = s_h;
      init.sdot_h = 0.7;
      GeneralRolling::State y = general.initial_state(init);
      const Pieces pieces = general.pieces_for(y, +1);
      general.project(t, y, pieces);
      const GeneralRolling::Assembled p = general.assemble_and_solve(t, y, pieces);

      pb.hand = std::make_shared<ExtrudedSurface>(planar->hand, pieces.hand);
      const HandKinematics k = planar->motion->at(t, pieces.motion);
      HandPose3 hand;
      hand.position = Vec3(k.position.x(), k.position.y(), 0);
      hand.velocity = Vec3(k.velocity.x(), k.velocity.y(), 0);
      hand.acceleration = Vec3(k.acceleration.x(), k.acceleration.y(), 0);
      hand.rotation = rot_z(k.angle);
      hand.angular_velocity = Vec3(0, 0, k.angular_velocity);
      hand.angular_acceleration = Vec3(0, 0, k.angular_acceleration);
      SpatialState st;
      st.position = Vec3(y[0], y[1], 0);
      st.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(y[2], Vec3::UnitZ()));
      st.s_o = SurfaceParam(y[3], 0);  // the sphere's equator is the disk's rim
      st.s_h = SurfaceParam(y[4], 0);
      st.velocity = Vec3(y[5], y[6], 0);
      st.angular_velocity = Vec3(0, 0, y[7]);
      st.sdot_o = SurfaceParam(y[8], 0);
      st.sdot_h = SurfaceParam(y[9], 0);
      const SpatialSolution s = solve_spatial_rolling(pb, hand, st);
      SCOPED_TRACE("t " + std::to_string(t) + ", s_h " + std::to_string(s_h));
      const double scale = 1 + p.x.norm();
      EXPECT_NEAR(s.acceleration.x(), p.x[0], 1e-9 * scale);
      EXPECT_NEAR(s.acceleration.y(), p.x[1], 1e-9 * scale);
      EXPECT_NEAR(s.angular_acceleration.z(), p.x[2], 1e-9 * scale);
      EXPECT_NEAR(s.sddot_o.x(), p.x[3], 1e-9 * scale);
      EXPECT_NEAR(s.sddot_h.x(), p.x[4], 1e-9 * scale);
      EXPECT_NEAR(s.acceleration.z(), 0, 1e-12 * scale);
      EXPECT_NEAR(s.angular_acceleration.x(), 0, 1e-9 * scale);
      EXPECT_NEAR(s.angular_acceleration.y(), 0, 1e-9 * scale);
      EXPECT_NEAR(s.sddot_o.y(), 0, 1e-9 * scale);
      EXPECT_NEAR(s.sddot_h.y(), 0, 1e-9 * scale);
      EXPECT_LT(s.residual, 1e-9 * scale);
    }
  }
}

TEST(SpatialRolling, AConformingContactIsRefused) {
  // A ball in a spherical bowl of its own radius: the curvatures match, A loses rank.
  const double R = 0.05;
  SpatialRollingProblem pb;
  pb.hand = std::make_shared<EllipsoidSurface>(
      EllipsoidSurface::sphere(R, EllipsoidSurface::Side::kDish));
  pb.object = uniform_ball(R);
  const SurfaceParam s_h(0.0, -0.5);
  const SurfaceGeometry gh = pb.hand->geometry(s_h);
  SpatialState st;
  st.s_h = s_h;
  st.position = gh.point + R * gh.normal;  // the ball's centre: the bowl's
  st.orientation = Eigen::Quaterniond::FromTwoVectors(Vec3::UnitX(), -gh.normal);
  try {
    solve_spatial_rolling(pb, HandPose3{}, st);
    FAIL() << "no error for a conforming contact";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("rank deficient"), std::string::npos) << e.what();
  }
  // A smaller ball in the same bowl is fine.
  pb.object = uniform_ball(0.5 * R);
  st.position = gh.point + 0.5 * R * gh.normal;
  EXPECT_EQ(solve_spatial_rolling(pb, HandPose3{}, st).rank, 10);
}

}  // namespace
}  // namespace flatland::sim
