// flatland calibrate: camera intrinsics and distortion from images of a planar board (chessboard
// or ChArUco), written as a camera file (OpenCV YAML, ROS camera_info layout).
#include "common.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/calibration/joint.hpp"
#include "flatland/calibration/report.hpp"
#include "flatland/calibration/session.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/vision/hand_pose.hpp"
#include "flatland/vision/image_file.hpp"

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <numbers>
#include <optional>
#include <sstream>

namespace flatland::app {

namespace {

struct CalibrateOptions {
  std::vector<std::string> images;
  std::string board, out, camera_name = "flatland";
  std::string camera, table, table_board, joint, scene, fix, report;
  bool force = false;
  bool rational = false;
  bool json = false;
  CLI::Option* camera_name_opt = nullptr;
};

const char* kParamNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
const char* kRationalNames[3] = {"k4", "k5", "k6"};

void warn(const std::string& message) { std::cerr << "flatland: warning: " << message << "\n"; }

std::string describe(const camera::Board& b) {
  const cv::Size p = b.pattern_size();
  const std::string inner = std::to_string(p.width) + "x" + std::to_string(p.height);
  const std::string squares = std::to_string(b.squares_x) + "x" + std::to_string(b.squares_y);
  return b.kind == camera::Board::Kind::kChessboard
             ? "a chessboard of " + inner + " inner corners (" + squares + " squares)"
             : "a ChArUco board of " + squares + " squares (" + inner + " inner corners)";
}

// Searching every image again would double a failure that already took a while; a miscounted
// board shows in the first few.
constexpr std::size_t kHintImages = 3;

// The board was found nowhere: say what was searched for and, if the same numbers in the other
// count find a board, say so (people count a chessboard's squares, or a ChArUco board's corners).
std::string board_found_nowhere(const camera::Board& board,
                                const std::vector<std::string>& readable) {
  std::string message = "board found in no image (" + std::to_string(readable.size()) +
                        " images searched for " + describe(board) + ", --board " +
                        board.notation() + ")";
  const std::optional<camera::Board> other = board.other_count();
  if (!other) return message;
  std::size_t tried = 0, found = 0;
  for (const std::string& f : readable) {
    if (tried == kHintImages) break;
    std::string why;
    const cv::Mat image = vision::read_image_file(f, cv::IMREAD_GRAYSCALE, why);
    ++tried;
    if (!image.empty() && calibration::detect_board(image, *other, f)) ++found;
  }
  if (found == 0) return message;
  const bool chessboard = board.kind == camera::Board::Kind::kChessboard;
  return message + "; but " + describe(*other) + " is in " + std::to_string(found) +
         " of the first " + std::to_string(tried) + ": flatland counts " +
         (chessboard ? "a chessboard by its inner corners, as OpenCV's patternSize does"
                     : "a ChArUco board by its squares, as cv::aruco::CharucoBoard does") +
         "; try --board " + other->notation();
}

// The intrinsics' standard deviations (fx fy cx cy k1 k2 p1 p2 k3 [k4 k5 k6]) from the file's
// report, for the table pose's and the joint's sigma; empty when the file has none (render's
// camera file: the scene's exact camera).
std::vector<double> intrinsics_std(const camera::CameraFile& file) {
  if (!file.report) return {};
  std::vector<double> s(file.report->std.begin(), file.report->std.end());
  if (file.report->std_rational)
    s.insert(s.end(), file.report->std_rational->begin(), file.report->std_rational->end());
  return s;
}

// A section whose data do not support its result: exit 1 naming what is missing or
// inconsistent, or with --force a warning and the mark in the camera file.
void refuse_or_mark(const CalibrateOptions& o, const std::string& section,
                    const std::string& option, const std::string& why, camera::CameraFile& file) {
  if (!o.force)
    throw std::runtime_error(option + ": " + why +
                             "; nothing written (--force writes it anyway, marked unsupported)");
  warn(option + ": " + why + "; written anyway (--force), marked unsupported in the camera file");
  file.unsupported.push_back(section + ": " + why);
}

// A new fit of `section` replaces the old one's mark (and marks of what it invalidates).
void drop_marks(camera::CameraFile& file, const std::vector<std::string>& sections) {
  std::erase_if(file.unsupported, [&](const std::string& mark) {
    for (const std::string& s : sections)
      if (mark.rfind(s + ":", 0) == 0) return true;
    return false;
  });
}

// ---- intrinsics: --images and --board

// The readable images and the views in which the board was found; the image size goes to `size`.
struct DetectedViews {
  std::vector<calibration::BoardView> views;
  std::vector<std::string> not_found;  // "<file>: board not found"
  cv::Size size;
};

DetectedViews detect_views(const std::vector<std::string>& files, const camera::Board& board) {
  DetectedViews d;
  std::string first_sized;
  std::vector<std::string> readable;
  for (const std::string& f : files) {
    std::string why;
    const cv::Mat image = vision::read_image_file(f, cv::IMREAD_GRAYSCALE, why);
    if (image.empty()) {
      warn("skipping " + f + ": " + why);
      continue;
    }
    readable.push_back(f);
    if (first_sized.empty()) {
      first_sized = f;
      d.size = image.size();
    } else if (image.size() != d.size) {
      throw UsageError("mixed image sizes: " + first_sized + " is " + std::to_string(d.size.width) +
                       "x" + std::to_string(d.size.height) + ", " + f + " is " +
                       std::to_string(image.cols) + "x" + std::to_string(image.rows));
    }
    if (auto v = calibration::detect_board(image, board, f)) {
      d.views.push_back(std::move(*v));
    } else {
      warn("board not found in " + f + "; skipped");
      d.not_found.push_back(f + ": board not found");
    }
  }
  if (readable.empty())
    throw UsageError("--images: none of the " + std::to_string(files.size()) +
                     " files is a readable image");
  if (d.views.empty()) throw UsageError(board_found_nowhere(board, readable));
  if (d.views.size() < 3)
    throw UsageError("fewer than 3 usable views: the board was found in " +
                     std::to_string(d.views.size()) + " of " + std::to_string(readable.size()) +
                     " images; calibration needs at least 3");
  return d;
}

// Six significant digits: far below the uncertainties, unlike format_number's round trip.
std::string g6(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return std::string(buf);
}

// --report DIR: each view with its residual arrows, and the coverage map, staged as PNG.
void stage_report(OutputSet& outputs, const fs::path& dir, const calibration::IntrinsicsResult& r,
                  const std::vector<calibration::BoardView>& views, Json& j) {
  std::vector<unsigned char> png;
  Json pictures = Json::array();
  for (std::size_t i = 0; i < views.size(); ++i) {
    std::string why;
    const cv::Mat image = vision::read_image_file(views[i].name, cv::IMREAD_COLOR, why);
    if (image.empty()) throw std::runtime_error(views[i].name + ": cannot be read again: " + why);
    char name[32];
    std::snprintf(name, sizeof name, "view_%03zu_", i);
    const fs::path out = dir / (name + fs::path(views[i].name).stem().string() + ".png");
    if (!cv::imencode(".png", calibration::draw_view_residuals(image, r, views, i), png))
      throw std::runtime_error("cannot encode " + out.string());
    outputs.stage(out, std::string(png.begin(), png.end()));
    pictures.push_back(out.string());
  }
  if (!cv::imencode(".png", calibration::draw_coverage(r, views), png))
    throw std::runtime_error("cannot encode the coverage map");
  outputs.stage(dir / "coverage.png", std::string(png.begin(), png.end()));
  j["report"] = {{"views", pictures},
                 {"coverage", (dir / "coverage.png").string()},
                 {"coverage_fraction", calibration::coverage_fraction(r, views)}};
}

void intrinsics_section(const CalibrateOptions& o, const camera::Board& board,
                        const calibration::IntrinsicsOptions& options, camera::CameraFile& file,
                        Json& j, std::ostream& os, OutputSet& outputs) {
  const DetectedViews d = detect_views(expand_file_patterns(o.images, "--images"), board);
  const calibration::IntrinsicsResult r = calibration::calibrate_intrinsics(d.views, options);
  file.camera = r.camera();
  camera::CalibrationReport report = r.report();
  report.views_rejected.insert(report.views_rejected.begin(), d.not_found.begin(),
                               d.not_found.end());
  file.report = report;
  file.rational_model = r.rational;
  if (!o.report.empty()) stage_report(outputs, o.report, r, d.views, j);
  std::string undetermined;
  for (int k = 0; k < 9; ++k)
    if (std::isnan(r.std[static_cast<std::size_t>(k)]))
      undetermined += (undetermined.empty() ? "" : ", ") + std::string(kParamNames[k]);
  if (!undetermined.empty())
    refuse_or_mark(o, "intrinsics", "--images",
                   "the views do not determine " + undetermined +
                       " (the covariance of the intrinsics is rank deficient)",
                   file);

  const std::array<double, 9> p = r.params();
  j["rms_px"] = number(r.rms_px);
  j["fx"] = p[0];
  j["fy"] = p[1];
  j["cx"] = p[2];
  j["cy"] = p[3];
  j["dist"] = Json::array();
  for (int k = 4; k < 9; ++k) j["dist"].push_back(p[k]);
  j["std"] = Json::object();
  for (int k = 0; k < 9; ++k) j["std"][kParamNames[k]] = number(r.std[k]);
  j["model"] = r.rational ? "rational_polynomial" : "plumb_bob";
  if (r.rational)
    for (int k = 0; k < 3; ++k) {
      j["dist"].push_back(r.dist[5 + k]);
      j["std"][kRationalNames[k]] = number(r.std_rational[static_cast<std::size_t>(k)]);
    }
  j["fixed"] = options.fixed_names();
  j["views_used"] = r.views_used();
  j["views_rejected"] = report.views_rejected;
  j["view_rms_px"] = Json::object();
  for (std::size_t i = 0; i < d.views.size(); ++i)
    if (r.used[i]) j["view_rms_px"][d.views[i].name] = number(r.view_rms_px[i]);

  os << "  intrinsics         " << d.views.size() << " views of " << board.notation() << ", "
     << r.image_size.width << " x " << r.image_size.height << " px\n";
  os << "  rms                " << g6(r.rms_px) << " px over " << r.views_used() << " views\n";
  if (!options.fixed_names().empty()) {
    std::string held;
    for (const std::string& f : options.fixed_names()) held += (held.empty() ? "" : ", ") + f;
    os << "  held               " << held << "\n";
  }
  for (int k = 0; k < 9; ++k)
    os << "  " << kParamNames[k] << std::string(17, ' ') << g6(p[k]) << " +- " << g6(r.std[k])
       << (k < 4 ? " px" : "") << "\n";
  if (r.rational)
    for (int k = 0; k < 3; ++k)
      os << "  " << kRationalNames[k] << std::string(17, ' ') << g6(r.dist[5 + k]) << " +- "
         << g6(r.std_rational[static_cast<std::size_t>(k)]) << "\n";
  for (const std::string& s : report.views_rejected) os << "  rejected           " << s << "\n";
  if (!o.report.empty())
    os << "  coverage           " << g6(100 * calibration::coverage_fraction(r, d.views))
       << " % of the image's 8 x 6 cells; "
       << "pictures in " << o.report << "\n";
}

// ---- table pose and joint: images listed in a CSV, each the camera's size

cv::Mat read_listed_image(const std::string& option, const std::string& path,
                          const camera::CameraModel& camera) {
  std::string why;
  const cv::Mat image = vision::read_image_file(path, cv::IMREAD_COLOR, why);
  if (image.empty()) throw UsageError(option + ": " + path + ": " + why);
  if (image.cols != camera.width || image.rows != camera.height)
    throw UsageError(option + ": " + path + " is " + std::to_string(image.cols) + " x " +
                     std::to_string(image.rows) + " px but the camera is " +
                     std::to_string(camera.width) + " x " + std::to_string(camera.height) + " px");
  return image;
}

// The table pose from the listed images, read one at a time: each image's corners are kept and
// the image dropped, so memory does not grow with the rows.
void table_section(const CalibrateOptions& o, const camera::Board& board,
                   const std::vector<calibration::TablePlacement>& rows, camera::CameraFile& file,
                   Json& j, std::ostream& os) {
  calibration::TableCorners corners;
  calibration::TablePose pose;
  try {
    for (const calibration::TablePlacement& p : rows)
      corners.add(read_listed_image("--table", p.image, file.camera), p.placed(board), p.image);
    pose = calibration::estimate_table_pose(corners, file.camera.K, file.camera.dist,
                                            intrinsics_std(file));
  } catch (const std::invalid_argument& e) {
    if (dynamic_cast<const UsageError*>(&e)) throw;
    throw UsageError("--table " + o.table + ": " + e.what());
  }
  file.camera.R = pose.R;
  file.camera.t = pose.t;
  file.has_table_pose = true;
  camera::TablePoseReport report{pose.rms_px, pose.corners, static_cast<int>(rows.size()), {}, {}};
  std::array<double, 36> cov{};
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c)
      cov[static_cast<std::size_t>(6 * r + c)] = pose.noise_covariance(r, c);
  report.covariance = cov;
  for (const cv::Vec<double, 6>& g : pose.sensitivity)
    report.sensitivity.insert(report.sensitivity.end(), g.val, g.val + 6);
  file.table_report = report;
  if (!pose.unsupported.empty())
    refuse_or_mark(o, "table", "--table " + o.table, pose.unsupported, file);
  const cv::Vec3d rv = file.camera.rvec(), c = file.camera.position_in_table();
  const cv::Vec3d sc = pose.sigma_camera_in_table();
  Json placement_rms = Json::array();
  for (double rms : pose.placement_rms_px) placement_rms.push_back(number(rms));
  j["table"] = {{"rms_px", number(pose.rms_px)},
                {"corners", pose.corners},
                {"images", rows.size()},
                {"placement_rms_px", placement_rms},
                {"rvec", {rv[0], rv[1], rv[2]}},
                {"tvec", {pose.t[0], pose.t[1], pose.t[2]}},
                {"camera_in_table", {c[0], c[1], c[2]}},
                {"sigma_camera_in_table", {number(sc[0]), number(sc[1]), number(sc[2])}},
                {"rcond", number(pose.rcond)},
                {"f_statistic", number(pose.f_statistic)},
                {"f_limit", number(pose.f_limit)},
                {"unsupported", pose.unsupported.empty() ? Json() : Json(pose.unsupported)}};
  os << "  table pose         " << rows.size() << " placements of " << board.notation() << ", "
     << pose.corners << " corners, rms " << g6(pose.rms_px) << " px\n"
     << "  camera centre      (" << g6(c[0]) << ", " << g6(c[1]) << ", " << g6(c[2]) << ") m +- ("
     << g6(sc[0]) << ", " << g6(sc[1]) << ", " << g6(sc[2]) << ") m in the table frame\n";
  if (!pose.unsupported.empty()) os << "  UNSUPPORTED        " << pose.unsupported << "\n";
}

// The joint from the listed images, read and measured one at a time (the hand's pose kept, the
// image dropped).
void joint_section(const CalibrateOptions& o, const Scene& scene,
                   const std::vector<calibration::JointImage>& rows, camera::CameraFile& file,
                   Json& j, std::ostream& os) {
  std::vector<vision::HandPose> poses;
  std::vector<double> encoder;
  const double plate = scene.render.hand_thickness;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const cv::Mat image = read_listed_image("--joint", rows[i].image, file.camera);
    try {
      poses.push_back(vision::measure_hand_pose(image, file.camera, plate));
    } catch (const std::invalid_argument& e) {
      throw UsageError("--joint " + o.joint + ": calibrate_joint: image " + std::to_string(i) +
                       ": " + e.what());
    }
    encoder.push_back(rows[i].encoder);
  }
  calibration::CameraUncertainty uncertainty;
  uncertainty.intrinsics_std = intrinsics_std(file);
  if (file.table_report && file.table_report->covariance)
    uncertainty.pose_noise = cv::Matx<double, 6, 6>(file.table_report->covariance->data());
  if (file.table_report)
    for (std::size_t k = 0; k + 6 <= file.table_report->sensitivity.size(); k += 6)
      uncertainty.pose_sensitivity.emplace_back(file.table_report->sensitivity.data() + k);
  calibration::JointReport report;
  camera::JointCalibration joint;
  try {
    joint = calibration::calibrate_joint(poses, encoder, file.camera, plate, uncertainty, &report);
  } catch (const std::invalid_argument& e) {
    throw UsageError("--joint " + o.joint + ": " + e.what());
  }
  file.joint = joint;
  camera::JointFitReport fit;
  fit.images = static_cast<int>(rows.size());
  fit.inliers = static_cast<int>(std::count(report.inlier.begin(), report.inlier.end(), true));
  fit.center_rms_m = report.center_rms;
  fit.angle_rms_rad = report.angle_rms;
  fit.sigma_axis_m = report.sigma_axis;
  fit.sigma_offset_rad = report.sigma_offset;
  file.joint_report = fit;
  if (!report.unsupported.empty())
    refuse_or_mark(o, "joint", "--joint " + o.joint, report.unsupported, file);
  Json outliers = Json::array();
  for (std::size_t i = 0; i < rows.size(); ++i)
    if (!report.inlier[i]) outliers.push_back(rows[i].image);
  j["joint"] = {{"axis", {joint.axis_table.x, joint.axis_table.y}},
                {"encoder_offset_rad", joint.encoder_offset},
                {"images", fit.images},
                {"inliers", fit.inliers},
                {"outliers", outliers},
                {"center_rms_m", number(fit.center_rms_m)},
                {"angle_rms_rad", number(fit.angle_rms_rad)},
                {"sigma_axis_m", number(fit.sigma_axis_m)},
                {"sigma_offset_rad", number(fit.sigma_offset_rad)},
                {"distinct_readings", report.distinct_readings},
                {"span_rad", number(report.span_rad)},
                {"chi2", number(report.chi2)},
                {"dof", report.dof},
                {"chi2_limit", number(report.chi2_limit)},
                {"unsupported", report.unsupported.empty() ? Json() : Json(report.unsupported)}};
  constexpr double kToDeg = 180 / std::numbers::pi;
  os << "  joint axis         (" << g6(joint.axis_table.x * 1e3) << ", "
     << g6(joint.axis_table.y * 1e3) << ") mm +- " << g6(fit.sigma_axis_m * 1e3) << " mm\n"
     << "  encoder offset     " << g6(joint.encoder_offset * kToDeg) << " deg +- "
     << g6(fit.sigma_offset_rad * kToDeg) << " deg (" << fit.inliers << " of " << fit.images
     << " images, angle rms " << g6(fit.angle_rms_rad * kToDeg) << " deg)\n"
     << "  joint data         " << report.distinct_readings << " distinct readings over "
     << g6(report.span_rad * kToDeg) << " deg, chi-square " << g6(report.chi2) << " over "
     << report.dof << " dof (limit " << g6(report.chi2_limit) << ")\n";
  for (const auto& name : outliers)
    os << "  outlier            " << name.get<std::string>() << "\n";
  if (!report.unsupported.empty()) os << "  UNSUPPORTED        " << report.unsupported << "\n";
}

