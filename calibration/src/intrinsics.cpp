// Intrinsics calibration with Ceres (see intrinsics.hpp). The model is OpenCV's pinhole +
// (k1, k2, p1, p2, k3) distortion, written out in the cost functor so that the result can be
// compared with cv::calibrateCamera number for number.
#include "flatland/calibration/intrinsics.hpp"
#include "flatland/sim/format.hpp"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <sstream>
#include <stdexcept>

namespace flatland::calibration {

namespace {

// ---------------------------------------------------------------- the model

// The intrinsics' parameter block: fx fy cx cy k1 k2 p1 p2 k3, then k4 k5 k6 for the rational
// model (CALIB_RATIONAL_MODEL), which alone uses them.
constexpr int kPlumbBob = 9, kRational = 12;

// OpenCV's projection (cv::projectPoints) of a board point (X, Y, 0) seen with pose
// (rvec, tvec) by a camera with intrinsics `intr` (kPlumbBob or, with `rational`, kRational of
// them). `unit_aspect`: fy is fx (CALIB_FIX_ASPECT_RATIO with a ratio of 1; intr[1] is then held
// and ignored).
template <typename T>
void project(const T* intr, const T* rvec, const T* tvec, double X, double Y, T* uv,
             bool unit_aspect, bool rational) {
  const T p[3] = {T(X), T(Y), T(0)};
  T pc[3];
  ceres::AngleAxisRotatePoint(rvec, p, pc);
  pc[0] += tvec[0];
  pc[1] += tvec[1];
  pc[2] += tvec[2];
  const T x = pc[0] / pc[2], y = pc[1] / pc[2];
  const T r2 = x * x + y * y;
  T radial = T(1) + r2 * (intr[4] + r2 * (intr[5] + r2 * intr[8]));
  if (rational) radial /= T(1) + r2 * (intr[9] + r2 * (intr[10] + r2 * intr[11]));
  const T xd = x * radial + T(2) * intr[6] * x * y + intr[7] * (r2 + T(2) * x * x);
  const T yd = y * radial + intr[6] * (r2 + T(2) * y * y) + T(2) * intr[7] * x * y;
  uv[0] = intr[0] * xd + intr[2];
  uv[1] = (unit_aspect ? intr[0] : intr[1]) * yd + intr[3];
}

// One observed corner: residual = projection - observation, in px.
template <int N>
struct ReprojectionError {
  ReprojectionError(double u, double v, double X, double Y, bool unit_aspect)
      : u(u), v(v), X(X), Y(Y), unit_aspect(unit_aspect) {}

  template <typename T>
  bool operator()(const T* intr, const T* rvec, const T* tvec, T* residual) const {
    T uv[2];
    project(intr, rvec, tvec, X, Y, uv, unit_aspect, N == kRational);
    residual[0] = uv[0] - T(u);
    residual[1] = uv[1] - T(v);
    return true;
  }

  static ceres::CostFunction* create(const cv::Point2f& image, const cv::Point3f& object,
                                     bool unit_aspect) {
    return new ceres::AutoDiffCostFunction<ReprojectionError, 2, N, 3, 3>(
        new ReprojectionError(image.x, image.y, object.x, object.y, unit_aspect));
  }

