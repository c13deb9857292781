// The renderer's study (render_study.hpp).
#include "flatland/studies/render_study.hpp"

#include "flatland/render/renderer.hpp"
#include "flatland/sim/trajectory_csv.hpp"
#include "flatland/studies/timing.hpp"
#include "flatland/vision/mapping.hpp"

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <random>
#include <stdexcept>

namespace flatland::studies {

namespace {

using sim::format_number;

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

/// The window the centroid is taken over (tests/render/test_render.cpp's): 1.4 apparent radii
/// around the truth, so that it holds the whole disk and a border of table.
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
/// effect off (render_8u applies none anyway), no calibration targets, and no lamp: the study
/// measures where the renderer puts the disk, and a lamp's shading (brighter towards the lamp,
/// the O-ring's highlight) would move the face's intensity centroid without moving the disk.
Scene cell_scene(const Scene& scene, double scale, int factor) {
  Scene s = scene;
  s.camera = scaled_camera(*scene.camera, scale);
  s.effects = EffectsSpec{};
  s.effects.supersample = factor;
  s.effects.seed = scene.effects.seed;
  s.targets.clear();
  s.lighting.reset();
  return s;
}

/// `n` seeded random disk positions on the free table: a pixel drawn uniformly in the image is
/// back-projected onto the disk's top-face plane; it is kept when, at every scale, the centroid
/// window (grown by 3 px) lies in the image and is uniform in an image without the disk (nothing
/// but table: the hand, the table's edge or a target in the window would bias the centroid).
std::vector<RenderStudyPosition> free_positions(const Scene& scene,
                                                const std::vector<double>& scales, int n,
                                                std::uint64_t seed) {
  const double radius = scene.sim.object.radius, z = scene.render.disk_thickness;
  std::vector<camera::CameraModel> cams;
  std::vector<cv::Mat> backgrounds;
  for (double s : scales) {
    render::Renderer r(model::render_setup(*model::compile(cell_scene(scene, s, 1))));
    cams.push_back(r.camera());
    cv::Mat gray;
    cv::cvtColor(r.render_8u(disk_at({1e3, 1e3}, 0)), gray, cv::COLOR_BGR2GRAY);
    backgrounds.push_back(gray);
  }
  const camera::CameraModel& cam = cams.front();
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  std::vector<RenderStudyPosition> out;
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
    throw std::invalid_argument(scene.origin +
                                ": study render: the camera sees too little free table (found " +
                                std::to_string(out.size()) + " of " + std::to_string(n) +
                                " disk positions clear of the hand and inside every image)");
  return out;
}

RenderStudyCell measure_cell(const Scene& scene, double scale, int factor,
                             const std::vector<RenderStudyPosition>& positions,
                             double timing_seconds, std::string& gl,
                             const std::function<void()>& tick) {
  render::Renderer r(model::render_setup(*model::compile(cell_scene(scene, scale, factor))));
  gl = r.gl_description();
  const camera::CameraModel& cam = r.camera();
  const double radius = scene.sim.object.radius, z = scene.render.disk_thickness;
  RenderStudyCell c;
  c.supersample = factor;
  c.scale = scale;
  c.width = cam.width;
  c.height = cam.height;
  c.fx = cam.K(0, 0);
  std::vector<render::SceneState> states;
  double sum2 = 0, max = 0, bx = 0, by = 0, rsum = 0;
  for (const RenderStudyPosition& p : positions) {
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

std::string render_csv(const std::vector<RenderStudyCell>& cells) {
  std::string out = kRenderColumns;
  for (const RenderStudyCell& c : cells) {
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

}  // namespace

RenderStudyGrid render_study_grid(bool quick) {
  RenderStudyGrid g;
  g.factors = quick ? std::vector<int>{1, 2, 4} : std::vector<int>{1, 2, 3, 4};
  g.scales = quick ? std::vector<double>{0.5, 1.0} : std::vector<double>{0.5, 1.0, 2.0};
  g.positions = quick ? 4 : 24;
  g.timing_seconds = quick ? 0.05 : 0.5;
  return g;
}

RenderStudyResult run_render_study(const model::Model& model, const RenderStudyOptions& options) {
  const Scene& scene = model.spec;
  if (!model.camera)
    throw std::invalid_argument(
        scene.origin + ": camera: the scene has no camera section (needed by study render)");
  RenderStudyResult out;
  out.grid = render_study_grid(options.quick);
  const RenderStudyGrid& g = out.grid;
  for (double s : g.scales) {
    const CameraSpec c = scaled_camera(*scene.camera, s);
    out.resolutions.emplace_back(c.width, c.height);
  }
  out.seed = scene.effects.seed;
  const camera::CameraModel& base = *model.camera;
  out.projection_biased = base.distorted() || !(std::abs(base.R(2, 2)) > 1 - 1e-12);

  out.load_start = load_average_1min();
  const auto wall0 = std::chrono::steady_clock::now();
  out.positions = free_positions(scene, g.scales, g.positions, out.seed);
  long done = 0;
  const long total = static_cast<long>(g.factors.size() * g.scales.size() * out.positions.size());
  for (double s : g.scales)
    for (int f : g.factors)
      out.cells.push_back(measure_cell(scene, s, f, out.positions, g.timing_seconds, out.gl, [&] {
        ++done;
        if (options.progress) options.progress(done, total);
      }));
  out.wall_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  out.load_end = load_average_1min();
  return out;
}

std::string render_study_csv(const RenderStudyResult& result) { return render_csv(result.cells); }

}  // namespace flatland::studies
