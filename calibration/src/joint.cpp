// Table pose from a chessboard at a known place, and the joint axis and encoder offset from the
// hand's outline at known encoder angles. See docs/JOINT.md.
#include "flatland/calibration/joint.hpp"

#include "flatland/camera/board.hpp"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

namespace flatland::calibration {
namespace {

constexpr double kPi = std::numbers::pi;

// Wrap to (-pi/2, pi/2]: angles of an outline that looks the same after a half turn.
double wrap_half_turn(double a) {
  a = std::remainder(a, kPi);
  if (a <= -kPi / 2) a += kPi;
  return a;
}

double median_of(std::vector<double> v) {
  auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  if (v.size() % 2 == 1) return *mid;
  const double hi = *mid;
  return 0.5 * (hi + *std::max_element(v.begin(), mid));
}

// Mean grey level in a 3 x 3 window around a sub-pixel point (clamped to the image).
double grey_at(const cv::Mat& gray, cv::Point2f p) {
  const int x0 = std::clamp(static_cast<int>(std::lround(p.x)) - 1, 0, gray.cols - 3);
  const int y0 = std::clamp(static_cast<int>(std::lround(p.y)) - 1, 0, gray.rows - 3);
  return cv::mean(gray(cv::Rect(x0, y0, 3, 3)))[0];
}

}  // namespace

namespace {

// The board's inner corners in the image, in OpenCV's order (camera::corners_in_table's order).
std::vector<cv::Point2f> find_board_corners(const cv::Mat& image, const camera::Board& board,
                                            const std::string& who) {
  if (board.kind != camera::Board::Kind::kChessboard)
    throw std::invalid_argument(who + "only chessboards are supported");
  // Messages count inner corners, as the scene file and --board do (OpenCV's patternSize).
  const int n = board.squares_x - 1, m = board.squares_y - 1;  // inner corners per row, rows
  const std::string pattern = std::to_string(n) + "x" + std::to_string(m);
  // cv::findChessboardCorners refuses fewer than 3 inner corners either way.
  if (n < 3 || m < 3 || !(board.square > 0))
    throw std::invalid_argument(
        who + "a chessboard needs at least 3x3 inner corners and square > 0, got " + pattern);
  if ((n + m) % 2 == 0)
    throw std::invalid_argument(who + "a chessboard of " + pattern +
                                " inner corners looks the same turned by a half turn; use an odd "
                                "sum, e.g. 9x6");
  if (image.empty()) throw std::invalid_argument(who + "empty image");
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else
    gray = image;
  if (gray.depth() != CV_8U) gray.convertTo(gray, CV_8U);

  std::vector<cv::Point2f> found;
  if (!cv::findChessboardCorners(gray, cv::Size(n, m), found,
                                 cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
    throw std::invalid_argument(who + "no " + std::to_string(n) + "x" + std::to_string(m) +
                                " inner-corner chessboard found in the image");
  cv::cornerSubPix(gray, found, cv::Size(5, 5), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));

  // OpenCV may list the grid from either end. The board is not half-turn symmetric, so the colour
  // of the first square (between corners 0, 1, n, n + 1) tells which: in OpenCV's order it is our
  // square (column 1, row rows - 2), black when (1 + rows - 2) is even.
  const bool first_black = (board.squares_y - 1) % 2 == 0;
  auto square_centre = [&](int r, int c) {
    const auto at = [&](int rr, int cc) { return found[static_cast<std::size_t>(rr * n + cc)]; };
    return 0.25f * (at(r, c) + at(r, c + 1) + at(r + 1, c) + at(r + 1, c + 1));
  };
  // Compare with the neighbouring square (the other colour) rather than with a fixed level.
  const double first = grey_at(gray, square_centre(0, 0));
  const double other =
      n >= 3 ? grey_at(gray, square_centre(0, 1)) : grey_at(gray, square_centre(1, 0));
  if ((first < other) != first_black) std::reverse(found.begin(), found.end());
  return found;
}

}  // namespace

TablePose estimate_table_pose(const cv::Mat& image, const camera::PlacedBoard& board, const cv::Matx33d& K,
                              const camera::Distortion& dist) {
  return estimate_table_pose(std::vector<cv::Mat>{image}, std::vector<camera::PlacedBoard>{board}, K, dist);
}

TablePose estimate_table_pose(const std::vector<cv::Mat>& images,
                              const std::vector<camera::PlacedBoard>& boards, const cv::Matx33d& K,
                              const camera::Distortion& dist) {
  const std::string who = "estimate_table_pose: ";
  if (images.empty() || images.size() != boards.size())
    throw std::invalid_argument(who + std::to_string(images.size()) + " images but " +
                                std::to_string(boards.size()) + " board placements");
  if (!(K(0, 0) > 0) || !(K(1, 1) > 0))
    throw std::invalid_argument(who + "camera matrix needs fx, fy > 0");
  // The camera does not move between the images and every board's corners are known in the table
  // frame, so all placements are one point set: boards spread over the table pin its tilt far
  // better than one small board (measured: docs/JOINT.md).
  std::vector<cv::Point3f> object_f;
  std::vector<cv::Point2f> found;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const std::string where = images.size() > 1 ? who + "image " + std::to_string(i) + ": " : who;
    const std::vector<cv::Point2f> corners = find_board_corners(images[i], boards[i].board, where);
    const std::vector<cv::Point3d> object = camera::corners_in_table(boards[i]);
    found.insert(found.end(), corners.begin(), corners.end());
    object_f.insert(object_f.end(), object.begin(), object.end());
  }
  cv::Mat rvec, tvec;
  if (!cv::solvePnP(object_f, found, cv::Mat(K), cv::Mat(dist), rvec, tvec, false,
                    cv::SOLVEPNP_ITERATIVE))
    throw std::invalid_argument(who + "solvePnP failed");
  cv::solvePnPRefineLM(object_f, found, cv::Mat(K), cv::Mat(dist), rvec, tvec);

