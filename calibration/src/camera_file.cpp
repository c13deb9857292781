// Camera files (see camera_file.hpp). The ROS camera_info keys come first and are exactly what
// camera_calibration_parsers reads; everything flatland adds lives under one `flatland` mapping
// so that ROS tools ignore it.
#include "flatland/calibration/camera_file.hpp"

#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace flatland::calibration {

namespace {

const char* kStdNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};

// ROS's {rows, cols, data} matrix layout.
void write_matrix(cv::FileStorage& fs, const std::string& key, int rows, int cols,
                  const std::vector<double>& data) {
  fs << key << "{"
     << "rows" << rows << "cols" << cols << "data"
     << "[:";
  for (double v : data) fs << v;
  fs << "]"
     << "}";
}

void write_vector(cv::FileStorage& fs, const std::string& key, const std::vector<double>& v) {
  fs << key << "[:";
  for (double x : v) fs << x;
  fs << "]";
}

class Reader {
 public:
  Reader(std::string path) : path_(std::move(path)) {}

  /// One line whatever the file holds (a quoted YAML string may contain "\n"): the CLI prints
  /// what() as its single error line.
  [[noreturn]] void fail(const std::string& field, const std::string& reason) const {
    std::string msg;
    for (const char c : path_ + ": " + field + ": " + reason) {
      if (c == '\n')
        msg += "\\n";
      else if (c == '\r')
        msg += "\\r";
      else
        msg += c;
    }
    throw std::invalid_argument(msg);
  }

  cv::FileNode require(const cv::FileNode& parent, const std::string& key,
                       const std::string& field) const {
    const cv::FileNode n = parent[key];
    if (n.empty() || n.isNone()) fail(field, "missing");
    return n;
  }

  double number(const cv::FileNode& n, const std::string& field) const {
    if (!n.isReal() && !n.isInt()) fail(field, "must be a number");
    const double v = static_cast<double>(n);
    if (!std::isfinite(v)) fail(field, "must be finite");
    return v;
  }

  int integer(const cv::FileNode& n, const std::string& field) const {
    if (!n.isInt()) fail(field, "must be an integer");
    return static_cast<int>(n);
  }

  std::vector<double> numbers(const cv::FileNode& n, const std::string& field,
                              std::size_t expected) const {
    if (!n.isSeq()) fail(field, "must be a list of " + std::to_string(expected) + " numbers");
    if (n.size() != expected)
      fail(field,
           "must hold " + std::to_string(expected) + " numbers, got " + std::to_string(n.size()));
    std::vector<double> out;
    for (std::size_t i = 0; i < n.size(); ++i)
      out.push_back(number(n[static_cast<int>(i)], field + "[" + std::to_string(i) + "]"));
    return out;
  }

  std::vector<double> matrix(const cv::FileNode& root, const std::string& key, int rows,
                             int cols) const {
    const cv::FileNode m = require(root, key, key);
    if (!m.isMap()) fail(key, "must be a mapping with rows, cols and data");
    const int r = integer(require(m, "rows", key + ".rows"), key + ".rows");
    const int c = integer(require(m, "cols", key + ".cols"), key + ".cols");
    if (r != rows || c != cols)
      fail(key, "must be " + std::to_string(rows) + " x " + std::to_string(cols) + ", got " +
                    std::to_string(r) + " x " + std::to_string(c));
    return numbers(require(m, "data", key + ".data"), key + ".data",
                   static_cast<std::size_t>(rows * cols));
  }

 private:
  std::string path_;
};

// OpenCV 4.6's YAML reader (cv::FileStorage) is not safe on arbitrary text, and a camera file may
// come from anywhere. Two of its defects are reachable from a few bytes, so they are ruled out
// here before the text reaches it:
// - an empty mapping key (": 1" with nothing before the colon) makes parseKey scan backwards
//   past the key's start (opencv/opencv#28619); depending on the bytes there it reads garbage,
//   throws std::length_error, or loops forever ("%YAML:1.0\n s:1\n: [-\n " hangs; found by
//   fuzzing: tests/fuzz/regressions/camera_file/opencv-empty-key-hang.yaml);
// - its parser recurses once per nesting level without a limit (opencv/opencv#29939), so a
//   deep "[[[[..." overflows the stack.
// A camera file holds a few dozen keys nested two levels deep, so neither rule excludes one.
constexpr std::size_t kMaxCameraFileBytes = 1 << 20;
constexpr int kMaxFlowDepth = 32;