// Whether the output is the --camera file itself (then it is replaced without --force).
bool updates_in_place(const CalibrateOptions& o, const fs::path& out) {
  std::error_code ec;
  return !o.camera.empty() && (out == fs::path(o.camera) || fs::equivalent(out, o.camera, ec));
}

// Where the camera file goes: --out, or --camera updated in place.
fs::path output_path(const CalibrateOptions& o) {
  if (o.out.empty()) {
    if (o.camera.empty())
      throw UsageError("--out: required (FILE.yaml), or --camera FILE to update that file");
    return o.camera;
  }
  const fs::path out = o.out;
  if (o.out.back() == '/' || fs::is_directory(out))
    throw UsageError("--out: must be a file (camera.yaml), got '" + o.out + "'");
  if (!updates_in_place(o, out)) check_output_file("--out", out, o.force);
  return out;
}

void run_calibrate(const CalibrateOptions& o) {
  // ---- bad input first: what to calibrate, its inputs, the output
  if (o.images.empty() && o.table.empty() && o.joint.empty())
    throw UsageError(
        "nothing to calibrate: give --images (intrinsics), --table (the table pose) "
        "or --joint (the joint axis), or several");
  const bool intrinsics = !o.images.empty();
  if (intrinsics && o.board.empty()) throw UsageError("--board: required with --images");
  if (!o.fix.empty() && !intrinsics) throw UsageError("--fix: holds intrinsics; needs --images");
  if (o.rational && !intrinsics)
    throw UsageError("--rational: a model of the intrinsics; needs --images");
  if (!o.report.empty() && !intrinsics)
    throw UsageError("--report: pictures the intrinsics; needs --images");
  calibration::IntrinsicsOptions intrinsics_options;  // parsed with the other bad input
  intrinsics_options.parse_fixed(o.fix);
  intrinsics_options.rational_model = o.rational;
  std::optional<camera::Board> board;
  if (!o.board.empty()) board = camera::Board::parse(o.board);
  std::optional<camera::Board> table_board = board;
  if (!o.table_board.empty()) table_board = camera::Board::parse(o.table_board, "--table-board");
  if (!o.table.empty() && !table_board)
    throw UsageError("--table: needs the board: --table-board SPEC (or --board)");
  std::optional<camera::CameraFile> start;
  if (!o.camera.empty()) start = camera::read_camera_file(o.camera);
  if (!o.table.empty() && !intrinsics && !start)
    throw UsageError(
        "--table: needs the camera's intrinsics: --images in the same run, or "
        "--camera FILE");
  if (!o.joint.empty() && o.table.empty() && !(start && start->has_table_pose && !intrinsics))
    throw UsageError(
        "--joint: needs the table pose: --table in the same run, or --camera FILE "
        "that has one (flatland.table_rvec)");
  std::vector<calibration::TablePlacement> table_rows;
  if (!o.table.empty()) table_rows = calibration::read_table_csv(o.table);
  std::vector<calibration::JointImage> joint_rows;
  std::optional<Scene> scene;
  if (!o.joint.empty()) {
    joint_rows = calibration::read_joint_csv(o.joint);
    CommonOptions common;
    common.scene = o.scene;
    scene = load_scene_with_overrides(common);
  }
  const fs::path out = output_path(o);
  if (!o.report.empty()) check_output_directory("--report", o.report, o.force);

  // libpng/libjpeg complain on stderr about corrupt files; our own warning names the file.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  camera::CameraFile file = start.value_or(camera::CameraFile{});
  file.camera_name = o.camera_name_opt && o.camera_name_opt->count()
                         ? o.camera_name
                         : (start ? start->camera_name : o.camera_name);
  Json j;
  std::ostringstream os;
  std::vector<std::string> sections;
  OutputSet outputs(o.force || updates_in_place(o, out));
  if (!o.report.empty()) outputs.begin_directory(o.report);
  if (intrinsics) {
    drop_marks(file, o.table.empty() ? std::vector<std::string>{"intrinsics", "table", "joint"}
                                     : std::vector<std::string>{"intrinsics"});
    intrinsics_section(o, *board, intrinsics_options, file, j, os, outputs);
    sections.push_back("intrinsics");
    if (start && (start->has_table_pose || start->joint) && o.table.empty())
      warn("new intrinsics: the table pose and joint of " + o.camera +
           " were measured through the old ones and are dropped; calibrate them again (--table, "
           "--joint)");
    if (o.table.empty()) {
      file.has_table_pose = false;
      file.table_report.reset();
    }
  }
  if (!o.table.empty()) {
    drop_marks(file, o.joint.empty() ? std::vector<std::string>{"table", "joint"}
                                     : std::vector<std::string>{"table"});
    table_section(o, *table_board, table_rows, file, j, os);
    sections.push_back("table");
    if (o.joint.empty() && file.joint) {
      warn("new table pose: the joint of " + o.camera +
           " was measured through the old one and is dropped; calibrate it again (--joint)");
    }
  }
  if ((intrinsics || !o.table.empty()) && o.joint.empty()) {
    file.joint.reset();
    file.joint_report.reset();
  }
  if (!o.joint.empty()) {
    drop_marks(file, {"joint"});
    joint_section(o, *scene, joint_rows, file, j, os);
    sections.push_back("joint");
  }

  // ---- write
  outputs.ensure_directory(out.parent_path().empty() ? fs::path(".") : out.parent_path());
  camera::write_camera_file(outputs.reserve(out).string(), file);
  outputs.commit();

  if (o.json) {
    Json head;
    head["sections"] = sections;
    head.update(j);
    head["unsupported"] = file.unsupported;
    head["out"] = out.string();
    emit_json(head);
    return;
  }
  std::cout << "flatland calibrate: " <<
      [&] {
        std::string s;
        for (const std::string& x : sections) s += (s.empty() ? "" : ", ") + x;
        return s;
      }() << "\n"
            << os.str();
  for (const std::string& mark : file.unsupported)
    std::cout << "  marked unsupported " << mark << "\n";
  std::cout << "  wrote              " << out.string() << "\n";
}

}  // namespace

