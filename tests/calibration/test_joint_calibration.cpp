// Hand pose from the outline and the joint / table-pose calibration against the renderer's exact
// truth: the hand pivots at the table origin, hand_angle = encoder + offset, and
// camera::CameraModel::from_spec gives the true table pose. Frames get 1 DN of read noise.
#include "flatland/calibration/joint.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/vision/hand_pose.hpp"
#include "render_support.hpp"
#include "units.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

using namespace flatland;
using namespace flatland::render;

namespace {

using flatland_test::kDeg;

// The brief's camera: 640 x 480, f = 900 px, 1 m above the table, a little off the pivot, so the
// pivot is not at the principal point and the view is slightly oblique.
Scene joint_scene(std::array<double, 3> position = {0.02, -0.03, 1.0},
                  std::array<double, 3> look_at = {0, 0, 0},
                  std::array<double, 5> distortion = {}) {
  Scene s;
  CameraSpec cam = flatland_test::overhead_camera(position);
  cam.look_at = look_at;
  cam.distortion = distortion;
  s.camera = cam;
  s.effects.supersample = 2;
  s.effects.noise_read_dn = 1;
  return s;
}

// One frame of the hand at `hand_angle`, the disk out of view, with the scene's read noise.
cv::Mat hand_frame(Renderer& r, const Scene& s, double hand_angle, EffectsRng& rng) {
  SceneState st;
  st.hand_angle = hand_angle;
  st.disk_center = {5, 5};
  cv::Mat f = r.render_linear(st);
  apply_noise(f, s.effects.noise_read_dn, 0, rng);
  return quantize(f);
}

bool one_line(const std::string& s) { return !s.empty() && s.find('\n') == std::string::npos; }

}  // namespace

TEST(HandPose, SingleFrameCentreAndAngle) {
  const Scene s = joint_scene();
  Renderer r(flatland_test::render_setup(s));
  EffectsRng rng(3);
  for (double angle : {0.0, 0.4, 1.3, 2.2, 3.0}) {
    const cv::Mat img = hand_frame(r, s, angle, rng);
    const vision::HandPose p = vision::measure_hand_pose(img, r.camera(), s.render.hand_thickness);
    EXPECT_LT(std::hypot(p.center_table.x, p.center_table.y), 0.3e-3) << "angle " << angle;
    const double a = vision::resolve_half_turn(p.angle, angle);
    EXPECT_LT(std::abs(a - angle), 0.05 * kDeg) << "angle " << angle;
    EXPECT_GT(p.elongation, 2.0);  // the hand is long: the principal axis is well defined
  }
}

TEST(HandPose, ObliqueDistortedCamera) {
  // Camera foot point over the hand's tip region, looking sideways, barrel distortion: the side
  // walls of the plate are in view and the hand is far from the principal point.
  const Scene s = joint_scene({0.15, 0.1, 0.9}, {0.05, 0.02, 0}, {-0.1, 0.02, 0, 0, 0});
  Renderer r(flatland_test::render_setup(s));
  EffectsRng rng(4);
  for (double angle : {0.1, 1.0, 2.4}) {
    const cv::Mat img = hand_frame(r, s, angle, rng);
    const vision::HandPose p = vision::measure_hand_pose(img, r.camera(), s.render.hand_thickness);
    EXPECT_LT(std::hypot(p.center_table.x, p.center_table.y), 0.3e-3) << "angle " << angle;
    EXPECT_LT(std::abs(vision::resolve_half_turn(p.angle, angle) - angle), 0.05 * kDeg);
  }
}

TEST(HandPose, ResolveHalfTurn) {
  EXPECT_NEAR(vision::resolve_half_turn(0.1, 3.2), 0.1 + std::numbers::pi, 1e-12);
  EXPECT_NEAR(vision::resolve_half_turn(-1.5, 1.7), -1.5 + std::numbers::pi, 1e-12);
  EXPECT_NEAR(vision::resolve_half_turn(0.3, 0.0), 0.3, 1e-12);
}

TEST(HandPose, NoHandOrWrongSizeThrows) {
  const camera::CameraModel cam = flatland::model::compile_camera(*joint_scene().camera);
  const cv::Mat table(480, 640, CV_8UC3, cv::Scalar(52, 52, 52));
  try {
    vision::measure_hand_pose(table, cam, 0.012);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_TRUE(one_line(e.what()));
    EXPECT_NE(std::string(e.what()).find("no hand found"), std::string::npos) << e.what();
  }
  EXPECT_THROW(
      vision::measure_hand_pose(cv::Mat(240, 320, CV_8UC3, cv::Scalar::all(52)), cam, 0.012),
      std::invalid_argument);
  EXPECT_THROW(vision::measure_hand_pose(cv::Mat(), cam, 0.012), std::invalid_argument);
}

