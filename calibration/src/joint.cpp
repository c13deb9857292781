// Table pose from a chessboard at a known place, and the joint axis and encoder offset from the
// hand's outline at known encoder angles. See docs/JOINT.md.
#include "flatland/calibration/joint.hpp"

#include "flatland/camera/board.hpp"
#include "flatland/sim/format.hpp"
#include "flatland/vision/mapping.hpp"

#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/fisher_f.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

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

void TableCorners::add(const cv::Mat& image, const camera::PlacedBoard& board,
                       const std::string& name) {
  const std::string where = "estimate_table_pose: image " + std::to_string(names_.size()) + ": ";
  const std::vector<cv::Point2f> corners = find_board_corners(image, board.board, where);
  const std::vector<cv::Point3d> object = camera::corners_in_table(board);
  starts_.push_back(found_.size());
  found_.insert(found_.end(), corners.begin(), corners.end());
  object_.insert(object_.end(), object.begin(), object.end());
  names_.push_back(name.empty() ? "image " + std::to_string(names_.size()) : name);
}

cv::Vec3d TablePose::sigma_camera_in_table() const {
  // c = -R^T t: its Jacobian in (rvec, tvec) by central differences (R through Rodrigues).
  cv::Vec3d r0;
  cv::Rodrigues(R, r0);
  const auto centre = [&](const cv::Vec<double, 6>& p) {
    cv::Matx33d Rp;
    cv::Rodrigues(cv::Vec3d(p[0], p[1], p[2]), Rp);
    return cv::Vec3d(-(Rp.t() * cv::Vec3d(p[3], p[4], p[5])));
  };
  const cv::Vec<double, 6> p0(r0[0], r0[1], r0[2], t[0], t[1], t[2]);
  cv::Matx<double, 3, 6> J;
  for (int k = 0; k < 6; ++k) {
    const double h = 1e-7;
    cv::Vec<double, 6> plus = p0, minus = p0;
    plus[k] += h;
    minus[k] -= h;
    const cv::Vec3d d = (centre(plus) - centre(minus)) * (1 / (2 * h));
    for (int i = 0; i < 3; ++i) J(i, k) = d[i];
  }
  const cv::Matx33d C = J * covariance * J.t();
  return {std::sqrt(C(0, 0)), std::sqrt(C(1, 1)), std::sqrt(C(2, 2))};
}

TablePose estimate_table_pose(const cv::Mat& image, const camera::PlacedBoard& board,
                              const cv::Matx33d& K, const camera::Distortion& dist) {
  return estimate_table_pose(std::vector<cv::Mat>{image}, std::vector<camera::PlacedBoard>{board},
                             K, dist);
}

TablePose estimate_table_pose(const std::vector<cv::Mat>& images,
                              const std::vector<camera::PlacedBoard>& boards, const cv::Matx33d& K,
                              const camera::Distortion& dist) {
  if (images.empty() || images.size() != boards.size())
    throw std::invalid_argument("estimate_table_pose: " + std::to_string(images.size()) +
                                " images but " + std::to_string(boards.size()) +
                                " board placements");
  TableCorners corners;
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (images.size() > 1) {
      corners.add(images[i], boards[i]);
      continue;
    }
    try {
      corners.add(images[i], boards[i]);
    } catch (const std::invalid_argument& e) {  // one image: no index in the message
      std::string what = e.what();
      const std::string index = "image 0: ";
      if (const auto at = what.find(index); at != std::string::npos) what.erase(at, index.size());
      throw std::invalid_argument(what);
    }
  }
  return estimate_table_pose(corners, K, dist);
}

