// flatland study render: the command's side of studies::run_render_study (the renderer's
// centroid error against cv::projectPoints and its frames/s, against supersampling and
// resolution): render.csv, .json and the plots, the JSON on stdout or a table.
#include "study_vision.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/studies/render_study.hpp"

#include <algorithm>
#include <cmath>
#include <iostream>
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
  return scene;
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

/// One curve per resolution (selected by width, CSV column 2) of column `col` against the
/// supersampling factor; `dashed_col` adds a dashed curve of the same colour (0: none).
std::string per_resolution_curves(const std::vector<studies::RenderStudyCell>& cells, int col,
                                  int dashed_col, const std::string& what,
                                  const std::string& dashed_what) {
  std::vector<std::pair<int, int>> sizes;
  for (const studies::RenderStudyCell& c : cells)
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

  const studies::RenderStudyGrid grid = studies::render_study_grid(o.quick);
  std::cerr << "flatland: study render: " << grid.factors.size() * grid.scales.size() << " cells ("
            << grid.factors.size() << " supersampling factors x " << grid.scales.size()
            << " resolutions) x " << grid.positions << " disk positions x 2 turns, " << scene.origin
            << "\n";
  studies::RenderStudyResult study;
  {
    ProgressBar bar("study render");
    studies::RenderStudyOptions so;
    so.quick = o.quick;
    so.progress = bar.callback();
    study = studies::run_render_study(*model::compile(scene), so);
  }
  const std::vector<int>& factors = grid.factors;
  const std::vector<studies::RenderStudyPosition>& positions = study.positions;
  const std::vector<studies::RenderStudyCell>& cells = study.cells;
  const std::string& gl = study.gl;
  const double timing_seconds = grid.timing_seconds, wall = study.wall_seconds;
  const double load_start = study.load_start, load_end = study.load_end;
  const double bound = studies::kRenderAcceptancePx;
  const std::uint64_t seed = study.seed;

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
  for (const cv::Size& size : study.resolutions) res.push_back({size.width, size.height});
  j["resolutions"] = res;
  Json pos = Json::array();
  for (const studies::RenderStudyPosition& p : positions)
    pos.push_back({{"x", p.table.x}, {"y", p.table.y}, {"angle", p.angle}});
  j["positions"] = pos;
  Json rows = Json::array();
  for (const studies::RenderStudyCell& c : cells) {
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
  if (!study.projection_biased) {
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
    outputs.stage(dir / "render.csv", studies::render_study_csv(study));
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
  for (const studies::RenderStudyCell& c : cells) {
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