TEST(JointCalibration, AxisAndOffsetAcceptance) {
  // Two cameras: the brief's, and one whose view puts the pivot well off the image centre.
  const std::vector<Scene> scenes = {joint_scene(), joint_scene({0.12, 0.08, 1.0}, {0.1, 0.06, 0})};
  for (const Scene& s : scenes) {
    Renderer r(flatland_test::render_setup(s));
    EffectsRng rng(11);
    const double offset = 0.7 * kDeg;
    std::vector<cv::Mat> images;
    std::vector<double> encoder;
    for (int i = 0; i < 8; ++i) {
      const double e = i * std::numbers::pi / 8 + 0.05;  // spread over a half turn
      encoder.push_back(e);
      images.push_back(hand_frame(r, s, e + offset, rng));
    }
    calibration::JointReport report;
    const camera::JointCalibration j =
        calibration::calibrate_joint(images, encoder, r.camera(), s.render.hand_thickness, &report);
    EXPECT_LT(std::hypot(j.axis_table.x, j.axis_table.y), 0.5e-3);
    EXPECT_NEAR(j.encoder_offset, offset, 0.1 * kDeg);
    EXPECT_EQ(report.poses.size(), 8u);
    EXPECT_LT(report.center_rms, 0.3e-3);
    EXPECT_LT(report.angle_rms, 0.05 * kDeg);
    for (bool in : report.inlier) EXPECT_TRUE(in);
  }
}

namespace {

// The brief's camera, 8 frames of the hand over a half turn at a known offset: their measured
// poses, rendered once for the tests below.
struct HandSeries {
  camera::CameraModel camera;
  double plate = 0;
  double offset = 0.7 * kDeg;
  std::vector<double> encoder;
  std::vector<vision::HandPose> poses;
};

const HandSeries& hand_series() {
  static const HandSeries series = [] {
    HandSeries h;
    const Scene s = joint_scene();
    Renderer r(flatland_test::render_setup(s));
    EffectsRng rng(21);
    h.camera = r.camera();
    h.plate = s.render.hand_thickness;
    for (int i = 0; i < 8; ++i) {
      h.encoder.push_back(0.05 + i * std::numbers::pi / 8);
      h.poses.push_back(vision::measure_hand_pose(
          hand_frame(r, s, h.encoder.back() + h.offset, rng), h.camera, h.plate));
    }
    return h;
  }();
  return series;
}

calibration::JointReport fit(const std::vector<vision::HandPose>& poses,
                             const std::vector<double>& encoder,
                             const calibration::CameraUncertainty& uncertainty = {}) {
  const HandSeries& h = hand_series();
  calibration::JointReport report;
  calibration::calibrate_joint(poses, encoder, h.camera, h.plate, uncertainty, &report);
  return report;
}

}  // namespace

TEST(JointCalibration, SupportedDataPassAndTheSigmaCoversTheError) {
  const HandSeries& h = hand_series();
  calibration::JointReport report;
  const camera::JointCalibration j =
      calibration::calibrate_joint(h.poses, h.encoder, h.camera, h.plate, {}, &report);
  EXPECT_EQ(report.unsupported, "");
  EXPECT_EQ(report.distinct_readings, 8);
  EXPECT_NEAR(report.span_rad, 7 * std::numbers::pi / 8, 1e-9);
  EXPECT_EQ(report.dof, 21);
  // chi-square's 0.999 quantile for 21 degrees of freedom, from the standard tables.
  EXPECT_NEAR(report.chi2_limit, 46.797, 1e-3);
  EXPECT_LT(report.chi2, report.chi2_limit);
  // The truth: the pivot at the table origin, the offset 0.7 degrees.
  std::printf(
      "joint, exact camera: axis error %.2e m (sigma %.2e), offset error %.2e rad (sigma "
      "%.2e)\n",
      std::hypot(j.axis_table.x, j.axis_table.y), report.sigma_axis, j.encoder_offset - h.offset,
      report.sigma_offset);
  EXPECT_LT(std::abs(j.axis_table.x), 3 * report.sigma_axis);
  EXPECT_LT(std::abs(j.axis_table.y), 3 * report.sigma_axis);
  EXPECT_LT(std::abs(j.encoder_offset - h.offset), 3 * report.sigma_offset);
  // An exact camera adds nothing: the sigma is the images' part.
  EXPECT_EQ(report.sigma_axis, report.sigma_axis_images);

  // An uncertain camera widens the axis's sigma: 1 px of principal point moves the axis by about
  // the table distance / f, here 1 m / 900 px (the pose held: no sensitivity given).
  calibration::CameraUncertainty cx_only;
  cx_only.intrinsics_std = {0, 0, 1.0, 0};
  const calibration::JointReport wide = fit(h.poses, h.encoder, cx_only);
  const double camera_part = std::sqrt(wide.sigma_axis * wide.sigma_axis -
                                       wide.sigma_axis_images * wide.sigma_axis_images);
  EXPECT_NEAR(camera_part, 1.0 / 900 * (1.0 - h.plate), 0.1 * 1.0 / 900);
}