namespace {

// Calls f(part) with each placement's object points, so that Jacobians are built a placement at
// a time (the whole Jacobian of 10 000 placements would take 200 MB).
template <typename F>
void for_each_placement(const TableCorners& corners, F&& f) {
  const std::vector<cv::Point3f>& object = corners.object_points();
  const std::size_t n = corners.placements();
  for (std::size_t p = 0; p < n; ++p) {
    const std::size_t begin = corners.starts()[p];
    const std::size_t end = p + 1 < n ? corners.starts()[p + 1] : object.size();
    f(std::vector<cv::Point3f>(object.begin() + static_cast<std::ptrdiff_t>(begin),
                               object.begin() + static_cast<std::ptrdiff_t>(end)),
      begin);
  }
}

// Sum of squared reprojection errors over all corners.
double reprojection_ssr(const TableCorners& corners, const cv::Mat& rvec, const cv::Mat& tvec,
                        const cv::Matx33d& K, const camera::Distortion& dist) {
  double ssr = 0;
  for_each_placement(corners, [&](const std::vector<cv::Point3f>& part, std::size_t begin) {
    std::vector<cv::Point2f> projected;
    cv::projectPoints(part, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected);
    for (std::size_t i = 0; i < part.size(); ++i) {
      const cv::Point2f d = projected[i] - corners.image_points()[begin + i];
      ssr += d.dot(d);
    }
  });
  return ssr;
}

// The pose that minimises the reprojection error over every corner: cv::solvePnP on a subsample
// of at most kStartCorners corners (its memory grows with the points: 270 MB for 270 000), then
// Levenberg-Marquardt on all of them with normal equations summed a placement at a time.
void solve_pose(const TableCorners& corners, const cv::Matx33d& K, const camera::Distortion& dist,
                cv::Mat& rvec, cv::Mat& tvec) {
  constexpr std::size_t kStartCorners = 4000;
  const std::vector<cv::Point3f>& object = corners.object_points();
  const std::vector<cv::Point2f>& found = corners.image_points();
  const std::size_t stride = (object.size() + kStartCorners - 1) / kStartCorners;
  std::vector<cv::Point3f> object_start;
  std::vector<cv::Point2f> found_start;
  for (std::size_t i = 0; i < object.size(); i += stride) {
    object_start.push_back(object[i]);
    found_start.push_back(found[i]);
  }
  if (!cv::solvePnP(object_start, found_start, cv::Mat(K), cv::Mat(dist), rvec, tvec, false,
                    cv::SOLVEPNP_ITERATIVE))
    throw std::invalid_argument("estimate_table_pose: solvePnP failed");
  cv::solvePnPRefineLM(object_start, found_start, cv::Mat(K), cv::Mat(dist), rvec, tvec);
  if (stride == 1) return;  // that was every corner

  rvec.convertTo(rvec, CV_64F);
  tvec.convertTo(tvec, CV_64F);
  double ssr = reprojection_ssr(corners, rvec, tvec, K, dist);
  double lambda = 1e-3;
  for (int iteration = 0; iteration < 50; ++iteration) {
    cv::Mat N = cv::Mat::zeros(6, 6, CV_64F), b = cv::Mat::zeros(6, 1, CV_64F);
    for_each_placement(corners, [&](const std::vector<cv::Point3f>& part, std::size_t begin) {
      std::vector<cv::Point2f> projected;
      cv::Mat jacobian;
      cv::projectPoints(part, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected, jacobian);
      jacobian.convertTo(jacobian, CV_64F);
      cv::Mat r(static_cast<int>(2 * part.size()), 1, CV_64F);
      for (std::size_t i = 0; i < part.size(); ++i) {
        const cv::Point2f d = projected[i] - found[begin + i];
        r.at<double>(static_cast<int>(2 * i)) = d.x;
        r.at<double>(static_cast<int>(2 * i + 1)) = d.y;
      }
      const cv::Mat Jp = jacobian.colRange(0, 6);
      N += Jp.t() * Jp;
      b += Jp.t() * r;
    });
    bool improved = false;
    for (int tries = 0; tries < 10 && !improved; ++tries) {
      cv::Mat damped = N.clone();
      for (int k = 0; k < 6; ++k) damped.at<double>(k, k) *= 1 + lambda;
      cv::Mat step;
      if (!cv::solve(damped, -b, step, cv::DECOMP_CHOLESKY)) break;
      const cv::Mat r2 = rvec + step.rowRange(0, 3), t2 = tvec + step.rowRange(3, 6);
      const double ssr2 = reprojection_ssr(corners, r2, t2, K, dist);
      if (ssr2 <= ssr) {
        improved = true;
        const bool converged = ssr - ssr2 <= 1e-12 * ssr;
        rvec = r2;
        tvec = t2;
        ssr = ssr2;
        lambda = std::max(lambda / 10, 1e-9);
        if (converged) return;
      } else {
        lambda *= 10;
      }
    }
    if (!improved) return;  // no step lowers the error: at the minimum
  }
}

// The pose's covariance and condition from the projection's Jacobian: the corners' scatter with
// the residual variance, and each intrinsic parameter's sigma through the fit (the pose moves by
// -(J^T J)^-1 J^T dr/dk to make up for a changed parameter k).
void pose_covariance(const TableCorners& corners, const cv::Mat& rvec, const cv::Mat& tvec,
                     const cv::Matx33d& K, const camera::Distortion& dist, double ssr,
                     const std::vector<double>& intrinsics_std, TablePose& pose) {
  // J^T J of the pose and J_pose^T J_intrinsics, summed one placement at a time: the whole
  // Jacobian of 10 000 placements would take 200 MB.
  cv::Mat N = cv::Mat::zeros(6, 6, CV_64F), cross = cv::Mat::zeros(6, 12, CV_64F);
  for_each_placement(corners, [&](const std::vector<cv::Point3f>& part, std::size_t) {
    std::vector<cv::Point2f> projected;
    cv::Mat jacobian;  // 2n x (3 rot + 3 trans + 2 f + 2 c + 8 dist)
    cv::projectPoints(part, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected, jacobian);
    jacobian.convertTo(jacobian, CV_64F);
    const cv::Mat Jp = jacobian.colRange(0, 6);
    N += Jp.t() * Jp;
    cross += Jp.t() * jacobian.colRange(6, 18);
  });
  // Scale the columns to unit norm before the condition: rotations (rad) and translations (m)
  // differ in size, not in how well they are determined.
  cv::Mat scale(6, 1, CV_64F);
  for (int k = 0; k < 6; ++k) scale.at<double>(k) = 1 / std::sqrt(N.at<double>(k, k));
  const cv::Mat Ns = N.mul(scale * scale.t());
  cv::Mat eigenvalues;
  cv::eigen(Ns, eigenvalues);
  pose.rcond = eigenvalues.at<double>(5) / eigenvalues.at<double>(0);
  if (!(pose.rcond >= kMinTableRcond)) return;  // no covariance of an undetermined pose
  const cv::Mat Ninv = N.inv(cv::DECOMP_CHOLESKY);
  const double dof = static_cast<double>(2 * corners.image_points().size()) - 6;
  const cv::Mat noise = Ninv * (dof > 0 ? ssr / dof : 0.0);
  cv::Mat cov = noise.clone();
  // The intrinsic columns of the Jacobian, in intrinsics_std's order (fx fy cx cy k1 .. k6).
  for (std::size_t k = 0; k < intrinsics_std.size() && k < 12; ++k) {
    const cv::Mat g = -Ninv * cross.col(static_cast<int>(k));
    pose.sensitivity.push_back(cv::Vec<double, 6>(g.ptr<double>()));
    const double s = intrinsics_std[k];
    if (s > 0) cov += s * s * (g * g.t());
  }
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      pose.noise_covariance(i, j) = noise.at<double>(i, j);
      pose.covariance(i, j) = cov.at<double>(i, j);
    }
}