void check_for_opencv_yaml(const std::string& text, const Reader& rd) {
  if (text.size() > kMaxCameraFileBytes)
    rd.fail("(document)", "larger than 1 MiB (" + std::to_string(text.size()) +
                              " bytes); a camera file is a few kB");
  int line = 1, depth = 0;
  char quote = 0;        // inside a '...' or "..." scalar
  bool comment = false;  // after a '#' that starts a comment
  std::size_t line_start = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
      line_start = i + 1;
      comment = false;
      continue;
    }
    if (comment) continue;
    if (quote) {
      if (c == quote)
        quote = 0;
      else if (c == '\\' && quote == '"')
        ++i;
      continue;
    }
    const bool after_blank = i == line_start || text[i - 1] == ' ' || text[i - 1] == '\t';
    const bool starts_scalar =
        after_blank || text[i - 1] == '[' || text[i - 1] == '{' || text[i - 1] == ',';
    if (c == '#' && after_blank) {
      comment = true;
    } else if ((c == '"' || c == '\'') && starts_scalar) {
      quote = c;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxFlowDepth)
        rd.fail("(document)", "invalid YAML: collections nested deeper than " +
                                  std::to_string(kMaxFlowDepth) + " levels on line " +
                                  std::to_string(line));
    } else if (c == ']' || c == '}') {
      depth = std::max(depth - 1, 0);
    } else if (c == ':' && (i + 1 == text.size() || text[i + 1] == ' ' || text[i + 1] == '\t' ||
                            text[i + 1] == '\n' || text[i + 1] == '\r')) {
      // A mapping indicator: its key is what stands before it on the line, back to a flow
      // collection's '{' or ',' or a block sequence's "- ".
      std::size_t k = i;
      while (k > line_start && (text[k - 1] == ' ' || text[k - 1] == '\t')) --k;
      const bool dash_entry = k > line_start && text[k - 1] == '-' &&
                              text.find_first_not_of(" \t", line_start) == k - 1;
      if (k == line_start || text[k - 1] == '{' || text[k - 1] == ',' || dash_entry)
        rd.fail("(document)", "invalid YAML: empty mapping key on line " + std::to_string(line));
    }
  }
}

}  // namespace

void write_camera_file(const std::string& path, const CameraFile& file) {
  const render::CameraModel& m = file.camera;
  cv::FileStorage fs(
      ".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
  fs << "image_width" << m.width << "image_height" << m.height;
  fs << "camera_name" << file.camera_name;
  write_matrix(fs, "camera_matrix", 3, 3,
               {m.K(0, 0), m.K(0, 1), m.K(0, 2), m.K(1, 0), m.K(1, 1), m.K(1, 2), m.K(2, 0),
                m.K(2, 1), m.K(2, 2)});
  fs << "distortion_model"
     << "plumb_bob";
  write_matrix(fs, "distortion_coefficients", 1, 5,
               {m.dist[0], m.dist[1], m.dist[2], m.dist[3], m.dist[4]});
  // ROS readers expect these two as well; for a monocular camera R = I and P = [K | 0].
  write_matrix(fs, "rectification_matrix", 3, 3, {1, 0, 0, 0, 1, 0, 0, 0, 1});
  write_matrix(
      fs, "projection_matrix", 3, 4,
      {m.K(0, 0), m.K(0, 1), m.K(0, 2), 0, m.K(1, 0), m.K(1, 1), m.K(1, 2), 0, 0, 0, 1, 0});

  fs << "flatland"
     << "{";
  fs << "fps" << m.fps << "exposure_s" << m.exposure;
  if (file.has_table_pose) {
    const cv::Vec3d r = m.rvec();
    write_vector(fs, "table_rvec", {r[0], r[1], r[2]});
    write_vector(fs, "table_tvec", {m.t[0], m.t[1], m.t[2]});
  }
  if (file.joint) {
    write_vector(fs, "joint_axis", {file.joint->axis_table.x, file.joint->axis_table.y});
    fs << "encoder_offset_rad" << file.joint->encoder_offset;
  }
  if (file.report) {
    const CalibrationReport& rep = *file.report;
    fs << "rms_px" << rep.rms_px;
    write_vector(fs, "view_rms_px", rep.view_rms_px);
    fs << "views_used" << rep.views_used;
    fs << "views_rejected"
       << "[";
    for (const std::string& s : rep.views_rejected) fs << s;
    fs << "]";
    fs << "std"
       << "{";
    for (int k = 0; k < 9; ++k) fs << kStdNames[k] << rep.std[static_cast<std::size_t>(k)];
    fs << "}";
  }
  fs << "}";
  std::string text = fs.releaseAndGetString();
  if (!text.empty() && text.back() != '\n') text += '\n';

  // Temp file + rename: a reader never sees a half-written camera file.
  const std::filesystem::path final_path(path);
  const std::filesystem::path tmp(path + ".tmp-" + std::to_string(::getpid()));
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      throw std::runtime_error(path + ": cannot write camera file");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, final_path, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw std::runtime_error(path + ": cannot write camera file (rename failed: " + ec.message() +
                             ")");
  }
}

