// Camera files (see camera_file.hpp). The ROS camera_info keys come first and are exactly what
// camera_calibration_parsers reads; everything flatland adds lives under one `flatland` mapping
// so that ROS tools ignore it.
#include "flatland/camera/camera_file.hpp"

#include <yaml-cpp/yaml.h>
#include <opencv2/calib3d.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace flatland::camera {

namespace {

const char* kStdNames[9] = {"fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3"};
const char* kRationalStdNames[3] = {"k4", "k5", "k6"};

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

// A number as YAML writes it: a plain scalar holding a decimal number, or one of YAML's special
// values in any capitalisation (OpenCV writes ".Nan" and ".Inf", YAML 1.2 ".nan" and ".inf").
std::optional<double> parse_number(const std::string& s) {
  std::string lower;
  for (const char c : s) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (lower == ".nan") return std::numeric_limits<double>::quiet_NaN();
  if (lower == ".inf" || lower == "+.inf") return std::numeric_limits<double>::infinity();
  if (lower == "-.inf") return -std::numeric_limits<double>::infinity();
  const char* first = s.data();
  const char* last = s.data() + s.size();
  if (first != last && *first == '+') ++first;  // from_chars takes no '+'
  double v = 0;
  const auto [end, ec] = std::from_chars(first, last, v);
  if (ec != std::errc() || end != last || first == last) return std::nullopt;
  return v;
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

  static bool present(const YAML::Node& n) { return n.IsDefined() && !n.IsNull(); }

  YAML::Node require(const YAML::Node& parent, const std::string& key,
                     const std::string& field) const {
    const YAML::Node n = parent[key];
    if (!present(n)) fail(field, "missing");
    return n;
  }

  /// A plain (unquoted) scalar: a quoted "800" is a string, as in OpenCV's reader.
  static bool plain_scalar(const YAML::Node& n) { return n.IsScalar() && n.Tag() != "!"; }

  double number(const YAML::Node& n, const std::string& field, bool finite = true) const {
    const std::optional<double> v =
        plain_scalar(n) ? parse_number(n.Scalar()) : std::optional<double>();
    if (!v) fail(field, "must be a number");
    if (finite && !std::isfinite(*v)) fail(field, "must be finite");
    return *v;
  }

  int integer(const YAML::Node& n, const std::string& field) const {
    int v = 0;
    bool ok = plain_scalar(n);
    if (ok) {
      const std::string& s = n.Scalar();
      const char* first = s.data() + (!s.empty() && s[0] == '+' ? 1 : 0);
      const auto [end, ec] = std::from_chars(first, s.data() + s.size(), v);
      ok = ec == std::errc() && end == s.data() + s.size() && first != end;
    }
    if (!ok) fail(field, "must be an integer");
    return v;
  }

  std::string text(const YAML::Node& n, const std::string& field) const {
    if (!n.IsScalar()) fail(field, "must be a string");
    return n.Scalar();
  }

  std::vector<double> numbers(const YAML::Node& n, const std::string& field,
                              std::size_t expected) const {
    if (!n.IsSequence()) fail(field, "must be a list of " + std::to_string(expected) + " numbers");
    if (n.size() != expected)
      fail(field,
           "must hold " + std::to_string(expected) + " numbers, got " + std::to_string(n.size()));
    std::vector<double> out;
    for (std::size_t i = 0; i < n.size(); ++i)
      out.push_back(number(n[i], field + "[" + std::to_string(i) + "]"));
    return out;
  }

  std::vector<double> matrix(const YAML::Node& root, const std::string& key, int rows,
                             int cols) const {
    const YAML::Node m = require(root, key, key);
    if (!m.IsMap()) fail(key, "must be a mapping with rows, cols and data");
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

// A camera file is a few kB; anything far larger is not one.
constexpr std::size_t kMaxCameraFileBytes = 1 << 20;

// A report's number: finite and not negative (RMS values, sigmas).
double report_number(const YAML::Node& map, const char* key, const std::string& section,
                     const Reader& rd) {
  const std::string field = "flatland." + section + "." + key;
  const double v = rd.number(rd.require(map, key, field), field);
  if (v < 0) rd.fail(field, "must not be negative");
  return v;
}

int report_count(const YAML::Node& map, const char* key, const std::string& section,
                 const Reader& rd) {
  const std::string field = "flatland." + section + "." + key;
  const int v = rd.integer(rd.require(map, key, field), field);
  if (v < 0) rd.fail(field, "must not be negative");
  return v;
}

// flatland.table_report and flatland.joint_report: what the table and joint fits reported.
void read_fit_reports(const YAML::Node& fl, const Reader& rd, CameraFile& file) {
  if (const YAML::Node t = fl["table_report"]; Reader::present(t)) {
    if (!t.IsMap()) rd.fail("flatland.table_report", "must be a mapping rms_px, corners, images");
    TablePoseReport r;
    r.rms_px = report_number(t, "rms_px", "table_report", rd);
    r.corners = report_count(t, "corners", "table_report", rd);
    r.images = report_count(t, "images", "table_report", rd);
    if (Reader::present(t["covariance"])) {
      const std::vector<double> c =
          rd.numbers(t["covariance"], "flatland.table_report.covariance", 36);
      std::array<double, 36> cov{};
      std::copy(c.begin(), c.end(), cov.begin());
      for (std::size_t i = 0; i < 6; ++i)
        if (cov[i * 7] < 0) rd.fail("flatland.table_report.covariance", "negative variance");
      r.covariance = cov;
    }
    if (const YAML::Node g = t["sensitivity"]; Reader::present(g)) {
      if (!g.IsSequence() || g.size() % 6 != 0 || g.size() > 72)
        rd.fail("flatland.table_report.sensitivity", "must be a list of 6 numbers per intrinsic");
      r.sensitivity = rd.numbers(g, "flatland.table_report.sensitivity", g.size());
    }
    file.table_report = r;
  }
  if (const YAML::Node j = fl["joint_report"]; Reader::present(j)) {
    if (!j.IsMap()) rd.fail("flatland.joint_report", "must be a mapping");
    JointFitReport r;
    r.images = report_count(j, "images", "joint_report", rd);
    r.inliers = report_count(j, "inliers", "joint_report", rd);
    r.center_rms_m = report_number(j, "center_rms_m", "joint_report", rd);
    r.angle_rms_rad = report_number(j, "angle_rms_rad", "joint_report", rd);
    r.sigma_axis_m = report_number(j, "sigma_axis_m", "joint_report", rd);
    r.sigma_offset_rad = report_number(j, "sigma_offset_rad", "joint_report", rd);
    file.joint_report = r;
  }
}

// The fields of a parsed camera file (the ROS keys, then flatland's extras).
CameraFile read_fields(const YAML::Node& root, const Reader& rd) {
  if (!root.IsMap()) rd.fail("(document)", "not a mapping");

  CameraFile file;
  CameraModel& m = file.camera;
  m.width = rd.integer(rd.require(root, "image_width", "image_width"), "image_width");
  m.height = rd.integer(rd.require(root, "image_height", "image_height"), "image_height");
  if (m.width <= 0) rd.fail("image_width", "must be positive, got " + std::to_string(m.width));
  if (m.height <= 0) rd.fail("image_height", "must be positive, got " + std::to_string(m.height));
  file.camera_name = rd.text(rd.require(root, "camera_name", "camera_name"), "camera_name");

  const std::vector<double> k = rd.matrix(root, "camera_matrix", 3, 3);
  m.K = cv::Matx33d(k.data());
  if (!(m.K(0, 0) > 0)) rd.fail("camera_matrix", "fx must be positive");
  if (!(m.K(1, 1) > 0)) rd.fail("camera_matrix", "fy must be positive");
  if (m.K(1, 0) != 0 || m.K(2, 0) != 0 || m.K(2, 1) != 0 || m.K(2, 2) != 1)
    rd.fail("camera_matrix", "must be upper triangular with a 1 in the corner");

  const std::string model_name =
      rd.text(rd.require(root, "distortion_model", "distortion_model"), "distortion_model");
  if (model_name != "plumb_bob" && model_name != "rational_polynomial")
    rd.fail("distortion_model",
            "unknown model '" + model_name +
                "' (OpenCV's plumb_bob, 5 coefficients, or rational_polynomial, "
                "8)");
  file.rational_model = model_name == "rational_polynomial";
  const int n = file.rational_model ? 8 : 5;
  const std::vector<double> d = rd.matrix(root, "distortion_coefficients", 1, n);
  for (int i = 0; i < n; ++i) m.dist[i] = d[static_cast<std::size_t>(i)];

  const YAML::Node fl = root["flatland"];
  if (!Reader::present(fl)) return file;
  if (!fl.IsMap()) rd.fail("flatland", "must be a mapping");
  if (Reader::present(fl["fps"])) {
    m.fps = rd.number(fl["fps"], "flatland.fps");
    if (!(m.fps > 0)) rd.fail("flatland.fps", "must be positive");
  }
  if (Reader::present(fl["exposure_s"])) {
    m.exposure = rd.number(fl["exposure_s"], "flatland.exposure_s");
    if (m.exposure < 0) rd.fail("flatland.exposure_s", "must not be negative");
  }
  const bool has_r = Reader::present(fl["table_rvec"]), has_t = Reader::present(fl["table_tvec"]);
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
  const bool has_axis = Reader::present(fl["joint_axis"]),
             has_off = Reader::present(fl["encoder_offset_rad"]);
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
  if (Reader::present(fl["rms_px"])) {
    CalibrationReport rep;
    rep.rms_px = rd.number(fl["rms_px"], "flatland.rms_px");
    const YAML::Node v = fl["view_rms_px"];
    if (Reader::present(v)) rep.view_rms_px = rd.numbers(v, "flatland.view_rms_px", v.size());
    if (Reader::present(fl["views_used"]))
      rep.views_used = rd.integer(fl["views_used"], "flatland.views_used");
    const YAML::Node rej = fl["views_rejected"];
    if (Reader::present(rej)) {
      if (!rej.IsSequence()) rd.fail("flatland.views_rejected", "must be a list of strings");
      for (std::size_t i = 0; i < rej.size(); ++i)
        rep.views_rejected.push_back(rd.text(rej[i], "flatland.views_rejected"));
    }
    const YAML::Node sd = fl["std"];
    rep.std.fill(std::nan(""));
    if (Reader::present(sd)) {
      if (!sd.IsMap()) rd.fail("flatland.std", "must be a mapping fx, fy, cx, cy, k1, ..., k3");
      for (int k = 0; k < 9; ++k) {
        const YAML::Node e = sd[kStdNames[k]];
        // Standard deviations may be .nan (rank-deficient covariance), so no finiteness check.
        if (Reader::present(e))
          rep.std[static_cast<std::size_t>(k)] =
              rd.number(e, std::string("flatland.std.") + kStdNames[k], false);
      }
      if (file.rational_model) {
        std::array<double, 3> r;
        r.fill(std::nan(""));
        for (int k = 0; k < 3; ++k) {
          const YAML::Node e = sd[kRationalStdNames[k]];
          if (Reader::present(e))
            r[static_cast<std::size_t>(k)] =
                rd.number(e, std::string("flatland.std.") + kRationalStdNames[k], false);
        }
        rep.std_rational = r;
      }
    }
    file.report = rep;
  }
  read_fit_reports(fl, rd, file);
  if (const YAML::Node u = fl["unsupported"]; Reader::present(u)) {
    if (!u.IsSequence()) rd.fail("flatland.unsupported", "must be a list of strings");
    for (std::size_t i = 0; i < u.size(); ++i)
      file.unsupported.push_back(rd.text(u[i], "flatland.unsupported"));
  }
  return file;
}

}  // namespace

void write_camera_file(const std::string& path, const CameraFile& file) {
  const CameraModel& m = file.camera;
  cv::FileStorage fs(
      ".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
  fs << "image_width" << m.width << "image_height" << m.height;
  fs << "camera_name" << file.camera_name;
  write_matrix(fs, "camera_matrix", 3, 3,
               {m.K(0, 0), m.K(0, 1), m.K(0, 2), m.K(1, 0), m.K(1, 1), m.K(1, 2), m.K(2, 0),
                m.K(2, 1), m.K(2, 2)});
  // ROS's names: plumb_bob has 5 coefficients, rational_polynomial 8 (OpenCV's order for both).
  const bool rational = file.rational_model || m.rational();
  fs << "distortion_model" << (rational ? "rational_polynomial" : "plumb_bob");
  std::vector<double> d(m.dist.val, m.dist.val + (rational ? 8 : 5));
  write_matrix(fs, "distortion_coefficients", 1, rational ? 8 : 5, d);
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
    if (rep.std_rational)
      for (int k = 0; k < 3; ++k)
        fs << kRationalStdNames[k] << (*rep.std_rational)[static_cast<std::size_t>(k)];
    fs << "}";
  }
  if (file.table_report) {
    const TablePoseReport& r = *file.table_report;
    fs << "table_report"
       << "{"
       << "rms_px" << r.rms_px << "corners" << r.corners << "images" << r.images;
    if (r.covariance)
      write_vector(fs, "covariance",
                   std::vector<double>(r.covariance->begin(), r.covariance->end()));
    if (!r.sensitivity.empty()) write_vector(fs, "sensitivity", r.sensitivity);
    fs << "}";
  }
  if (file.joint_report) {
    const JointFitReport& r = *file.joint_report;
    fs << "joint_report"
       << "{"
       << "images" << r.images << "inliers" << r.inliers << "center_rms_m" << r.center_rms_m
       << "angle_rms_rad" << r.angle_rms_rad << "sigma_axis_m" << r.sigma_axis_m
       << "sigma_offset_rad" << r.sigma_offset_rad << "}";
  }
  if (!file.unsupported.empty()) {
    fs << "unsupported"
       << "[";
    for (const std::string& s : file.unsupported) fs << s;
    fs << "]";
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
    // At most one byte past the limit: /dev/zero or a huge file costs no more than that.
    text.resize(kMaxCameraFileBytes + 1);
    in.read(text.data(), static_cast<std::streamsize>(text.size()));
    text.resize(static_cast<std::size_t>(in.gcount()));
  }
  return parse_camera_file(text, path);
}

CameraFile parse_camera_file(const std::string& text, const std::string& origin) {
  const Reader rd(origin);
  if (text.size() > kMaxCameraFileBytes)
    rd.fail("(document)", "larger than 1 MiB; a camera file is a few kB");
  // yaml-cpp, not OpenCV's FileStorage, reads the file: OpenCV 4.6's YAML reader loops forever on
  // some malformed text (" s:1\n: [-\n " and " -g\nar -\n ", found by fuzzing: tests/fuzz/
  // regressions/camera_file/opencv-*-hang.yaml), reads out of bounds on an empty key
  // (opencv/opencv#28619) and recurses without limit on deep nesting (opencv/opencv#29939).
  // yaml-cpp skips OpenCV's "%YAML:1.0" header line as an unknown directive.
  try {
    return read_fields(YAML::Load(text), rd);
  } catch (const YAML::Exception& e) {
    // yaml-cpp marks are 0-based; editors count from 1.
    const std::string where = e.mark.is_null()
                                  ? std::string()
                                  : " (line " + std::to_string(e.mark.line + 1) + ", column " +
                                        std::to_string(e.mark.column + 1) + ")";
    rd.fail("(document)", "invalid YAML: " + e.msg + where);
  }
}

}  // namespace flatland::camera