// Each placement's own pose (cv::solvePnP on its corners alone): the sum of squared residuals
// that P separate poses leave, the reference against which one common pose is tested, and where
// each pose puts the table point on the camera's optical axis.
std::vector<double> separate_ssr(const TableCorners& corners, const cv::Matx33d& K,
                                 const camera::Distortion& dist, std::vector<cv::Vec3d>& centres) {
  std::vector<double> ssr;
  for_each_placement(corners, [&](const std::vector<cv::Point3f>& part, std::size_t begin) {
    const std::vector<cv::Point2f> found(
        corners.image_points().begin() + static_cast<std::ptrdiff_t>(begin),
        corners.image_points().begin() + static_cast<std::ptrdiff_t>(begin + part.size()));
    cv::Mat rvec, tvec;
    double sum = 0;
    if (cv::solvePnP(part, found, cv::Mat(K), cv::Mat(dist), rvec, tvec, false,
                     cv::SOLVEPNP_ITERATIVE)) {
      cv::solvePnPRefineLM(part, found, cv::Mat(K), cv::Mat(dist), rvec, tvec);
      std::vector<cv::Point2f> projected;
      cv::projectPoints(part, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected);
      for (std::size_t i = 0; i < part.size(); ++i) {
        const cv::Point2f d = projected[i] - found[i];
        sum += d.dot(d);
      }
      // The table point on the optical axis: a board whose row is wrong moves the table frame
      // under it by the error, while a placement's tilt error moves it only by the tilt times
      // the board's distance from the axis.
      cv::Matx33d R;
      cv::Rodrigues(rvec, R);
      const cv::Vec3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
      const cv::Vec3d centre = -(R.t() * t), ray = R.t() * cv::Vec3d(0, 0, 1);
      centres.push_back(std::abs(ray[2]) > 1e-9 ? cv::Vec3d(centre - ray * (centre[2] / ray[2]))
                                                : cv::Vec3d(NAN, NAN, NAN));
    } else {
      sum = std::numeric_limits<double>::infinity();  // then no test against it
      centres.push_back({NAN, NAN, NAN});
    }
    ssr.push_back(sum);
  });
  return ssr;
}

}  // namespace