  TablePose pose;
  cv::Mat Rm;
  cv::Rodrigues(rvec, Rm);
  Rm.convertTo(Rm, CV_64F);
  pose.R = cv::Matx33d(Rm);
  pose.t = cv::Vec3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  std::vector<cv::Point2f> projected;
  cv::projectPoints(object_f, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected);
  double sum = 0;
  for (std::size_t i = 0; i < found.size(); ++i) {
    const cv::Point2f d = projected[i] - found[i];
    sum += d.dot(d);
  }
  pose.corners = static_cast<int>(found.size());
  pose.rms_px = std::sqrt(sum / static_cast<double>(found.size()));
  if (!(pose.t[2] > 0)) throw std::invalid_argument(who + "board found behind the camera");
  return pose;
}

camera::JointCalibration calibrate_joint(const std::vector<cv::Mat>& images,
                                 const std::vector<double>& encoder_angles,
                                 const camera::CameraModel& camera, double plate_height,
                                 JointReport* report) {
  const std::string who = "calibrate_joint: ";
  if (images.size() != encoder_angles.size())
    throw std::invalid_argument(who + std::to_string(images.size()) + " images but " +
                                std::to_string(encoder_angles.size()) + " encoder angles");
  if (images.size() < 3)
    throw std::invalid_argument(who + "needs at least 3 images, got " +
                                std::to_string(images.size()));
  for (std::size_t i = 0; i < encoder_angles.size(); ++i)
    if (!std::isfinite(encoder_angles[i]))
      throw std::invalid_argument(who + "encoder angle " + std::to_string(i) + " is not finite");

  const std::size_t count = images.size();
  std::vector<vision::HandPose> poses;
  poses.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    try {
      poses.push_back(vision::measure_hand_pose(images[i], camera, plate_height));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(who + "image " + std::to_string(i) + ": " + e.what());
    }
  }

  // Robust start: medians of the centres and of the angle differences (the differences are taken
  // modulo pi about their doubled-angle mean, so a spread around +-pi/2 does not split).
  std::vector<double> xs, ys, diffs(count);
  double s2 = 0, c2 = 0;
  for (std::size_t i = 0; i < count; ++i) {
    xs.push_back(poses[i].center_table.x);
    ys.push_back(poses[i].center_table.y);
    diffs[i] = wrap_half_turn(poses[i].angle - encoder_angles[i]);
    s2 += std::sin(2 * diffs[i]);
    c2 += std::cos(2 * diffs[i]);
  }
  const double rough_offset = 0.5 * std::atan2(s2, c2);
  std::vector<double> rel(count);
  for (std::size_t i = 0; i < count; ++i) rel[i] = wrap_half_turn(diffs[i] - rough_offset);
  const cv::Point2d med(median_of(xs), median_of(ys));
  const double med_rel = median_of(rel);

  // Outliers (a frame where something else was bright, a mis-read encoder): far from the medians
  // by more than 5 robust sigmas, with floors so that a perfect data set rejects nothing.
  std::vector<double> dist_c(count), dist_a(count);
  for (std::size_t i = 0; i < count; ++i) {
    dist_c[i] = std::hypot(xs[i] - med.x, ys[i] - med.y);
    dist_a[i] = std::abs(rel[i] - med_rel);
  }
  const double tol_c = std::max(5 * 1.4826 * median_of(dist_c), 0.5e-3);
  const double tol_a = std::max(5 * 1.4826 * median_of(dist_a), 0.1 * kPi / 180);
  std::vector<bool> inlier(count);
  std::size_t used = 0;
  for (std::size_t i = 0; i < count; ++i) {
    inlier[i] = dist_c[i] <= tol_c && dist_a[i] <= tol_a;
    used += inlier[i] ? 1 : 0;
  }
  if (used < 3)
    throw std::invalid_argument(who + "only " + std::to_string(used) +
                                " images agree with each other (need 3)");

  // The centroid is the axis in every image and the outline's axis is encoder + offset: both are
  // plain means over the inliers (least squares with equal weights).
  cv::Point2d axis(0, 0);
  double mean_rel = 0;
  for (std::size_t i = 0; i < count; ++i)
    if (inlier[i]) {
      axis += poses[i].center_table;
      mean_rel += rel[i];
    }
  axis *= 1.0 / static_cast<double>(used);
  mean_rel /= static_cast<double>(used);
  camera::JointCalibration result;
  result.axis_table = axis;
  result.encoder_offset = wrap_half_turn(rough_offset + mean_rel);

  if (report) {
    report->poses = poses;
    report->inlier = inlier;
    report->center_residuals.assign(count, {});
    report->angle_residuals.assign(count, 0);
    double sc = 0, sa = 0;
    for (std::size_t i = 0; i < count; ++i) {
      report->center_residuals[i] = poses[i].center_table - axis;
      report->angle_residuals[i] =
          wrap_half_turn(poses[i].angle - encoder_angles[i] - result.encoder_offset);
      if (inlier[i]) {
        sc += report->center_residuals[i].dot(report->center_residuals[i]);
        sa += report->angle_residuals[i] * report->angle_residuals[i];
      }
    }
    const double u = static_cast<double>(used);
    report->center_rms = std::sqrt(sc / u);
    report->angle_rms = std::sqrt(sa / u);
    // Standard error of a mean from the scatter (per coordinate: half the 2-D variance).
    report->sigma_axis = std::sqrt(0.5 * sc / (u - 1) / u);
    report->sigma_offset = std::sqrt(sa / (u - 1) / u);
  }
  return result;
}

}  // namespace flatland::calibration