CameraFile read_camera_file(const std::string& path) {
  std::string text;
  {
    std::ifstream in(path, std::ios::binary);
    if (!in.is_open() || std::filesystem::is_directory(path))
      Reader(path).fail("(file)", "cannot read camera file");
    std::ostringstream ss;
    ss << in.rdbuf();
    text = ss.str();
  }
  return parse_camera_file(text, path);
}

CameraFile parse_camera_file(const std::string& file_text, const std::string& origin) {
  const Reader rd(origin);
  std::string text = file_text;
  // OpenCV's YAML reader insists on its "%YAML:1.0" header, which ROS's files do not have.
  check_for_opencv_yaml(text, rd);
  if (text.rfind("%YAML", 0) != 0) text = "%YAML:1.0\n---\n" + text;
  cv::FileStorage fs;
  bool opened = false;
  try {
    opened = fs.open(
        text, cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
  } catch (const cv::Exception& e) {
    std::string msg = e.err.empty() ? e.msg : e.err;
    for (char& c : msg)
      if (c == '\n' || c == '\r') c = ' ';
    rd.fail("(document)", "invalid YAML: " + msg);
  } catch (const std::exception& e) {
    // OpenCV 4.6's YAML parser lets std::length_error out for some malformed keys (a negative
    // key length; found by fuzzing: tests/fuzz/regressions/camera_file/opencv-length-error.yaml).
    rd.fail("(document)", std::string("invalid YAML (OpenCV's parser failed: ") + e.what() + ")");
  }
  if (!opened) rd.fail("(document)", "invalid YAML");
  const cv::FileNode root = fs.root();
  if (!root.isMap()) rd.fail("(document)", "not a mapping");

  CameraFile file;
  render::CameraModel& m = file.camera;
  m.width = rd.integer(rd.require(root, "image_width", "image_width"), "image_width");
  m.height = rd.integer(rd.require(root, "image_height", "image_height"), "image_height");
  if (m.width <= 0) rd.fail("image_width", "must be positive, got " + std::to_string(m.width));
  if (m.height <= 0) rd.fail("image_height", "must be positive, got " + std::to_string(m.height));
  const cv::FileNode name = rd.require(root, "camera_name", "camera_name");
  if (!name.isString()) rd.fail("camera_name", "must be a string");
  file.camera_name = static_cast<std::string>(name);

  const std::vector<double> k = rd.matrix(root, "camera_matrix", 3, 3);
  m.K = cv::Matx33d(k.data());
  if (!(m.K(0, 0) > 0)) rd.fail("camera_matrix", "fx must be positive");
  if (!(m.K(1, 1) > 0)) rd.fail("camera_matrix", "fy must be positive");
  if (m.K(1, 0) != 0 || m.K(2, 0) != 0 || m.K(2, 1) != 0 || m.K(2, 2) != 1)
    rd.fail("camera_matrix", "must be upper triangular with a 1 in the corner");

  const cv::FileNode model = rd.require(root, "distortion_model", "distortion_model");
  if (!model.isString()) rd.fail("distortion_model", "must be a string");
  const std::string model_name = static_cast<std::string>(model);
  if (model_name != "plumb_bob")
    rd.fail("distortion_model",
            "unknown model '" + model_name + "' (flatland uses OpenCV's 5-coefficient plumb_bob)");
  const std::vector<double> d = rd.matrix(root, "distortion_coefficients", 1, 5);
  for (int i = 0; i < 5; ++i) m.dist[i] = d[static_cast<std::size_t>(i)];

  const cv::FileNode fl = root["flatland"];
  if (fl.empty() || fl.isNone()) return file;
  if (!fl.isMap()) rd.fail("flatland", "must be a mapping");
  if (!fl["fps"].empty()) {
    m.fps = rd.number(fl["fps"], "flatland.fps");
    if (!(m.fps > 0)) rd.fail("flatland.fps", "must be positive");
  }
  if (!fl["exposure_s"].empty()) {
    m.exposure = rd.number(fl["exposure_s"], "flatland.exposure_s");
    if (m.exposure < 0) rd.fail("flatland.exposure_s", "must not be negative");
  }
  const bool has_r = !fl["table_rvec"].empty(), has_t = !fl["table_tvec"].empty();
  if (has_r != has_t)
    rd.fail(has_r ? "flatland.table_tvec" : "flatland.table_rvec",
            "missing (the table pose needs both table_rvec and table_tvec)");
  if (has_r) {
    const std::vector<double> r = rd.numbers(fl["table_rvec"], "flatland.table_rvec", 3);
    const std::vector<double> t = rd.numbers(fl["table_tvec"], "flatland.table_tvec", 3);
    cv::Rodrigues(cv::Vec3d(r[0], r[1], r[2]), m.R);
    m.t = cv::Vec3d(t[0], t[1], t[2]);
    file.has_table_pose = true;
  }
  const bool has_axis = !fl["joint_axis"].empty(), has_off = !fl["encoder_offset_rad"].empty();
  if (has_axis != has_off)
    rd.fail(has_axis ? "flatland.encoder_offset_rad" : "flatland.joint_axis",
            "missing (the joint needs both joint_axis and encoder_offset_rad)");
  if (has_axis) {
    const std::vector<double> a = rd.numbers(fl["joint_axis"], "flatland.joint_axis", 2);
    JointCalibration j;
    j.axis_table = cv::Point2d(a[0], a[1]);
    j.encoder_offset = rd.number(fl["encoder_offset_rad"], "flatland.encoder_offset_rad");
    file.joint = j;
  }
  if (!fl["rms_px"].empty()) {
    CalibrationReport rep;
    rep.rms_px = rd.number(fl["rms_px"], "flatland.rms_px");
    const cv::FileNode v = fl["view_rms_px"];
    if (!v.empty()) rep.view_rms_px = rd.numbers(v, "flatland.view_rms_px", v.size());
    if (!fl["views_used"].empty())
      rep.views_used = rd.integer(fl["views_used"], "flatland.views_used");
    const cv::FileNode rej = fl["views_rejected"];
    if (!rej.empty()) {
      if (!rej.isSeq()) rd.fail("flatland.views_rejected", "must be a list of strings");
      for (std::size_t i = 0; i < rej.size(); ++i) {
        const cv::FileNode s = rej[static_cast<int>(i)];
        if (!s.isString()) rd.fail("flatland.views_rejected", "must be a list of strings");
        rep.views_rejected.push_back(static_cast<std::string>(s));
      }
    }
    const cv::FileNode sd = fl["std"];
    rep.std.fill(std::nan(""));
    if (!sd.empty()) {
      if (!sd.isMap()) rd.fail("flatland.std", "must be a mapping fx, fy, cx, cy, k1, ..., k3");
      for (int k = 0; k < 9; ++k) {
        const cv::FileNode e = sd[kStdNames[k]];
        // Standard deviations may be .nan (rank-deficient covariance), so no finiteness check.
        if (!e.empty()) {
          if (!e.isReal() && !e.isInt())
            rd.fail(std::string("flatland.std.") + kStdNames[k], "must be a number");
          rep.std[static_cast<std::size_t>(k)] = static_cast<double>(e);
        }
      }
    }
    file.report = rep;
  }
  return file;
}

}  // namespace flatland::calibration