TablePose estimate_table_pose(const TableCorners& corners, const cv::Matx33d& K,
                              const camera::Distortion& dist,
                              const std::vector<double>& intrinsics_std) {
  const std::string who = "estimate_table_pose: ";
  if (corners.placements() == 0) throw std::invalid_argument(who + "no board placements");
  if (!(K(0, 0) > 0) || !(K(1, 1) > 0))
    throw std::invalid_argument(who + "camera matrix needs fx, fy > 0");
  // The camera does not move between the images and every board's corners are known in the table
  // frame, so all placements are one point set: boards spread over the table pin its tilt far
  // better than one small board (measured: docs/JOINT.md).
  const std::vector<cv::Point3f>& object = corners.object_points();
  const std::vector<cv::Point2f>& found = corners.image_points();
  cv::Mat rvec, tvec;
  solve_pose(corners, K, dist, rvec, tvec);

  TablePose pose;
  cv::Mat Rm;
  cv::Rodrigues(rvec, Rm);
  Rm.convertTo(Rm, CV_64F);
  pose.R = cv::Matx33d(Rm);
  pose.t = cv::Vec3d(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  if (!(pose.t[2] > 0)) throw std::invalid_argument(who + "board found behind the camera");
  std::vector<cv::Point2f> projected;
  cv::projectPoints(object, rvec, tvec, cv::Mat(K), cv::Mat(dist), projected);
  double sum = 0;
  const std::size_t n = corners.placements();
  for (std::size_t p = 0; p < n; ++p) {
    const std::size_t begin = corners.starts()[p];
    const std::size_t end = p + 1 < n ? corners.starts()[p + 1] : found.size();
    double placement = 0;
    for (std::size_t i = begin; i < end; ++i) {
      const cv::Point2f d = projected[i] - found[i];
      placement += d.dot(d);
    }
    sum += placement;
    pose.placement_rms_px.push_back(std::sqrt(placement / static_cast<double>(end - begin)));
  }
  pose.corners = static_cast<int>(found.size());
  pose.rms_px = std::sqrt(sum / static_cast<double>(found.size()));
  pose_covariance(corners, rvec, tvec, K, dist, sum, intrinsics_std, pose);

  // What the corners cannot support: an undetermined pose, or a placement that does not fit the
  // others (a wrong row of table.csv: the board was not where the row says).
  if (!(pose.rcond >= kMinTableRcond)) {
    pose.unsupported =
        "the boards' corners do not determine the table pose (reciprocal condition " +
        sim::format_significant(pose.rcond, 3) + " < " +
        sim::format_significant(kMinTableRcond, 3) + ")";
    return pose;
  }
  if (n < 2) return pose;
  // One pose for every placement against a pose each: the F test of the extra residual that the
  // common pose leaves, per degree of freedom it saves, against the separate fits' residual
  // variance (the corners' noise as the placements themselves show it).
  std::vector<cv::Vec3d> centres;
  const std::vector<double> alone = separate_ssr(corners, K, dist, centres);
  double sum_alone = 0;
  for (double a : alone) sum_alone += a;
  const double dof_saved = 6.0 * static_cast<double>(n - 1);
  const double dof_alone = 2.0 * static_cast<double>(found.size()) - 6.0 * static_cast<double>(n);
  if (!(sum_alone > 0) || !std::isfinite(sum_alone) || dof_alone <= 0) return pose;
  pose.f_statistic = ((sum - sum_alone) / dof_saved) / (sum_alone / dof_alone);
  pose.f_limit = boost::math::quantile(
      boost::math::complement(boost::math::fisher_f(dof_saved, dof_alone), kTableSignificance));
  if (pose.f_statistic > pose.f_limit) {
    char text[320];
    std::snprintf(text, sizeof text,
                  "the placements do not agree on one table pose: F = %.4g over (%g, %g) degrees "
                  "of freedom, above %.4g (significance %g)",
                  pose.f_statistic, dof_saved, dof_alone, pose.f_limit, kTableSignificance);
    pose.unsupported = text;
    // Which row to check: with 3 or more, the placement whose own pose puts the table point on
    // the optical axis farthest from the placements' median (a common pose spreads one wrong
    // row's error over all of them).
    if (n >= 3) {
      std::vector<double> xs, ys, zs;
      for (const cv::Vec3d& c : centres) {
        xs.push_back(c[0]);
        ys.push_back(c[1]);
        zs.push_back(c[2]);
      }
      const cv::Vec3d median(median_of(xs), median_of(ys), median_of(zs));
      std::size_t worst = 0;
      for (std::size_t p = 1; p < n; ++p)
        if (cv::norm(centres[p] - median) > cv::norm(centres[worst] - median)) worst = p;
      std::snprintf(text, sizeof text,
                    "; %s is farthest from the others (alone, it puts the table %.3g mm from "
                    "where their median does): is its row right?",
                    corners.names()[worst].c_str(), cv::norm(centres[worst] - median) * 1e3);
      pose.unsupported += text;
    }
  }
  return pose;
}

namespace {

// Encoder readings modulo a half turn (the outline's period) on a circle of circumference pi:
// how many are at least `distinct` apart, and the shortest arc holding them all.
void reading_spread(const std::vector<double>& readings, double distinct, int& count,
                    double& span) {
  std::vector<double> a;
  for (double r : readings) a.push_back(std::fmod(std::fmod(r, kPi) + kPi, kPi));
  std::sort(a.begin(), a.end());
  count = a.empty() ? 0 : 1;
  double largest_gap = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    const double gap = i + 1 < a.size() ? a[i + 1] - a[i] : a.front() + kPi - a.back();
    if (i + 1 < a.size() && gap >= distinct) ++count;
    largest_gap = std::max(largest_gap, gap);
  }
  // The circle's closing gap merges the first and last groups when they are closer than that.
  if (a.size() > 1 && count > 1 && a.front() + kPi - a.back() < distinct) --count;
  span = a.size() > 1 ? kPi - largest_gap : 0;
}

// How the measured centre and the outline's angle move when the camera moves while the image
// stays: each pixel the hand was measured at is mapped again through a changed camera. Returns
// the 1-sigma of the axis (per coordinate, the larger) and of the mean angle.
std::pair<double, double> camera_sigma(const camera::CameraModel& camera, double plate_height,
                                       cv::Point2d axis, const std::vector<double>& angles,
                                       const CameraUncertainty& u) {
  constexpr double kArm = 0.1;  // m along the hand's x axis: a second point for the angle
  const cv::Point3d axis3(axis.x, axis.y, plate_height);
  const cv::Point2d axis_px = camera.project(axis3);
  std::vector<cv::Point2d> arm_px;
  for (double a : angles)
    arm_px.push_back(camera.project(
        cv::Point3d(axis.x + kArm * std::cos(a), axis.y + kArm * std::sin(a), plate_height)));
  // (axis x, axis y, mean angle) through a camera.
  const auto measure = [&](const camera::CameraModel& c) -> cv::Vec3d {
    const auto a = vision::pixel_to_table(c, axis_px, plate_height);
    if (!a) return {NAN, NAN, NAN};
    double angle = 0;
    for (std::size_t i = 0; i < angles.size(); ++i) {
      const auto q = vision::pixel_to_table(c, arm_px[i], plate_height);
      if (!q) return {NAN, NAN, NAN};
      angle += wrap_half_turn(std::atan2(q->y - a->y, q->x - a->x) - angles[i]);
    }
    return {a->x, a->y, angle / static_cast<double>(angles.size())};
  };
  const auto derivative = [&](auto&& perturb, double h) {
    camera::CameraModel plus = camera, minus = camera;
    perturb(plus, h);
    perturb(minus, -h);
    return (measure(plus) - measure(minus)) * (1 / (2 * h));
  };
  cv::Matx33d cov = cv::Matx33d::zeros();
  // The table pose: (rvec, tvec) with its full covariance.
  cv::Matx<double, 3, 6> J;
  for (int k = 0; k < 6; ++k) {
    const cv::Vec3d d = derivative(
        [&](camera::CameraModel& c, double h) {
          cv::Vec3d r = camera.rvec();
          if (k < 3) {
            r[k] += h;
            cv::Rodrigues(r, c.R);
          } else {
            c.t[k - 3] += h;
          }
        },
        1e-7);
    for (int i = 0; i < 3; ++i) J(i, k) = d[i];
  }
  cov += J * u.pose_noise * J.t();
  // The intrinsics, each on its own (their correlations are not kept in a camera file), with the
  // table pose moving as its fit made it move: d/dk + d/d(pose) d(pose)/dk.
  for (std::size_t k = 0; k < u.intrinsics_std.size() && k < 12; ++k) {
    const double s = u.intrinsics_std[k];
    if (!(s > 0)) continue;
    const cv::Vec3d d = derivative(
        [&](camera::CameraModel& c, double h) {
          if (k == 0) c.K(0, 0) += h;
          if (k == 1) c.K(1, 1) += h;
          if (k == 2) c.K(0, 2) += h;
          if (k == 3) c.K(1, 2) += h;
          if (k >= 4) c.dist[static_cast<int>(k - 4)] += h;
        },
        1e-6 * std::max(s, 1e-3));
    const cv::Vec3d total =
        k < u.pose_sensitivity.size() ? cv::Vec3d(d + J * u.pose_sensitivity[k]) : d;
    cov += s * s * (total * total.t());
  }
  return {std::sqrt(std::max(cov(0, 0), cov(1, 1))), std::sqrt(cov(2, 2))};
}

std::string deg(double rad) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g", rad * 180 / kPi);
  return text;
}

