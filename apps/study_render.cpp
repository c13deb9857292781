// flatland study render: the renderer's speed-accuracy trade. For every supersampling factor and
// resolution (the scene's camera scaled, same field of view), the disk is rendered at random
// positions on the free table (no noise, no blur) and the intensity centroid of its face is
// compared with cv::projectPoints of its true centre; the same states are then rendered back to
// back and timed (wall time per frame, readback into a cv::Mat included, as
// bench/render_bench.cpp).
#include "study_vision.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/vision/mapping.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <numbers>
#include <random>
#include <sstream>

namespace flatland::app {

// ---- shared with study_tracker.cpp (study_vision.hpp) ------------------------------------------

std::string default_camera_scene() {
  return (fs::path(default_scene_path()).parent_path() / "butterfly-camera.yaml").string();
}

Scene load_camera_scene(const StudyOptions& o, const std::string& study) {
  CommonOptions common;
  common.scene = o.scene.empty() ? default_camera_scene() : o.scene;
  Scene scene = load_scene_with_overrides(common);
  if (!scene.camera)
    throw UsageError(scene.origin + ": camera: the scene has no camera section (needed by study " +
                     study + ")");
  flatland::model::compile_camera(*scene.camera);  // invalid_argument (exit 2) naming the field
  return scene;
}

double load_average_1min() {
  double load[1] = {0};
  return ::getloadavg(load, 1) == 1 ? load[0] : std::nan("");
}

double quantile(std::vector<double>& v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::clamp<std::size_t>(rank, 1, v.size()) - 1];
}

const std::string kLogTics = [] {
  std::string s = "set ytics (";
  for (int e = -4; e <= 4; ++e)
    for (int m : {1, 2, 5})
      s += (s.back() == '(' ? "" : ", ") + std::to_string(m) + "e" + std::to_string(e);
  return s + ")\n";
}();

Json camera_summary(const CameraSpec& spec) {
  const camera::CameraModel m = flatland::model::compile_camera(spec);
  Json j;
  j["width"] = m.width;
  j["height"] = m.height;
  j["fx"] = m.K(0, 0);
  j["fy"] = m.K(1, 1);
  j["cx"] = m.K(0, 2);
  j["cy"] = m.K(1, 2);
  j["distortion"] = spec.distortion;
  j["position"] = spec.position;
  j["look_at"] = spec.look_at;
  // The table's normal along the optical axis: the face of a disk lying on the table is then a
  // scaled copy of itself in the image (no perspective bias of its centroid).
  j["fronto_parallel"] = std::abs(m.R(2, 2)) > 1 - 1e-12;
  j["distorted"] = m.distorted();
  j["fps"] = m.fps;
  return j;
}