TEST(JointCalibration, RefusesWhatTheDataCannotSupport) {
  const HandSeries& h = hand_series();
  // Copies of one image at one reading: one angle cannot tell an offset from a stuck encoder.
  const calibration::JointReport same =
      fit(std::vector<vision::HandPose>(8, h.poses[3]), std::vector<double>(8, h.encoder[3]));
  EXPECT_NE(same.unsupported.find("1 distinct encoder reading"), std::string::npos)
      << same.unsupported;
  EXPECT_TRUE(one_line(same.unsupported));
  // Copies of one image at the true readings: the poses do not follow the encoder.
  const calibration::JointReport copies =
      fit(std::vector<vision::HandPose>(8, h.poses[3]), h.encoder);
  EXPECT_NE(copies.unsupported.find("do not follow the encoder"), std::string::npos)
      << copies.unsupported;
  // Readings shuffled between the images (no reading left in its place).
  std::vector<double> shuffled;
  for (int k : {3, 7, 0, 5, 1, 6, 2, 4}) shuffled.push_back(h.encoder[static_cast<std::size_t>(k)]);
  const calibration::JointReport mixed = fit(h.poses, shuffled);
  EXPECT_NE(mixed.unsupported.find("chi-square"), std::string::npos) << mixed.unsupported;
  EXPECT_GT(mixed.chi2, mixed.chi2_limit);
  // Two views.
  const calibration::JointReport two = fit({h.poses[0], h.poses[4]}, {h.encoder[0], h.encoder[4]});
  EXPECT_NE(two.unsupported.find("only 2 images"), std::string::npos) << two.unsupported;
  // Four distinct readings within 3 * 22.5 = 67.5 degrees pass; within 22.5 degrees they do not
  // span enough (the frames 1 degree apart are rendered for it).
  const calibration::JointReport four =
      fit({h.poses[0], h.poses[1], h.poses[2], h.poses[3]},
          {h.encoder[0], h.encoder[1], h.encoder[2], h.encoder[3]});
  EXPECT_EQ(four.unsupported, "");
  const Scene s = joint_scene();
  Renderer r(flatland_test::render_setup(s));
  EffectsRng rng(22);
  std::vector<vision::HandPose> close;
  std::vector<double> close_encoder;
  for (int i = 0; i < 5; ++i) {
    close_encoder.push_back(0.3 + i * 5 * kDeg);
    close.push_back(vision::measure_hand_pose(
        hand_frame(r, s, close_encoder.back() + h.offset, rng), h.camera, h.plate));
  }
  const calibration::JointReport narrow = fit(close, close_encoder);
  EXPECT_NE(narrow.unsupported.find("span 20 deg"), std::string::npos) << narrow.unsupported;
  // Readings that wrap round a half turn are one cluster, not two: 179.5 and 0.2 degrees.
  const calibration::JointReport wrapped =
      fit({h.poses[0], h.poses[0], h.poses[0], h.poses[0]},
          {h.encoder[0], h.encoder[0] + std::numbers::pi, h.encoder[0] - 0.3 * kDeg,
           h.encoder[0] + 0.3 * kDeg + std::numbers::pi});
  EXPECT_NE(wrapped.unsupported.find("1 distinct encoder reading"), std::string::npos)
      << wrapped.unsupported;
}

TEST(JointCalibration, RejectsMisreadEncoder) {
  const Scene s = joint_scene();
  Renderer r(flatland_test::render_setup(s));
  EffectsRng rng(5);
  const double offset = -1.2 * kDeg;
  std::vector<cv::Mat> images;
  std::vector<double> encoder;
  for (int i = 0; i < 6; ++i) {
    const double e = i * std::numbers::pi / 6;
    images.push_back(hand_frame(r, s, e + offset, rng));
    encoder.push_back(i == 2 ? e + 3 * kDeg : e);  // one encoder reading is 3 degrees off
  }
  calibration::JointReport report;
  const camera::JointCalibration j =
      calibration::calibrate_joint(images, encoder, r.camera(), s.render.hand_thickness, &report);
  EXPECT_NEAR(j.encoder_offset, offset, 0.1 * kDeg);
  EXPECT_FALSE(report.inlier[2]);
  EXPECT_NEAR(report.angle_residuals[2], -3 * kDeg, 0.1 * kDeg);
}