// The tests of JointOptions on a finished fit: what is missing or inconsistent, or "".
std::string joint_support(const JointReport& r, int images, int used, const JointOptions& o) {
  if (images < o.min_distinct_readings)
    return "only " + std::to_string(images) + " image" + (images == 1 ? "" : "s") +
           "; the joint needs " + std::to_string(o.min_distinct_readings) +
           " at distinct encoder readings spread over " + deg(o.min_span_rad) + " deg or more";
  if (used < 3)
    return "only " + std::to_string(used) + " of " + std::to_string(images) +
           " images agree with each other (need 3)";
  if (r.distinct_readings < o.min_distinct_readings)
    return std::to_string(r.distinct_readings) + " distinct encoder reading" +
           (r.distinct_readings == 1 ? "" : "s") + " (at least " + deg(o.distinct_rad) +
           " deg apart) among " + std::to_string(used) + " images; the joint needs " +
           std::to_string(o.min_distinct_readings) + " spread over " + deg(o.min_span_rad) +
           " deg or more";
  if (r.span_rad < o.min_span_rad)
    return "the encoder readings span " + deg(r.span_rad) + " deg; the joint needs " +
           deg(o.min_span_rad) + " deg or more (better a half turn)";
  if (r.chi2 > r.chi2_limit) {
    char text[240];
    std::snprintf(text, sizeof text,
                  "the hand's measured poses do not follow the encoder readings: chi-square %.4g "
                  "over %d degrees of freedom, above %.4g (significance %g; angle RMS %.3g deg, "
                  "centre RMS %.3g mm)",
                  r.chi2, r.dof, r.chi2_limit, o.significance, r.angle_rms * 180 / kPi,
                  r.center_rms * 1e3);
    return text;
  }
  return "";
}

}  // namespace

