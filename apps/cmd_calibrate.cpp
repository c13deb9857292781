// flatland calibrate: camera intrinsics and distortion from images of a planar board (chessboard
// or ChArUco), written as a camera file (OpenCV YAML, ROS camera_info layout).
#include "common.hpp"

#include "flatland/calibration/camera_file.hpp"
#include "flatland/calibration/intrinsics.hpp"
#include "flatland/vision/image_file.hpp"

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <array>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

namespace flatland::app {

namespace {

struct CalibrateOptions {
  std::vector<std::string> images;
  std::string board, out, camera_name = "flatland";
  bool force = false;
  bool json = false;
};

const char* kParamNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};

void warn(const std::string& message) { std::cerr << "flatland: warning: " << message << "\n"; }

std::string describe(const calibration::BoardSpec& b) {
  const cv::Size p = b.pattern_size();
  const std::string inner = std::to_string(p.width) + "x" + std::to_string(p.height);
  const std::string squares = std::to_string(b.squares_x) + "x" + std::to_string(b.squares_y);
  return b.kind == calibration::BoardSpec::Kind::kChessboard
             ? "a chessboard of " + inner + " inner corners (" + squares + " squares)"
             : "a ChArUco board of " + squares + " squares (" + inner + " inner corners)";
}

// Searching every image again would double a failure that already took a while; a miscounted
// board shows in the first few.
constexpr std::size_t kHintImages = 3;

// The board was found nowhere: say what was searched for and, if the same numbers in the other
// count find a board, say so (people count a chessboard's squares, or a ChArUco board's corners).
std::string board_found_nowhere(const calibration::BoardSpec& board,
                                const std::vector<std::string>& readable) {
  std::string message = "board found in no image (" + std::to_string(readable.size()) +
                        " images searched for " + describe(board) + ", --board " +
                        board.notation() + ")";
  const std::optional<calibration::BoardSpec> other = board.other_count();
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
  const bool chessboard = board.kind == calibration::BoardSpec::Kind::kChessboard;
  return message + "; but " + describe(*other) + " is in " + std::to_string(found) +
         " of the first " + std::to_string(tried) + ": flatland counts " +
         (chessboard ? "a chessboard by its inner corners, as OpenCV's patternSize does"
                     : "a ChArUco board by its squares, as cv::aruco::CharucoBoard does") +
         "; try --board " + other->notation();
}

void run_calibrate(const CalibrateOptions& o) {
  // ---- bad input first: options, then the images themselves
  const calibration::BoardSpec board = calibration::BoardSpec::parse(o.board);
  const fs::path out = o.out;
  if (o.out.empty() || o.out.back() == '/' || fs::is_directory(out))
    throw UsageError("--out: must be a file (camera.yaml), got '" + o.out + "'");
  check_output_file("--out", out, o.force);
  const std::vector<std::string> files = expand_file_patterns(o.images, "--images");

  // libpng/libjpeg complain on stderr about corrupt files; our own warning names the file.
  cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR);
  std::vector<calibration::BoardView> views;
  std::vector<std::string> not_found;
  std::string first_sized;
  cv::Size size;
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
      size = image.size();
    } else if (image.size() != size) {
      throw UsageError("mixed image sizes: " + first_sized + " is " + std::to_string(size.width) +
                       "x" + std::to_string(size.height) + ", " + f + " is " +
                       std::to_string(image.cols) + "x" + std::to_string(image.rows));
    }
    if (auto v = calibration::detect_board(image, board, f)) {
      views.push_back(std::move(*v));
    } else {
      warn("board not found in " + f + "; skipped");
      not_found.push_back(f + ": board not found");
    }
  }
  if (readable.empty())
    throw UsageError("--images: none of the " + std::to_string(files.size()) +
                     " files is a readable image");
  if (views.empty()) throw UsageError(board_found_nowhere(board, readable));
  if (views.size() < 3)
    throw UsageError("fewer than 3 usable views: the board was found in " +
                     std::to_string(views.size()) + " of " + std::to_string(readable.size()) +
                     " images; calibration needs at least 3");

  const calibration::IntrinsicsResult r = calibration::calibrate_intrinsics(views);

  // ---- write
  calibration::CameraFile file;
  file.camera_name = o.camera_name;
  file.camera = r.camera();
  calibration::CalibrationReport report = r.report();
  report.views_rejected.insert(report.views_rejected.begin(), not_found.begin(), not_found.end());
  file.report = report;
  OutputSet outputs(o.force);
  outputs.ensure_directory(out.parent_path().empty() ? fs::path(".") : out.parent_path());
  calibration::write_camera_file(outputs.reserve(out).string(), file);
  outputs.commit();

  const std::array<double, 9> p = r.params();
  if (o.json) {
    Json j;
    j["rms_px"] = number(r.rms_px);
    j["fx"] = p[0];
    j["fy"] = p[1];
    j["cx"] = p[2];
    j["cy"] = p[3];
    j["dist"] = Json::array();
    for (int k = 4; k < 9; ++k) j["dist"].push_back(p[k]);
    j["std"] = Json::object();
    for (int k = 0; k < 9; ++k) j["std"][kParamNames[k]] = number(r.std[k]);
    j["views_used"] = r.views_used();
    j["views_rejected"] = report.views_rejected;
    j["view_rms_px"] = Json::object();
    for (std::size_t i = 0; i < views.size(); ++i)
      if (r.used[i]) j["view_rms_px"][views[i].name] = number(r.view_rms_px[i]);
    j["out"] = out.string();
    emit_json(j);
    return;
  }
  // Six significant digits: far below the uncertainties, unlike format_number's round trip.
  const auto g6 = [](double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.6g", v);
    return std::string(buf);
  };
  std::ostringstream os;
  os << "flatland calibrate: " << views.size() << " views of " << o.board << ", "
     << r.image_size.width << " x " << r.image_size.height << " px\n";
  os << "  rms                " << g6(r.rms_px) << " px over " << r.views_used() << " views\n";
  for (int k = 0; k < 9; ++k)
    os << "  " << kParamNames[k] << std::string(17, ' ') << g6(p[k]) << " +- " << g6(r.std[k])
       << (k < 4 ? " px" : "") << "\n";
  for (const std::string& s : report.views_rejected) os << "  rejected           " << s << "\n";
  os << "  wrote              " << out.string() << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_calibrate_command(CLI::App& app) {
  auto o = std::make_shared<CalibrateOptions>();
  CLI::App* cmd = app.add_subcommand(
      "calibrate",
      "Calibrate the camera's intrinsics and OpenCV distortion (k1, k2, p1, p2, k3) from images "
      "of a planar board (Ceres; robust first pass, outlier views dropped) and write a camera "
      "file (OpenCV YAML, ROS camera_info layout; docs/CALIBRATION.md).");
  cmd->add_option("--images", o->images,
                  "Image files or glob patterns (quote them: 'imgs/*.png'). Unreadable files "
                  "are skipped with a warning")
      ->required()
      ->type_name("GLOB");
  cmd->add_option("--board", o->board,
                  "The board, counted as OpenCV counts it, sizes in metres: "
                  "chessboard:COLSxROWS:SQUARE_M counts inner corners (OpenCV's patternSize, "
                  "ROS camera_calibration --size; its sample board is chessboard:9x6:0.025), "
                  "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] counts squares "
                  "(cv::aruco::CharucoBoard; DICT default DICT_4X4_50)")
      ->required()
      ->type_name("SPEC");
  cmd->add_option("--out", o->out, "Camera file to write (YAML)")->required()->type_name("FILE");
  add_force_option(*cmd, o->force);
  cmd->add_option("--camera-name", o->camera_name, "camera_name in the file. Default: flatland");
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout (rms_px, fx, fy, cx, cy, dist, std, "
                "views_used, views_rejected, view_rms_px, out). Default: off");
  return {cmd, [o] { run_calibrate(*o); }};
}

}  // namespace flatland::app