namespace {

struct Position {
  cv::Point2d table;  // m, disk centre
  double angle = 0;   // rad, the disk's turn (where its marker is)
};

struct RenderCell {
  int supersample = 1;
  double scale = 1;
  int width = 0, height = 0;
  double fx = 0, radius_px = 0;
  int positions = 0, frames = 0;
  double err_rms = NAN, err_max = NAN, bias_x = NAN, bias_y = NAN;
  double ms_median = NAN, ms_p95 = NAN, fps_median = NAN, fps_mean = NAN;
};

/// The scene's camera with its image scaled by `s`: focal lengths scale with the image, so the
/// field of view stays; the principal point keeps its place (OpenCV's pixel-centre convention).
CameraSpec scaled_camera(CameraSpec c, double s) {
  const int w = std::max(1, static_cast<int>(std::lround(c.width * s)));
  const int h = std::max(1, static_cast<int>(std::lround(c.height * s)));
  const double sx = static_cast<double>(w) / c.width, sy = static_cast<double>(h) / c.height;
  c.fx *= sx;
  c.fy *= sy;
  c.cx = (c.cx + 0.5) * sx - 0.5;
  c.cy = (c.cy + 0.5) * sy - 0.5;
  c.width = w;
  c.height = h;
  c.exposure = 0;
  return c;
}

/// The disk's apparent radius (px) at `c`: the largest distance of its projected rim (top face)
/// from its projected centre.
double disk_radius_px(const camera::CameraModel& cam, cv::Point2d c, double radius, double z) {
  std::vector<cv::Point3d> pts{{c.x, c.y, z}};
  for (int i = 0; i < 32; ++i) {
    const double a = 2 * std::numbers::pi * i / 32;
    pts.emplace_back(c.x + radius * std::cos(a), c.y + radius * std::sin(a), z);
  }
  const auto px = cam.project(pts);
  double r = 0;
  for (std::size_t i = 1; i < px.size(); ++i) r = std::max(r, cv::norm(px[i] - px[0]));
  return r;
}

/// The window the centroid is taken over (tests/render/test_render.cpp's): 1.4 apparent radii around
/// the truth, so that it holds the whole disk and a border of table.
cv::Rect centroid_window(cv::Point2d around, double radius_px) {
  const int r = static_cast<int>(radius_px * 1.4);
  return {static_cast<int>(around.x) - r, static_cast<int>(around.y) - r, 2 * r + 1, 2 * r + 1};
}

bool inside(const cv::Rect& roi, int width, int height, int margin) {
  return roi.x >= margin && roi.y >= margin && roi.x + roi.width <= width - margin &&
         roi.y + roi.height <= height - margin;
}

/// Intensity centroid of the disk's bright face, the method of tests/render/test_render.cpp
/// (Render.DiskCentroidMatchesProjectedCentre): weights are the excess over the table level (the
/// median of the window's top row) less 5 DN, so the dark O-ring, rubber side and table weigh
/// nothing.
cv::Point2d face_centroid(const cv::Mat& bgr, const cv::Rect& roi) {
  cv::Mat gray;
  cv::cvtColor(bgr(roi), gray, cv::COLOR_BGR2GRAY);
  gray.convertTo(gray, CV_64F);
  std::vector<double> border;
  for (int i = 0; i < gray.cols; ++i) border.push_back(gray.at<double>(0, i));
  std::nth_element(border.begin(), border.begin() + border.size() / 2, border.end());
  const double table = border[border.size() / 2];
  double sw = 0, sx = 0, sy = 0;
  for (int y = 0; y < gray.rows; ++y)
    for (int x = 0; x < gray.cols; ++x) {
      const double v = std::max(0.0, gray.at<double>(y, x) - table - 5.0);
      sw += v;
      sx += v * (x + roi.x);
      sy += v * (y + roi.y);
    }
  return {sx / sw, sy / sw};
}

render::SceneState disk_at(cv::Point2d c, double angle) {
  render::SceneState st;
  st.hand_angle = 0;  // palm up, as at the start of the butterfly
  st.disk_center = c;
  st.disk_angle = angle;
  return st;
}

/// The scene as rendered in one cell: its camera scaled, supersampling `factor`, every other
/// effect off (render_8u applies none anyway), no calibration targets.
Scene cell_scene(const Scene& scene, double scale, int factor) {
  Scene s = scene;
  s.camera = scaled_camera(*scene.camera, scale);
  s.effects = EffectsSpec{};
  s.effects.supersample = factor;
  s.effects.seed = scene.effects.seed;
  s.targets.clear();
  return s;
}

/// `n` seeded random disk positions on the free table: a pixel drawn uniformly in the image is
/// back-projected onto the disk's top-face plane; it is kept when, at every scale, the centroid
/// window (grown by 3 px) lies in the image and is uniform in an image without the disk (nothing
/// but table: the hand, the table's edge or a target in the window would bias the centroid).
std::vector<Position> free_positions(const Scene& scene, const std::vector<double>& scales, int n,
                                     std::uint64_t seed) {
  const double radius = scene.sim.object.radius, z = scene.render.disk_thickness;
  std::vector<camera::CameraModel> cams;
  std::vector<cv::Mat> backgrounds;
  for (double s : scales) {
    render::Renderer r(model::compile(cell_scene(scene, s, 1)));
    cams.push_back(r.camera());
    cv::Mat gray;
    cv::cvtColor(r.render_8u(disk_at({1e3, 1e3}, 0)), gray, cv::COLOR_BGR2GRAY);
    backgrounds.push_back(gray);
  }
  const camera::CameraModel& cam = cams.front();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  std::vector<Position> out;
  for (int attempt = 0; attempt < 20000 && static_cast<int>(out.size()) < n; ++attempt) {
    const cv::Point2d px(U(rng) * (cam.width - 1), U(rng) * (cam.height - 1));
    const double angle = 2 * std::numbers::pi * U(rng);
    const auto p = vision::pixel_to_table(cam, px, z);
    if (!p) continue;
    bool ok = true;
    for (std::size_t i = 0; i < cams.size() && ok; ++i) {
      const camera::CameraModel& c = cams[i];
      cv::Rect roi =
          centroid_window(c.project(cv::Point3d(p->x, p->y, z)), disk_radius_px(c, *p, radius, z));
      roi = cv::Rect(roi.x - 3, roi.y - 3, roi.width + 6, roi.height + 6);
      ok = inside(roi, c.width, c.height, 0);
      if (!ok) break;
      double lo = 0, hi = 0;
      cv::minMaxLoc(backgrounds[i](roi), &lo, &hi);
      ok = hi - lo <= 1;
    }
    if (ok) out.push_back({*p, angle});
  }
  if (static_cast<int>(out.size()) < n)
    throw UsageError(scene.origin +
                     ": study render: the camera sees too little free table (found " +
                     std::to_string(out.size()) + " of " + std::to_string(n) +
                     " disk positions clear of the hand and inside every image)");
  return out;
}

RenderCell measure_cell(const Scene& scene, double scale, int factor,
                        const std::vector<Position>& positions, double timing_seconds,
                        std::string& gl, const std::function<void()>& tick) {
  render::Renderer r(model::compile(cell_scene(scene, scale, factor)));
  gl = r.gl_description();
  const camera::CameraModel& cam = r.camera();
  const double radius = scene.sim.object.radius, z = scene.render.disk_thickness;
  RenderCell c;
  c.supersample = factor;
  c.scale = scale;
  c.width = cam.width;
  c.height = cam.height;
  c.fx = cam.K(0, 0);
  std::vector<render::SceneState> states;
  double sum2 = 0, max = 0, bx = 0, by = 0, rsum = 0;
  for (const Position& p : positions) {
    // The off-centre marker is dark: the centroids of the disk and of the disk turned by pi are
    // averaged, which cancels its pull and leaves the geometry of the face (as the test does).
    const render::SceneState a = disk_at(p.table, p.angle),
                             b = disk_at(p.table, p.angle + std::numbers::pi);
    const cv::Point2d truth = r.truth(a).disk_center_px;
    const double rpx = disk_radius_px(cam, p.table, radius, z);
    const cv::Rect roi = centroid_window(truth, rpx);
    const cv::Point2d ca = face_centroid(r.render_8u(a), roi),
                      cb = face_centroid(r.render_8u(b), roi);
    const cv::Point2d e = 0.5 * (ca + cb) - truth;
    const double d = cv::norm(e);
    sum2 += d * d;
    max = std::max(max, d);
    bx += e.x;
    by += e.y;
    rsum += rpx;
    states.push_back(a);
    states.push_back(b);
    tick();
  }
  // Throughput as bench/render_bench.cpp measures it: the same states rendered back to back,
  // each at least once and for at least `timing_seconds`. (The renders above, interleaved with
  // the centroids, leave llvmpipe's worker threads idle in between; timed singly they were up to
  // 3x slower and varied more between runs.)
  std::vector<double> ms;
  double total = 0;
  for (std::size_t i = 0; ms.size() < states.size() || (total < timing_seconds && i < 5000); ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const cv::Mat image = r.render_8u(states[i % states.size()]);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ms.push_back(1e3 * s);
    total += s;
  }
  const double n = static_cast<double>(positions.size());
  c.positions = static_cast<int>(positions.size());
  c.frames = static_cast<int>(ms.size());
  c.radius_px = rsum / n;
  c.err_rms = std::sqrt(sum2 / n);
  c.err_max = max;
  c.bias_x = bx / n;
  c.bias_y = by / n;
  c.fps_mean = static_cast<double>(ms.size()) / total;
  c.ms_p95 = quantile(ms, 0.95);
  c.ms_median = quantile(ms, 0.5);
  c.fps_median = 1e3 / c.ms_median;
  return c;
}

const char* kRenderColumns =
    "supersample,width_px,height_px,fx_px,disk_radius_px,positions,frames,centroid_rms_px,"
    "centroid_max_px,bias_x_px,bias_y_px,frame_ms_median,frame_ms_p95,fps_median,fps_mean\n";

std::string render_csv(const std::vector<RenderCell>& cells) {
  std::string out = kRenderColumns;
  for (const RenderCell& c : cells) {
    std::string line = std::to_string(c.supersample);
    for (double v :
         {static_cast<double>(c.width), static_cast<double>(c.height), c.fx, c.radius_px,
          static_cast<double>(c.positions), static_cast<double>(c.frames), c.err_rms, c.err_max,
          c.bias_x, c.bias_y, c.ms_median, c.ms_p95, c.fps_median, c.fps_mean}) {
      line += ',';
      line += format_number(v);
    }
    out += line + "\n";
  }
  return out;
}

/// One curve per resolution (selected by width, CSV column 2) of column `col` against the
/// supersampling factor; `dashed_col` adds a dashed curve of the same colour (0: none).
std::string per_resolution_curves(const std::vector<RenderCell>& cells, int col, int dashed_col,
                                  const std::string& what, const std::string& dashed_what) {
  std::vector<std::pair<int, int>> sizes;
  for (const RenderCell& c : cells)
    if (std::find(sizes.begin(), sizes.end(), std::make_pair(c.width, c.height)) == sizes.end())
      sizes.emplace_back(c.width, c.height);
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e"};
  std::string b;
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    const std::string w = std::to_string(sizes[i].first),
                      size = w + " x " + std::to_string(sizes[i].second);
    const std::string color = colors[i % 5];
    b += std::string(i ? ", \\\n     " : "") + "datafile skip 1 using 1:(column(2) == " + w +
         " ? lift(column(" + std::to_string(col) + ")) : NaN) with linespoints lw 2 pt 7 lc rgb '" +
         color + "' title '" + size + " " + what + "'";
    if (dashed_col > 0)
      b += ", \\\n     datafile skip 1 using 1:(column(2) == " + w + " ? lift(column(" +
           std::to_string(dashed_col) + ")) : NaN) with linespoints lw 1 pt 6 dt 2 lc rgb '" +
           color + "' title '" + size + " " + dashed_what + "'";
  }
  return b;
}

}  // namespace