namespace {

TargetSpec board_at(double x, double y, double rot_z) {
  TargetSpec board;
  board.kind = TargetSpec::Kind::kChessboard;
  board.squares_x = 9;
  board.squares_y = 6;  // 9 + 6 odd: not half-turn symmetric, so its corners can be ordered
  board.square = 0.02;
  board.position = {x, y, 0.001};
  board.rotation = {0, 0, rot_z};
  return board;
}

// One image of `board` lying on the table, the hand turned across the view so that it does not
// cover the board.
cv::Mat board_image(const TargetSpec& board, EffectsRng& rng) {
  Scene s = joint_scene();
  s.targets.push_back(board);
  Renderer r(flatland_test::render_setup(s));
  return hand_frame(r, s, std::numbers::pi / 2, rng);
}

// Rotation angle between two rotations, rad.
double rotation_error(const cv::Matx33d& a, const cv::Matx33d& b) {
  const cv::Matx33d d = a * b.t();
  return std::acos(std::clamp((cv::trace(d) - 1) / 2, -1.0, 1.0));
}

}  // namespace

std::vector<camera::PlacedBoard> placed(const std::vector<TargetSpec>& boards) {
  std::vector<camera::PlacedBoard> out;
  for (const TargetSpec& b : boards) out.push_back(flatland::model::compile_target(b));
  return out;
}

TEST(JointCalibration, TablePoseFromBoards) {
  const camera::CameraModel truth = flatland::model::compile_camera(*joint_scene().camera);
  EffectsRng rng(9);
  // One board 0.16 m wide fixes the table's tilt only to a few tenths of a degree (measured:
  // docs/JOINT.md); the second placement is the board turned by a half turn, which checks that
  // its corners are matched the right way round (a wrong match would be a 180-degree error).
  for (const TargetSpec& board : {board_at(0.11, -0.09, 0.15), board_at(0.30, 0.05, 3.29)}) {
    const calibration::TablePose pose = calibration::estimate_table_pose(
        board_image(board, rng), flatland::model::compile_target(board), truth.K, truth.dist);
    EXPECT_EQ(pose.corners, 40);
    EXPECT_LT(pose.rms_px, 0.25);
    EXPECT_LT(rotation_error(pose.R, truth.R), 0.4 * kDeg);
    EXPECT_LT(cv::norm(pose.t - truth.t), 1.5e-3);
  }
  // Acceptance: four placements spread over the view, one pose fit: within 0.1 degree and 1 mm.
  std::vector<TargetSpec> boards = {board_at(0.11, -0.09, 0.15), board_at(-0.30, 0.06, -0.1),
                                    board_at(0.12, 0.10, 0.0), board_at(-0.30, -0.24, 0.05)};
  std::vector<cv::Mat> images;
  for (const TargetSpec& b : boards) images.push_back(board_image(b, rng));
  const calibration::TablePose pose =
      calibration::estimate_table_pose(images, placed(boards), truth.K, truth.dist);
  EXPECT_EQ(pose.corners, 160);
  EXPECT_LT(rotation_error(pose.R, truth.R), 0.1 * kDeg);
  EXPECT_LT(cv::norm(pose.t - truth.t), 1e-3);
  // The camera centre in the table frame too (what the hand pose mapping depends on).
  const cv::Vec3d c_est = -(pose.R.t() * pose.t);
  EXPECT_LT(cv::norm(c_est - truth.position_in_table()), 1e-3);

  // And the joint calibrated through the estimated pose instead of the true one.
  const Scene s = joint_scene();
  Renderer r(flatland_test::render_setup(s));
  camera::CameraModel estimated = r.camera();
  estimated.R = pose.R;
  estimated.t = pose.t;
  std::vector<cv::Mat> hands;
  std::vector<double> encoder;
  for (int i = 0; i < 8; ++i) {
    encoder.push_back(i * std::numbers::pi / 8);
    hands.push_back(hand_frame(r, s, encoder.back() + 0.7 * kDeg, rng));
  }
  const camera::JointCalibration j =
      calibration::calibrate_joint(hands, encoder, estimated, s.render.hand_thickness);
  EXPECT_LT(std::hypot(j.axis_table.x, j.axis_table.y), 0.5e-3);
  EXPECT_NEAR(j.encoder_offset, 0.7 * kDeg, 0.1 * kDeg);
}