camera::JointCalibration calibrate_joint(const std::vector<cv::Mat>& images,
                                         const std::vector<double>& encoder_angles,
                                         const camera::CameraModel& camera, double plate_height,
                                         JointReport* report, const JointOptions& options) {
  const std::string who = "calibrate_joint: ";
  if (images.size() != encoder_angles.size())
    throw std::invalid_argument(who + std::to_string(images.size()) + " images but " +
                                std::to_string(encoder_angles.size()) + " encoder angles");
  std::vector<vision::HandPose> poses;
  poses.reserve(images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    try {
      poses.push_back(vision::measure_hand_pose(images[i], camera, plate_height));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(who + "image " + std::to_string(i) + ": " + e.what());
    }
  }
  return calibrate_joint(poses, encoder_angles, camera, plate_height, CameraUncertainty{}, report,
                         options);
}

namespace {

// Outliers (a frame where something else was bright, a mis-read encoder): far from the medians of
// the centres (xs, ys) and of the angle differences (rel) by more than 5 robust sigmas, with floors
// so that a perfect data set rejects nothing. Fewer than 3 images have no median to stand against:
// all are kept; so are all when nothing agrees (the fit of all is then reported, and refused).
std::vector<bool> joint_inliers(const std::vector<double>& xs, const std::vector<double>& ys,
                                const std::vector<double>& rel) {
  const std::size_t count = xs.size();
  const cv::Point2d med(median_of(xs), median_of(ys));
  const double med_rel = median_of(rel);
  std::vector<double> dist_c(count), dist_a(count);
  for (std::size_t i = 0; i < count; ++i) {
    dist_c[i] = std::hypot(xs[i] - med.x, ys[i] - med.y);
    dist_a[i] = std::abs(rel[i] - med_rel);
  }
  const double tol_c = std::max(5 * 1.4826 * median_of(dist_c), 0.5e-3);
  const double tol_a = std::max(5 * 1.4826 * median_of(dist_a), 0.1 * kPi / 180);
  std::vector<bool> inlier(count);
  bool any = false;
  for (std::size_t i = 0; i < count; ++i) {
    inlier[i] = count < 3 || (dist_c[i] <= tol_c && dist_a[i] <= tol_a);
    any = any || inlier[i];
  }
  if (!any) inlier.assign(count, true);
  return inlier;
}

}  // namespace