  double u, v, X, Y;
  bool unit_aspect;
};

struct Pose {
  double r[3], t[3];
};

// Sum of squared reprojection errors of one view, px^2 (intr[1] already equal to intr[0] when
// the aspect ratio is fixed).
double view_ssr(const double* intr, const Pose& pose, const BoardView& view, bool rational) {
  double ssr = 0;
  for (std::size_t i = 0; i < view.image_points.size(); ++i) {
    double uv[2];
    project(intr, pose.r, pose.t, view.object_points[i].x, view.object_points[i].y, uv, false,
            rational);
    const double du = uv[0] - view.image_points[i].x, dv = uv[1] - view.image_points[i].y;
    ssr += du * du + dv * dv;
  }
  return ssr;
}

ceres::Solver::Options solver_options(int max_iterations) {
  ceres::Solver::Options o;
  // The poses only meet the intrinsics: eliminating them (Schur) leaves a 9 x 9 system.
  o.linear_solver_type = ceres::DENSE_SCHUR;
  o.max_num_iterations = max_iterations;
  // Tight enough that the optimum agrees with cv::calibrateCamera's to far below 1e-3 px RMS.
  o.function_tolerance = 1e-12;
  o.gradient_tolerance = 1e-12;
  o.parameter_tolerance = 1e-12;
  o.num_threads = 1;
  o.logging_type = ceres::SILENT;
  return o;
}

// The intrinsics held constant (indices into fx fy cx cy k1 k2 p1 p2 k3), from the options'
// CALIB_FIX_* equivalents.
std::vector<int> held_parameters(const IntrinsicsOptions& o) {
  std::vector<int> held;
  if (o.fix_aspect_ratio) held.push_back(1);
  if (o.fix_principal_point) held.insert(held.end(), {2, 3});
  if (o.zero_tangent_dist) held.insert(held.end(), {6, 7});
  if (o.fix_k3) held.push_back(8);
  return held;
}

// Solve for intrinsics and the poses of views[i] for every i in `which`.
void solve(double* intr, std::vector<Pose>& poses, const std::vector<BoardView>& views,
           const std::vector<int>& which, ceres::LossFunction* loss, const IntrinsicsOptions& io,
           ceres::Problem* keep = nullptr) {
  std::unique_ptr<ceres::Problem> owned;
  ceres::Problem::Options po;
  // One loss object is shared by every residual: the problem must not delete it per block.
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  if (!keep) owned = std::make_unique<ceres::Problem>(po);
  ceres::Problem& problem = keep ? *keep : *owned;
  for (int i : which) {
    const BoardView& v = views[i];
    for (std::size_t k = 0; k < v.image_points.size(); ++k)
      problem.AddResidualBlock(
          io.rational_model ? ReprojectionError<kRational>::create(
                                  v.image_points[k], v.object_points[k], io.fix_aspect_ratio)
                            : ReprojectionError<kPlumbBob>::create(
                                  v.image_points[k], v.object_points[k], io.fix_aspect_ratio),
          loss, intr, poses[i].r, poses[i].t);
  }
  const std::vector<int> held = held_parameters(io);
  if (!held.empty())
    problem.SetManifold(intr,
                        new ceres::SubsetManifold(io.rational_model ? kRational : kPlumbBob, held));
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options(io.max_iterations), &problem, &summary);
  if (io.fix_aspect_ratio) intr[1] = intr[0];
  if (!summary.IsSolutionUsable())
    throw std::runtime_error("calibration: Ceres failed: " + summary.message);
}

std::string size_text(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

}  // namespace

// ---------------------------------------------------------------- detection

std::optional<BoardView> detect_board(const cv::Mat& image, const camera::Board& board,
                                      const std::string& name) {
  if (image.empty()) return std::nullopt;
  cv::Mat gray;
  if (image.channels() == 3)
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  else if (image.channels() == 4)
    cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  else
    gray = image;
  if (gray.depth() != CV_8U) gray.convertTo(gray, CV_8U);

  BoardView view;
  view.name = name;
  view.image_size = gray.size();
  const std::vector<cv::Point3f> all = board.corners();
  std::vector<int> ids;
  if (board.kind == camera::Board::Kind::kChessboard) {
    const cv::Size pattern = board.pattern_size();
    if (!cv::findChessboardCorners(gray, pattern, view.image_points,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
      return std::nullopt;
    for (int k = 0; k < pattern.area(); ++k) ids.push_back(k);
  } else {
    const auto dict = cv::aruco::getPredefinedDictionary(
        cv::aruco::PREDEFINED_DICTIONARY_NAME(*camera::aruco_dictionary_id(board.dictionary)));
    const auto cv_board = cv::aruco::CharucoBoard::create(board.squares_x, board.squares_y,
                                                          static_cast<float>(board.square),
                                                          static_cast<float>(board.marker), dict);
    std::vector<std::vector<cv::Point2f>> marker_corners;
    std::vector<int> marker_ids;
    cv::aruco::detectMarkers(gray, dict, marker_corners, marker_ids);
    if (marker_ids.empty()) return std::nullopt;
    cv::aruco::interpolateCornersCharuco(marker_corners, marker_ids, gray, cv_board,
                                         view.image_points, ids);
    // Fewer corners than this cannot constrain a pose plus anything of the intrinsics.
    if (ids.size() < 6) return std::nullopt;
  }
  // Sub-pixel refinement. A larger window averages out more of the aliasing and noise (measured
  // on rendered boards: corner RMS 0.20 px with a 5 x 5 window, 0.13 px with 17 x 17), but it
  // must hold only the corner's own four squares: 0.4 of the smallest spacing of neighbouring
  // corners for a chessboard; for ChArUco it must also stay clear of the markers, which sit
  // (square - marker) / 2 from each corner. OpenCV 4.6's interpolated ChArUco corners are
  // ~(+0.5, +0.5) px off and need this refinement anyway.
  double spacing = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < view.image_points.size(); ++i)
    for (std::size_t j = i + 1; j < view.image_points.size(); ++j)
      spacing = std::min(spacing, cv::norm(view.image_points[i] - view.image_points[j]));
  const double reach = board.kind == camera::Board::Kind::kChessboard
                           ? 0.4 * spacing
                           : spacing * (board.square - board.marker) / (2 * board.square) - 1;
  const int half = std::clamp(static_cast<int>(reach), 2, 10);
  cv::cornerSubPix(gray, view.image_points, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  for (int id : ids) view.object_points.push_back(all.at(static_cast<std::size_t>(id)));
  return view;
}

// ---------------------------------------------------------------- result

std::array<double, 9> IntrinsicsResult::params() const {
  return {K(0, 0), K(1, 1), K(0, 2), K(1, 2), dist[0], dist[1], dist[2], dist[3], dist[4]};
}

int IntrinsicsResult::views_used() const {
  return static_cast<int>(std::count(used.begin(), used.end(), true));
}

camera::CameraModel IntrinsicsResult::camera() const {
  camera::CameraModel m;
  m.width = image_size.width;
  m.height = image_size.height;
  m.K = K;
  m.dist = dist;
  return m;
}

camera::CalibrationReport IntrinsicsResult::report() const {
  camera::CalibrationReport r;
  r.rms_px = rms_px;
  for (std::size_t i = 0; i < used.size(); ++i)
    if (used[i]) r.view_rms_px.push_back(view_rms_px[i]);
  r.views_used = views_used();
  r.views_rejected = rejected;
  r.std = std;
  if (rational) r.std_rational = std_rational;
  return r;
}

// ---------------------------------------------------------------- calibration

IntrinsicsResult calibrate_intrinsics(const std::vector<BoardView>& views,
                                      const IntrinsicsOptions& options) {
  const auto label = [&](std::size_t i) {
    return views[i].name.empty() ? "view " + std::to_string(i) : views[i].name;
  };
  if (views.empty()) throw std::invalid_argument("no views to calibrate from");
  for (std::size_t i = 1; i < views.size(); ++i)
    if (views[i].image_size != views[0].image_size)
      throw std::invalid_argument("mixed image sizes: " + label(0) + " is " +
                                  size_text(views[0].image_size) + ", " + label(i) + " is " +
                                  size_text(views[i].image_size));
  const cv::Size size = views[0].image_size;
  if (size.width <= 0 || size.height <= 0) throw std::invalid_argument("empty image size");

  IntrinsicsResult result;
  result.image_size = size;
  const std::size_t n = views.size();
  result.used.assign(n, false);
  result.view_rms_px.assign(n, std::numeric_limits<double>::quiet_NaN());
  result.rvecs.assign(n, cv::Vec3d(0, 0, 0));
  result.tvecs.assign(n, cv::Vec3d(0, 0, 0));

  std::vector<int> usable;
  for (std::size_t i = 0; i < n; ++i) {
    if (views[i].image_points.size() != views[i].object_points.size())
      throw std::invalid_argument(label(i) + ": image and object point counts differ");
    if (views[i].image_points.size() < 6)
      result.rejected.push_back(label(i) + ": fewer than 6 corners");
    else
      usable.push_back(static_cast<int>(i));
  }
  if (usable.size() < 3)
    throw std::invalid_argument("fewer than 3 usable views (got " + std::to_string(usable.size()) +
                                "); calibration needs at least 3 views of the board");

  // ---- initial guess, independent of cv::calibrateCamera: Zhang's closed form for the focal
  // length (principal point at the centre), zero distortion, a PnP pose per view.
  std::vector<std::vector<cv::Point3f>> obj;
  std::vector<std::vector<cv::Point2f>> img;
  for (int i : usable) {
    obj.push_back(views[i].object_points);
    img.push_back(views[i].image_points);
  }
  cv::Mat K0 = cv::initCameraMatrix2D(obj, img, size, 1.0);
  const double f_fallback = std::max(size.width, size.height);
  double f0 = K0.at<double>(0, 0);
  // Near-degenerate view sets make the closed form blow up; any sane focal length will do for
  // the tilt test and as a start (the solve is well conditioned when tilted views exist).
  if (!std::isfinite(f0) || f0 < 0.1 * f_fallback || f0 > 100 * f_fallback) f0 = f_fallback;
  const cv::Matx33d Kinit(f0, 0, (size.width - 1) * 0.5, 0, f0, (size.height - 1) * 0.5, 0, 0, 1);

  std::vector<Pose> poses(n);
  double max_tilt = 0;
  for (int i : usable) {
    cv::Vec3d r, t;
    // IPPE is the planar PnP solver: exact for a plane, no initial guess needed.
    if (!cv::solvePnP(views[i].object_points, views[i].image_points, Kinit, cv::noArray(), r, t,
                      false, cv::SOLVEPNP_IPPE))
      cv::solvePnP(views[i].object_points, views[i].image_points, Kinit, cv::noArray(), r, t);
    cv::Matx33d R;
    cv::Rodrigues(r, R);
    // Tilt = angle between the board's normal and the optical axis. A board parallel to the
    // image plane gives no constraint on the focal length (Zhang 2000, section 3.3), wherever it
    // is in the image; the image of such a board is a similarity of it for any focal length, so
    // the rough K above is enough to tell.
    const double tilt = std::acos(std::min(1.0, std::abs(R(2, 2)))) * 180.0 / std::numbers::pi;
    max_tilt = std::max(max_tilt, tilt);
    for (int k = 0; k < 3; ++k) {
      poses[i].r[k] = r[k];
      poses[i].t[k] = t[k];
    }
  }
  if (max_tilt < options.min_tilt_deg)
    throw std::invalid_argument(
        "focal length unobservable: all views are fronto-parallel (largest board tilt " +
        sim::format_significant(max_tilt, 2) + " deg, need views tilted by " +
        sim::format_significant(options.min_tilt_deg, 2) + " deg or more)");

  double intr[kRational] = {f0, f0, Kinit(0, 2), Kinit(1, 2), 0, 0, 0, 0, 0, 0, 0, 0};
  const bool rational = options.rational_model;
  result.rational = rational;

  // ---- pass 1: robust (Huber) so that a bad view or a few bad corners cannot drag the solution.
  ceres::HuberLoss huber(options.loss_scale_px);
  solve(intr, poses, views, usable, &huber, options);

  std::vector<double> rms1;
  for (int i : usable) {
    const double r =
        std::sqrt(view_ssr(intr, poses[i], views[i], rational) / views[i].image_points.size());
    result.view_rms_px[i] = r;
    rms1.push_back(r);
  }
  std::vector<double> sorted = rms1;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double median = sorted[sorted.size() / 2];
  const double threshold = std::max(options.outlier_factor * median, options.outlier_floor_px);
  std::vector<int> inliers;
  for (int i : usable) {
    if (result.view_rms_px[i] > threshold)
      result.rejected.push_back(label(i) + ": outlier, RMS " +
                                sim::format_significant(result.view_rms_px[i], 3) + " px > " +
                                sim::format_significant(threshold, 3) + " px");
    else
      inliers.push_back(i);
  }
  if (inliers.size() < 3)
    throw std::invalid_argument("fewer than 3 usable views after dropping outliers (" +
                                std::to_string(inliers.size()) + " of " +
                                std::to_string(usable.size()) + " remain)");

  // ---- pass 2: plain least squares on the inliers: the maximum-likelihood estimate for
  // Gaussian corner noise, and what the covariance below assumes.
  ceres::Problem::Options po;
  po.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(po);
  solve(intr, poses, views, inliers, nullptr, options, &problem);

  double ssr = 0;
  std::size_t points = 0;
  for (int i : inliers) {
    const double s = view_ssr(intr, poses[i], views[i], rational);
    ssr += s;
    points += views[i].image_points.size();
    result.view_rms_px[i] = std::sqrt(s / views[i].image_points.size());
    result.used[i] = true;
  }
  for (std::size_t i = 0; i < n; ++i) {
    result.rvecs[i] = cv::Vec3d(poses[i].r[0], poses[i].r[1], poses[i].r[2]);
    result.tvecs[i] = cv::Vec3d(poses[i].t[0], poses[i].t[1], poses[i].t[2]);
  }
  // Same definition as cv::calibrateCamera's return value: sqrt(SSR / number of points).
  result.rms_px = std::sqrt(ssr / static_cast<double>(points));
  result.K = cv::Matx33d(intr[0], 0, intr[2], 0, intr[1], intr[3], 0, 0, 1);
  for (int k = 0; k < 5; ++k) result.dist[k] = intr[4 + k];
  if (rational)
    for (int k = 0; k < 3; ++k) result.dist[5 + k] = intr[9 + k];

  result.std.fill(std::numeric_limits<double>::quiet_NaN());
  result.std_rational.fill(std::numeric_limits<double>::quiet_NaN());
  if (options.compute_covariance) {
    // (J^T J)^-1 of the intrinsics' block, scaled by the residual variance estimated from the fit
    // itself (sigma^2 = SSR / (2N - p)): the image noise need not be known.
    const int block = rational ? kRational : kPlumbBob;
    const double free_parameters = block - static_cast<double>(held_parameters(options).size());
    const double dof = 2.0 * static_cast<double>(points) - free_parameters - 6.0 * inliers.size();
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::SPARSE_QR;
    co.num_threads = 1;
    ceres::Covariance covariance(co);
    std::vector<std::pair<const double*, const double*>> blocks = {{intr, intr}};
    double cov[kRational * kRational];
    if (dof > 0 && covariance.Compute(blocks, &problem) &&
        covariance.GetCovarianceBlock(intr, intr, cov)) {
      const double sigma2 = ssr / dof;
      const auto sd = [&](int k) { return std::sqrt(std::max(0.0, cov[k * block + k] * sigma2)); };
      for (int k = 0; k < kPlumbBob; ++k) result.std[k] = sd(k);
      if (rational)
        for (int k = 0; k < 3; ++k) result.std_rational[k] = sd(kPlumbBob + k);
    }
  }
  return result;
}

}  // namespace flatland::calibration

namespace flatland::calibration {

void IntrinsicsOptions::parse_fixed(const std::string& list) {
  std::stringstream ss(list);
  for (std::string name; std::getline(ss, name, ',');) {
    if (name == "k3")
      fix_k3 = true;
    else if (name == "tangential")
      zero_tangent_dist = true;
    else if (name == "aspect")
      fix_aspect_ratio = true;
    else if (name == "principal-point")
      fix_principal_point = true;
    else if (name.empty())
      continue;
    else
      throw std::invalid_argument("--fix: unknown parameter '" + name +
                                  "' (k3, tangential, aspect, principal-point)");
  }
}

std::vector<std::string> IntrinsicsOptions::fixed_names() const {
  std::vector<std::string> out;
  if (fix_k3) out.push_back("k3");
  if (zero_tangent_dist) out.push_back("tangential");
  if (fix_aspect_ratio) out.push_back("aspect");
  if (fix_principal_point) out.push_back("principal-point");
  return out;
}

}  // namespace flatland::calibration