void run_render_study(const StudyOptions& o) {
  // ---- everything that can be bad input, before anything is computed or written
  const Scene scene = load_camera_scene(o, "render");
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  const std::vector<int> factors =
      o.quick ? std::vector<int>{1, 2, 4} : std::vector<int>{1, 2, 3, 4};
  const std::vector<double> scales =
      o.quick ? std::vector<double>{0.5, 1.0} : std::vector<double>{0.5, 1.0, 2.0};
  const int n_positions = o.quick ? 4 : 24;
  const double timing_seconds = o.quick ? 0.05 : 0.5;  // per cell, wall
  const std::uint64_t seed = scene.effects.seed;
  const double bound = 0.05;  // px: the renderer's acceptance bound (tests/render/test_render.cpp)

  const double load_start = load_average_1min();
  const auto wall0 = std::chrono::steady_clock::now();
  const std::vector<Position> positions = free_positions(scene, scales, n_positions, seed);
  std::cerr << "flatland: study render: " << factors.size() * scales.size() << " cells ("
            << factors.size() << " supersampling factors x " << scales.size() << " resolutions) x "
            << positions.size() << " disk positions x 2 turns, " << scene.origin << "\n";
  std::vector<RenderCell> cells;
  std::string gl;
  {
    ProgressBar bar("study render");
    long done = 0;
    const long total = static_cast<long>(factors.size() * scales.size() * positions.size());
    for (double s : scales)
      for (int f : factors)
        cells.push_back(measure_cell(scene, s, f, positions, timing_seconds, gl,
                                     [&] { bar.update(++done, total); }));
  }
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double load_end = load_average_1min();

  const camera::CameraModel base = flatland::model::compile_camera(*scene.camera);
  Json j;
  j["study"] = "render";
  j["scene"] = scene.origin;
  j["camera"] = camera_summary(*scene.camera);
  j["gl"] = gl;
  j["method"] =
      "render_8u (no noise, no blur), intensity centroid of the face (excess over the table "
      "level - 5 DN) averaged over the disk and the disk turned by pi, against "
      "cv::projectPoints of the top-face centre; frames/s: the same states rendered back to back "
      "for at least timing_seconds, wall time per frame including readback";
  j["acceptance_bound_px"] = bound;
  j["timing_seconds"] = timing_seconds;
  j["seed"] = seed;
  j["supersample"] = factors;
  Json res = Json::array();
  for (double s : scales) {
    const CameraSpec c = scaled_camera(*scene.camera, s);
    res.push_back({c.width, c.height});
  }
  j["resolutions"] = res;
  Json pos = Json::array();
  for (const Position& p : positions)
    pos.push_back({{"x", p.table.x}, {"y", p.table.y}, {"angle", p.angle}});
  j["positions"] = pos;
  Json rows = Json::array();
  for (const RenderCell& c : cells) {
    Json q;
    q["supersample"] = c.supersample;
    q["width"] = c.width;
    q["height"] = c.height;
    q["fx"] = c.fx;
    q["disk_radius_px"] = c.radius_px;
    q["positions"] = c.positions;
    q["frames"] = c.frames;
    q["centroid_rms_px"] = number(c.err_rms);
    q["centroid_max_px"] = number(c.err_max);
    q["bias_x_px"] = number(c.bias_x);
    q["bias_y_px"] = number(c.bias_y);
    q["frame_ms_median"] = number(c.ms_median);
    q["frame_ms_p95"] = number(c.ms_p95);
    q["fps_median"] = number(c.fps_median);
    q["fps_mean"] = number(c.fps_mean);
    rows.push_back(q);
  }
  j["rows"] = rows;
  j["load_average_1min"] = {number(load_start), number(load_end)};
  j["wall_seconds"] = wall;
  if (!base.distorted() && std::abs(base.R(2, 2)) > 1 - 1e-12) {
    j["note"] = nullptr;
  } else {
    // Then the image of the face is not a scaled copy of it: its centroid is not the image of
    // the centre, and the error includes that projection bias, not only the renderer's.
    j["note"] =
        "the camera is oblique or distorted: the face centroid is biased by the projection "
        "itself";
    std::cerr << "flatland: warning: study render: the scene's camera is oblique or distorted; "
                 "the centroid errors include the projection's own bias\n";
  }

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "render.csv", render_csv(cells));
    if (plots) {
      const std::string head = "set grid\nset logscale y\n" + kLogTics +
                               "set xtics 1\nset xrange [0.8:" + std::to_string(factors.back()) +
                               ".2]\nset xlabel 'supersampling factor (s x s samples "
                               "per pixel)'\nset key outside right\n";
      run_plot(
          outputs, dir,
          {"render_error.gp", "render.csv", "render_error.png",
           head +
               "set format y '%g'\nlift(e) = e < 1e-4 ? 1e-4 : e\n"
               "set title 'Renderer: face centroid vs cv::projectPoints (" +
               std::to_string(positions.size()) +
               " positions, no noise, no blur)'\n"
               "set ylabel 'centroid error (px)'\n"
               "set arrow from graph 0, first " +
               format_number(bound) + " to graph 1, first " + format_number(bound) +
               " nohead dt 3 lw 2 lc rgb 'red'\n"
               "set label 'acceptance " +
               format_number(bound) + " px' at graph 0.75, first " + format_number(bound * 1.15) +
               " tc rgb 'red'\nplot " + per_resolution_curves(cells, 8, 9, "RMS", "max") + "\n"});
      run_plot(outputs, dir,
               {"render_fps.gp", "render.csv", "render_fps.png",
                head +
                    "set format y '%g'\nlift(e) = e\n"
                    "set title " +
                    gnuplot_quote("Renderer: frames/s including readback (" + gl + ")") +
                    "\nset ylabel 'frames per second (wall)'\nplot " +
                    per_resolution_curves(cells, 14, 0, "median", "") + "\n"});
    }
    outputs.stage(dir / "render.json", j.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study render: " << positions.size() << " positions x 2 turns per cell ("
     << scene.origin << ", " << gl << "), " << format_number(std::round(wall * 10) / 10)
     << " s wall, load " << format_number(load_start) << " -> " << format_number(load_end) << "\n";
  for (const RenderCell& c : cells) {
    char line[200];
    std::snprintf(line, sizeof line,
                  "  %4d x %-4d supersample %d   centroid RMS %.4f px  max %.4f px   %7.1f fps "
                  "(median %.2f ms)\n",
                  c.width, c.height, c.supersample, c.err_rms, c.err_max, c.fps_median,
                  c.ms_median);
    os << line;
  }
  for (const auto& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace flatland::app