camera::JointCalibration calibrate_joint(const std::vector<vision::HandPose>& poses,
                                         const std::vector<double>& encoder_angles,
                                         const camera::CameraModel& camera, double plate_height,
                                         const CameraUncertainty& uncertainty, JointReport* report,
                                         const JointOptions& options) {
  const std::string who = "calibrate_joint: ";
  if (poses.size() != encoder_angles.size())
    throw std::invalid_argument(who + std::to_string(poses.size()) + " images but " +
                                std::to_string(encoder_angles.size()) + " encoder angles");
  if (poses.empty()) throw std::invalid_argument(who + "no images");
  for (std::size_t i = 0; i < encoder_angles.size(); ++i)
    if (!std::isfinite(encoder_angles[i]))
      throw std::invalid_argument(who + "encoder angle " + std::to_string(i) + " is not finite");
  const std::size_t count = poses.size();

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
  const std::vector<bool> inlier = joint_inliers(xs, ys, rel);
  const auto used = static_cast<std::size_t>(std::count(inlier.begin(), inlier.end(), true));

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

  JointReport local;
  JointReport& r = report ? *report : local;
  r = JointReport{};
  r.poses = poses;
  r.inlier = inlier;
  r.center_residuals.assign(count, {});
  r.angle_residuals.assign(count, 0);
  // Sums over the inliers: squared residuals, their chi-square terms, and 1 / sigma^2 (the
  // information a weighted mean would have).
  double sc = 0, sa = 0, chi2_c = 0, chi2_a = 0, info_c = 0, info_a = 0;
  std::vector<double> readings, angles;
  for (std::size_t i = 0; i < count; ++i) {
    r.center_residuals[i] = poses[i].center_table - axis;
    r.angle_residuals[i] =
        wrap_half_turn(poses[i].angle - encoder_angles[i] - result.encoder_offset);
    if (!inlier[i]) continue;
    const double dc2 = r.center_residuals[i].dot(r.center_residuals[i]);
    const double da2 = r.angle_residuals[i] * r.angle_residuals[i];
    sc += dc2;
    sa += da2;
    // The measurement sigma: the outline's image noise and the method's model error.
    const double vc = poses[i].sigma_center * poses[i].sigma_center +
                      options.model_sigma_center_m * options.model_sigma_center_m;
    const double va = poses[i].sigma_angle * poses[i].sigma_angle +
                      options.model_sigma_angle_rad * options.model_sigma_angle_rad;
    chi2_c += dc2 / vc;
    chi2_a += da2 / va;
    info_c += 1 / vc;
    info_a += 1 / va;
    readings.push_back(encoder_angles[i]);
    angles.push_back(encoder_angles[i] + result.encoder_offset);
  }
  const double u = static_cast<double>(used);
  r.center_rms = std::sqrt(sc / u);
  r.angle_rms = std::sqrt(sa / u);
  // The images' part of each sigma: the measurement sigma through the mean, scaled by the
  // residuals (the Birge ratio sqrt(chi-square / dof)) where they are larger than it says. The
  // scale is not taken below 1: the model error that the floor stands for is largely common to
  // all images (a bias of the outline method), which their scatter cannot show.
  const double birge_c = used > 1 ? std::sqrt(chi2_c / (2 * (u - 1))) : 1;
  const double birge_a = used > 1 ? std::sqrt(chi2_a / (u - 1)) : 1;
  r.sigma_axis_images = std::max(1.0, birge_c) / std::sqrt(info_c);
  r.sigma_offset_images = std::max(1.0, birge_a) / std::sqrt(info_a);
  const auto [camera_axis, camera_angle] =
      camera_sigma(camera, plate_height, axis, angles, uncertainty);
  r.sigma_axis = std::hypot(r.sigma_axis_images, camera_axis);
  r.sigma_offset = std::hypot(r.sigma_offset_images, camera_angle);
  reading_spread(readings, options.distinct_rad, r.distinct_readings, r.span_rad);
  r.chi2 = chi2_c + chi2_a;
  r.dof = 3 * static_cast<int>(used) - 3;
  r.chi2_limit = r.dof > 0 ? boost::math::quantile(boost::math::complement(
                                 boost::math::chi_squared(r.dof), options.significance))
                           : 0;
  r.unsupported = joint_support(r, static_cast<int>(count), static_cast<int>(used), options);
  return result;
}

}  // namespace flatland::calibration