Command add_calibrate_command(CLI::App& app) {
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* cmd = add_command(app, "calibrate");
  cmd->add_option("--images", o->images,
                  "Intrinsics: image files or glob patterns of the board at varied poses (quote "
                  "them: 'imgs/*.png'). Unreadable files are skipped with a warning")
      ->type_name("GLOB");
  cmd->add_option("--board", o->board,
                  "The board, counted as OpenCV counts it, sizes in metres: "
                  "chessboard:COLSxROWS:SQUARE_M counts inner corners (OpenCV's patternSize, "
                  "ROS camera_calibration --size; its sample board is chessboard:9x6:0.025), "
                  "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] counts squares "
                  "(cv::aruco::CharucoBoard; DICT default DICT_4X4_50). Required with --images")
      ->type_name("SPEC");
  cmd->add_option("--fix", o->fix,
                  "Intrinsics held, comma-separated, as OpenCV's flags hold them: k3 (k3 = 0, "
                  "CALIB_FIX_K3), tangential (p1 = p2 = 0, CALIB_ZERO_TANGENT_DIST), aspect (fy = "
                  "fx, CALIB_FIX_ASPECT_RATIO), principal-point (the image centre, "
                  "CALIB_FIX_PRINCIPAL_POINT). Default: none")
      ->type_name("LIST");
  cmd->add_flag("--rational", o->rational,
                "Intrinsics with OpenCV's rational model (CALIB_RATIONAL_MODEL): k4, k5, k6 in "
                "the radial term's denominator, 8 coefficients, written as ROS's "
                "rational_polynomial (for wide-angle lenses). Default: off (plumb_bob, 5)");
  cmd->add_option("--report", o->report,
                  "Directory for pictures to look at before trusting the intrinsics: each view "
                  "with its detected corners and reprojection errors as arrows (x20), and "
                  "coverage.png, the image's 8 x 6 cells shaded by the corners in them. Default: "
                  "none")
      ->type_name("DIR");
  cmd->add_option("--camera", o->camera,
                  "Camera file to start from (flatland calibrate's or render's YAML): the "
                  "sections this run does not calibrate come from it, and it is updated in "
                  "place unless --out is given")
      ->type_name("FILE");
  cmd->add_option("--table", o->table,
                  "Table pose: CSV with header image,x,y,yaw[,z], a row per image of a chessboard "
                  "lying on the table: its origin (the outer corner of its square grid, as a "
                  "scene's targets[i].position) at x, y, z m and its x axis turned by yaw rad in "
                  "the table frame; image paths relative to the CSV")
      ->type_name("CSV");
  cmd->add_option("--table-board", o->table_board,
                  "The board lying on the table (a chessboard whose inner-corner counts add to "
                  "an odd number, e.g. chessboard:9x6:0.02). Default: --board")
      ->type_name("SPEC");
  cmd->add_option("--joint", o->joint,
                  "Joint: CSV with header image,encoder, a row per image of the hand alone at "
                  "that encoder reading (rad), spread over a half turn; image paths relative to "
                  "the CSV. Needs the table pose (--table now, or in --camera)")
      ->type_name("CSV");
  cmd->add_option("--scene", o->scene,
                  "Scene file for the hand plate's thickness (render.hand_thickness) that --joint "
                  "measures the hand's top face at. Default: the bundled paper butterfly, " +
                      default_scene_path())
      ->type_name("FILE");
  cmd->add_option("--out", o->out,
                  "Camera file to write (YAML). Required unless --camera is given (then that "
                  "file is updated)")
      ->type_name("FILE");
  add_force_option(*cmd, o->force);
  o->camera_name_opt =
      cmd->add_option("--camera-name", o->camera_name,
                      "camera_name in the file. Default: --camera's, else flatland");
  cmd->add_flag(
      "--json", o->json,
      "Print exactly one JSON object on stdout: sections (what this run calibrated), "
      "with intrinsics rms_px, fx, fy, cx, cy, dist (5 or, rational, 8), std, model, fixed, "
      "views_used, views_rejected, "
      "view_rms_px; with --table a table object (rms_px, corners, images, rvec, tvec, "
      "camera_in_table); with --joint a joint object (axis, encoder_offset_rad, "
      "images, inliers, outliers, center_rms_m, angle_rms_rad, sigma_axis_m, "
      "sigma_offset_rad); and out. Default: off");
  return {cmd, [o] { run_calibrate(*o); }};
}

}  // namespace flatland::app