TEST(JointCalibration, BadInputThrows) {
  const Scene s = joint_scene();
  const camera::CameraModel cam = flatland::model::compile_camera(*s.camera);
  const cv::Mat table(480, 640, CV_8UC3, cv::Scalar::all(52));
  auto expect_one_line_throw = [](auto&& f, const std::string& needle) {
    try {
      f();
      ADD_FAILURE() << "no exception for " << needle;
    } catch (const std::invalid_argument& e) {
      EXPECT_TRUE(one_line(e.what())) << e.what();
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_one_line_throw(
      [&] { calibration::calibrate_joint(std::vector<cv::Mat>{}, {}, cam, 0.012); }, "no images");
  expect_one_line_throw(
      [&] {
        calibration::calibrate_joint({table, table, table}, {0.0, 1.0}, cam, 0.012);
      },
      "3 images but 2 encoder angles");
  expect_one_line_throw(
      [&] {
        calibration::calibrate_joint({table, table, table}, {0.0, 1.0, 2.0}, cam, 0.012);
      },
      "image 0: measure_hand_pose: no hand found");
  camera::PlacedBoard symmetric;
  symmetric.board.squares_x = 8;
  symmetric.board.squares_y = 6;
  expect_one_line_throw(
      [&] { calibration::estimate_table_pose(table, symmetric, cam.K, cam.dist); },
      "a chessboard of 7x5 inner corners looks the same turned by a half turn");
  camera::PlacedBoard small;
  small.board.squares_x = 3;
  expect_one_line_throw([&] { calibration::estimate_table_pose(table, small, cam.K, cam.dist); },
                        "at least 3x3 inner corners");
  camera::PlacedBoard board;  // 9 x 6 inner corners, but there is none in the image
  expect_one_line_throw([&] { calibration::estimate_table_pose(table, board, cam.K, cam.dist); },
                        "no 9x6 inner-corner chessboard found");
  expect_one_line_throw(
      [&] {
        calibration::estimate_table_pose(std::vector<cv::Mat>{table, table},
                                         std::vector<camera::PlacedBoard>{board}, cam.K, cam.dist);
      },
      "2 images but 1 board placements");
}

TEST(JointCalibration, TablePoseRefusesAMisplacedBoard) {
  const camera::CameraModel truth = flatland::model::compile_camera(*joint_scene().camera);
  EffectsRng rng(13);
  const std::vector<TargetSpec> boards = {board_at(0.11, -0.09, 0.15), board_at(-0.30, 0.06, -0.1),
                                          board_at(0.12, 0.10, 0.0), board_at(-0.30, -0.24, 0.05)};
  calibration::TableCorners right, wrong;
  for (std::size_t i = 0; i < boards.size(); ++i) {
    const cv::Mat image = board_image(boards[i], rng);
    camera::PlacedBoard placed = flatland::model::compile_target(boards[i]);
    const std::string name = std::string("b") += std::to_string(i);
    right.add(image, placed, name);
    if (i == 2) placed.position[0] += 0.01;  // the row says 1 cm further along x
    wrong.add(image, placed, name);
  }
  const calibration::TablePose good = calibration::estimate_table_pose(right, truth.K, truth.dist);
  EXPECT_EQ(good.unsupported, "");
  EXPECT_GT(good.rcond, calibration::kMinTableRcond);
  ASSERT_EQ(good.placement_rms_px.size(), 4u);
  // The residual-scaled sigma of the camera centre covers its error (the intrinsics exact here).
  const cv::Vec3d sigma = good.sigma_camera_in_table();
  const cv::Vec3d c_est = -(good.R.t() * good.t);
  for (int k = 0; k < 3; ++k)
    EXPECT_LT(std::abs(c_est[k] - truth.position_in_table()[k]), 3 * sigma[k]) << "axis " << k;
  const calibration::TablePose bad = calibration::estimate_table_pose(wrong, truth.K, truth.dist);
  std::printf("F good %.3g bad %.3g limit %.3g\n", good.f_statistic, bad.f_statistic, bad.f_limit);
  std::printf("%s\n", bad.unsupported.c_str());
  EXPECT_NE(bad.unsupported.find("b2 is farthest from the others"), std::string::npos)
      << bad.unsupported;
  EXPECT_TRUE(one_line(bad.unsupported));
}
