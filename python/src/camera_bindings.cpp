// Cameras: Renderer (frames as numpy arrays, with their truth), Tracker (the disk in a frame, and
// its s_h), calibrate (a camera from board images or corners) and a rendered calibration session.
#include "convert.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/drivers/calibration_session.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/sim/format.hpp"
#include "flatland/sim/spatial_spec.hpp"
#include "flatland/sim/spec.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <mutex>
#include <optional>

namespace flatland::python {

using namespace pybind11::literals;

py::dict camera_to_python(const camera::CameraModel& c) {
  const auto matrix = [](const cv::Matx33d& m) {
    py::array_t<double> a({3, 3});
    for (int r = 0; r < 3; ++r)
      for (int col = 0; col < 3; ++col) a.mutable_at(r, col) = m(r, col);
    return a;
  };
  py::dict d;
  d["width"] = c.width;
  d["height"] = c.height;
  d["fps"] = c.fps;
  d["exposure"] = c.exposure;
  d["K"] = matrix(c.K);
  const int n = c.rational() ? 8 : 5;
  py::array_t<double> dist(n);
  for (int i = 0; i < n; ++i) dist.mutable_at(i) = c.dist[i];
  d["dist"] = dist;
  d["R"] = matrix(c.R);
  d["t"] = py::array_t<double>(3, c.t.val);
  return d;
}

namespace {

py::tuple point(const cv::Point2d& p) { return py::make_tuple(p.x, p.y); }
py::tuple point(const cv::Point3d& p) { return py::make_tuple(p.x, p.y, p.z); }

py::dict truth_to_python(const render::FrameTruth& t) {
  py::dict d;
  d["t"] = t.t;
  d["theta"] = t.theta;
  d["s_h"] = t.s_h;
  d["disk_center_table"] = point(t.disk_center_table);
  d["marker_table"] = point(t.marker_table);
  d["disk_center_px"] = point(t.disk_center_px);
  d["marker_px"] = point(t.marker_px);
  d["dropped"] = t.dropped;
  d["t_state"] = t.t_state;
  return d;
}

/// A Renderer of a compiled scene, with the scene's run (simulated at the first render(t=...)).
class PyRenderer {
 public:
  PyRenderer(const py::object& scene, const std::optional<std::string>& backend,
             std::optional<double> duration)
      : duration_(duration) {
    if (duration && !(std::isfinite(*duration) && *duration > 0))
      throw std::invalid_argument("duration: must be positive and finite (s), got " +
                                  sim::format_number(*duration));
    std::optional<render::GlBackend> gl;
    if (backend) gl = render::parse_backend(*backend);
    if (py::isinstance<PyModel>(scene)) {
      model_ = scene.cast<const PyModel&>().model;
    } else {
      Scene loaded = scene_argument(scene, true, "model");
      if (loaded.spatial) {
        // A spatial scene: its run sampled at the camera's rate, as `flatland render` draws it.
        sim::SpatialSpec spec = *loaded.spatial;
        if (duration) spec.duration = *duration;
        spatial_ = std::make_unique<SpatialRun>();
        try {
          spatial_->setup = sim::build_spatial(spec);
        } catch (const std::invalid_argument& e) {
          throw std::invalid_argument(loaded.origin + ": " + e.what());
        }
        renderer_ = std::make_unique<render::Renderer>(
            model::spatial_render_setup(loaded, spatial_->setup), gl);
        return;
      }
      model_ = model::compile(std::move(loaded));
    }
    renderer_ = std::make_unique<render::Renderer>(model::render_setup(*model_), gl);
  }

  /// With `mask`, the truth holds the segmentation mask (H x W uint8 MaskId) under "mask".
  py::tuple render_at(double t, bool mask) {
    if (!std::isfinite(t)) throw std::invalid_argument("t: must be a finite time, s");
    if (spatial_) {
      if (mask) throw std::invalid_argument("mask: a spatial scene has no segmentation mask");
      return render_spatial_at(t);
    }
    render::CaptureOptions capture_options;
    capture_options.mask = mask;
    render::Frame frame = run_interruptible([&] {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!run_) {
        sim::SimulationSpec spec = model_->spec.sim;
        if (duration_) spec.duration = *duration_;
        spec.run.record = true;  // the frames sample the dense output
        run_ = std::make_unique<sim::RunResult>(sim::run_spec(spec));
        if (run_->trajectory.empty()) throw std::runtime_error("the run recorded no trajectory");
      }
      const double t0 = run_->trajectory.t_begin(), t1 = run_->trajectory.t_end();
      if (t < t0 - 1e-12 || t > t1 + 1e-12)
        throw std::invalid_argument("t: outside the scene's run [" + sim::format_number(t0) + ", " +
                                    sim::format_number(t1) + "] s, got " + sim::format_number(t));
      return renderer_->capture(run_->trajectory, t, capture_options);
    });
    py::dict truth = truth_to_python(frame.truth);
    if (mask && !frame.truth.dropped) truth["mask"] = image_to_numpy(frame.mask);
    return py::make_tuple(
        frame.truth.dropped ? py::object(py::none()) : image_to_numpy(frame.image), truth);
  }

  py::tuple render_state(double hand_angle, std::pair<double, double> disk_center,
                         double disk_angle, double t, bool mask) {
    if (spatial_)
      throw std::invalid_argument(
          "state: a planar scene's state (hand angle, disk centre); a spatial scene renders its "
          "run's frames, render(t=k / fps)");
    render::SceneState state;
    state.t = t;
    state.hand_angle = hand_angle;
    state.disk_center = {disk_center.first, disk_center.second};
    state.disk_angle = disk_angle;
    for (double v : {hand_angle, disk_center.first, disk_center.second, disk_angle, t})
      if (!std::isfinite(v)) throw std::invalid_argument("state: every value must be finite");
    cv::Mat image, ids;
    render::FrameTruth truth;
    {
      py::gil_scoped_release release;
      const std::lock_guard<std::mutex> lock(mutex_);
      image = renderer_->render_8u(state);
      truth = renderer_->truth(state);
      if (mask) ids = renderer_->render_mask(state);
    }
    py::dict truth_dict = truth_to_python(truth);
    if (mask) truth_dict["mask"] = image_to_numpy(ids);
    return py::make_tuple(image_to_numpy(image), truth_dict);
  }

  /// The run's end: the scene's (or the duration's) until the run is made, then where it stopped.
  double t_end() const {
    if (spatial_)
      return spatial_->frames.empty() ? spatial_->setup.options.t_end : spatial_->frames.back().t;
    if (run_) return run_->trajectory.t_end();
    return duration_ ? model_->spec.sim.initial.t0 + *duration_ : model_->spec.sim.end_time();
  }
  std::string gl() const { return renderer_->gl_description(); }
  py::dict camera() const { return camera_to_python(renderer_->camera()); }

 private:
  /// A spatial scene's setup and, once run, its frames: the samples on the camera's frame grid
  /// (the run's first sample, then every one at k / fps; its last, an event's time, is not one).
  struct SpatialRun {
    sim::SpatialSetup setup;
    std::vector<sim::SpatialSample> frames;
    bool ran = false;
  };

  py::tuple render_spatial_at(double t) {
    const double fps = renderer_->camera().fps;
    cv::Mat image;
    render::FrameTruth truth;
    run_interruptible([&] {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (!spatial_->ran) {
        sim::SpatialSetup& setup = spatial_->setup;
        setup.options.sample_dt = 1.0 / fps;
        setup.options.record = true;
        setup.options.progress = [](double) { InterruptScope::check(); };
        const sim::SpatialRunResult run = sim::run_spatial(setup);
        for (const sim::SpatialSample& sample : run.samples)
          if (spatial_->frames.empty() ||
              std::abs(sample.t * fps - std::round(sample.t * fps)) <= 1e-6)
            spatial_->frames.push_back(sample);
        spatial_->ran = true;
      }
      const double index = std::round(t * fps);
      if (std::abs(t * fps - index) > 1e-6)
        throw std::invalid_argument("t: a spatial scene is drawn at its camera's frames, t = k / " +
                                    sim::format_number(fps) + " s, got " + sim::format_number(t));
      const auto& frames = spatial_->frames;
      const auto at = std::find_if(frames.begin(), frames.end(), [&](const sim::SpatialSample& f) {
        return std::abs(f.t * fps - index) <= 1e-6;
      });
      if (at == frames.end())
        throw std::invalid_argument(
            "t: outside the scene's run [" + sim::format_number(frames.front().t) + ", " +
            sim::format_number(frames.back().t) + "] s, got " + sim::format_number(t));
      const render::SceneState state =
          render::SceneState::from_spatial_sample(*at, spatial_->setup.motion->at(at->t));
      image = renderer_->render_8u(state);
      truth = renderer_->truth(state);
      return 0;
    });
    return py::make_tuple(image_to_numpy(image), truth_to_python(truth));
  }

  std::shared_ptr<const model::Model> model_;
  std::unique_ptr<SpatialRun> spatial_;
  std::unique_ptr<render::Renderer> renderer_;
  std::optional<double> duration_;
  std::unique_ptr<sim::RunResult> run_;
  // The GIL is released while a frame renders: calls from several Python threads take turns.
  std::mutex mutex_;
};

/// A Tracker knowing a compiled scene's camera (and its hand, for s_h), or none.
class PyTracker {
 public:
  PyTracker(const py::object& scene, const std::optional<std::string>& method) {
    vision::TrackerConfig config;
    if (!scene.is_none()) {
      model_ = model_argument(scene, "model");
      config = model_->tracker;
      mapping_ = model_->mapping;
    }
    if (method) config.method = vision::parse_track_method(*method);
    tracker_ = std::make_unique<vision::Tracker>(config);
  }

  py::dict track(const py::array& frame, std::optional<double> theta) {
    const cv::Mat image = numpy_to_image(frame, "frame");
    if (theta && !std::isfinite(*theta)) throw std::invalid_argument("theta: must be finite, rad");
    vision::TrackResult r;
    std::optional<vision::ContactEstimate> contact;
    {
      py::gil_scoped_release release;
      const std::lock_guard<std::mutex> lock(mutex_);
      r = tracker_->track(image);
      if (r.ok() && theta && mapping_) {
        contact = vision::follow_contact(*mapping_, r.center, *theta, s_guess_);
        if (contact) s_guess_ = contact->s_h;
      }
    }
    py::dict d;
    d["state"] = vision::to_string(r.state);
    d["center"] = r.ok() ? py::object(point(r.center)) : py::none();
    d["radius_px"] = r.radius_px;
    d["sigma_px"] = r.sigma_px;
    d["quality"] = r.quality;
    d["edge_points"] = r.edge_points;
    d["s_h"] = contact ? py::object(py::float_(contact->s_h)) : py::none();
    return d;
  }

  void reset() {
    const std::lock_guard<std::mutex> lock(mutex_);
    tracker_->reset();
    s_guess_ = std::nan("");
  }

 private:
  std::shared_ptr<const model::Model> model_;
  std::optional<vision::HandMapping> mapping_;
  std::unique_ptr<vision::Tracker> tracker_;
  double s_guess_ = std::nan("");
  std::mutex mutex_;  ///< as the Renderer's: a stateful tracker, one frame at a time
};

std::vector<cv::Point2f> points2(const py::array_t<double>& a, const std::string& name) {
  if (a.ndim() != 2 || a.shape(1) != 2)
    throw std::invalid_argument(name + ": an array of shape (N, 2)");
  std::vector<cv::Point2f> out;
  for (py::ssize_t i = 0; i < a.shape(0); ++i)
    out.emplace_back(static_cast<float>(a.at(i, 0)), static_cast<float>(a.at(i, 1)));
  return out;
}

std::vector<cv::Point3f> points3(const py::array_t<double>& a, const std::string& name) {
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw std::invalid_argument(name + ": an array of shape (N, 3)");
  std::vector<cv::Point3f> out;
  for (py::ssize_t i = 0; i < a.shape(0); ++i)
    out.emplace_back(static_cast<float>(a.at(i, 0)), static_cast<float>(a.at(i, 1)),
                     static_cast<float>(a.at(i, 2)));
  return out;
}

py::dict calibrate_binding(const std::string& board_text, const std::optional<py::list>& images,
                           const std::optional<py::list>& corners,
                           std::optional<std::pair<int, int>> image_size, const std::string& fix,
                           bool rational) {
  const camera::Board board = camera::Board::parse(board_text, "board");
  if (images.has_value() == corners.has_value())
    throw std::invalid_argument("images/corners: give exactly one of them");
  calibration::IntrinsicsOptions options;
  options.parse_fixed(fix);
  options.rational_model = rational;
  std::vector<calibration::BoardView> views;
  std::vector<std::string> not_found;
  if (images) {
    std::vector<py::array> arrays;  // kept alive while their Mats are read
    for (std::size_t i = 0; i < images->size(); ++i)
      arrays.push_back(cast_argument<py::array>((*images)[i], "images[" + std::to_string(i) + "]",
                                                "an image array"));
    std::vector<cv::Mat> mats;
    for (std::size_t i = 0; i < arrays.size(); ++i)
      mats.push_back(numpy_to_image(arrays[i], ("images[" + std::to_string(i) + "]").c_str()));
    py::gil_scoped_release release;
    for (std::size_t i = 0; i < mats.size(); ++i) {
      const std::string name = "images[" + std::to_string(i) + "]";
      if (auto v = calibration::detect_board(mats[i], board, name))
        views.push_back(std::move(*v));
      else
        not_found.push_back(name);
    }
  } else {
    if (!image_size)
      throw std::invalid_argument("image_size: (width, height) is needed with corners");
    if (image_size->first < 1 || image_size->second < 1)
      throw std::invalid_argument("image_size: width and height must be positive");
    for (std::size_t i = 0; i < corners->size(); ++i) {
      const std::string name = "corners[" + std::to_string(i) + "]";
      const auto pair = cast_argument<py::tuple>(
          (*corners)[i], name, "a pair (image_points (N, 2), object_points (N, 3))");
      if (pair.size() != 2)
        throw std::invalid_argument(name + ": a pair (image_points (N, 2), object_points (N, 3))");
      calibration::BoardView v;
      v.name = name;
      v.image_size = {image_size->first, image_size->second};
      v.image_points = points2(cast_argument<py::array_t<double>>(pair[0], name + "[0]", "numbers"),
                               name + "[0]");
      v.object_points = points3(
          cast_argument<py::array_t<double>>(pair[1], name + "[1]", "numbers"), name + "[1]");
      if (v.image_points.size() != v.object_points.size())
        throw std::invalid_argument(name + ": as many image points as object points");
      views.push_back(std::move(v));
    }
  }
  const calibration::IntrinsicsResult r =
      run_interruptible([&] { return calibration::calibrate_intrinsics(views, options); });
  py::dict d;
  d["camera"] = camera_to_python(r.camera());
  d["rms_px"] = r.rms_px;
  d["views_used"] = r.views_used();
  d["view_rms_px"] = r.view_rms_px;
  d["rejected"] = r.rejected;
  d["not_found"] = not_found;
  d["std"] = r.std;
  return d;
}

py::dict render_calibration_binding(const py::object& scene, int intrinsics_views, int table_views,
                                    int joint_views, std::uint64_t seed, const std::string& board) {
  const auto compiled = model_argument(scene, "model");
  drivers::SessionOptions options;
  options.intrinsics_views = intrinsics_views;
  options.table_views = table_views;
  options.joint_views = joint_views;
  options.seed = seed;
  options.board = board;
  std::vector<std::pair<std::string, cv::Mat>> images;
  const drivers::CalibrationSession session = run_interruptible([&] {
    return drivers::render_calibration_session(*compiled, options,
                                               [&](const std::string& path, const cv::Mat& image) {
                                                 InterruptScope::check();
                                                 images.emplace_back(path, image.clone());
                                               });
  });
  py::dict out;
  py::dict by_path;
  for (const auto& [path, image] : images) by_path[py::str(path)] = image_to_numpy(image);
  out["images"] = by_path;
  out["board"] = session.board.notation();
  out["intrinsics_images"] = session.intrinsics_images;
  out["camera"] = camera_to_python(session.truth.camera);
  return out;
}

/// A camera from the arrays flatland.write_camera_file and flatland.project hand over, whose
/// shapes and values the Python side has checked (flatland/__init__.py, _camera).

// Row-major, as the loops below index them: a transposed (Fortran-ordered) K or R from numpy is
// copied into C order on the way in instead of being read transposed.
using CArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

camera::CameraModel camera_from_arrays(int width, int height, const CArray& K, const CArray& dist,
                                       const std::optional<CArray>& R,
                                       const std::optional<CArray>& t, double fps,
                                       double exposure) {
  if (K.size() != 9 || (dist.size() != 5 && dist.size() != 8) || (R && R->size() != 9) ||
      (t && t->size() != 3))
    throw std::invalid_argument("camera: K 3 x 3, dist 5 or 8, R 3 x 3 and t 3 numbers");
  camera::CameraModel m;
  m.width = width;
  m.height = height;
  m.fps = fps;
  m.exposure = exposure;
  for (int i = 0; i < 9; ++i) m.K.val[i] = K.data()[i];
  for (py::ssize_t i = 0; i < dist.size(); ++i) m.dist[static_cast<int>(i)] = dist.data()[i];
  if (R)
    for (int i = 0; i < 9; ++i) m.R.val[i] = R->data()[i];
  if (t)
    for (int i = 0; i < 3; ++i) m.t[i] = t->data()[i];
  return m;
}

py::dict camera_file_to_python(const camera::CameraFile& f) {
  py::dict d;
  d["camera_name"] = f.camera_name;
  d["camera"] = camera_to_python(f.camera);
  d["rational_model"] = f.rational_model;
  d["table_pose"] = f.has_table_pose;
  d["joint"] = py::none();
  if (f.joint) {
    py::dict j;
    j["axis_table"] = point(f.joint->axis_table);
    j["encoder_offset"] = f.joint->encoder_offset;
    d["joint"] = j;
  }
  d["report"] = py::none();
  if (f.report) {
    py::dict r;
    r["rms_px"] = f.report->rms_px;
    r["view_rms_px"] = f.report->view_rms_px;
    r["views_used"] = f.report->views_used;
    r["views_rejected"] = f.report->views_rejected;
    r["std"] = f.report->std;
    r["std_rational"] = f.report->std_rational ? py::cast(*f.report->std_rational) : py::none();
    d["report"] = r;
  }
  d["table_report"] = py::none();
  if (f.table_report) {
    py::dict r;
    r["rms_px"] = f.table_report->rms_px;
    r["corners"] = f.table_report->corners;
    r["images"] = f.table_report->images;
    d["table_report"] = r;
  }
  d["joint_report"] = py::none();
  if (f.joint_report) {
    const camera::JointFitReport& j = *f.joint_report;
    py::dict r;
    r["images"] = j.images;
    r["inliers"] = j.inliers;
    r["center_rms_m"] = j.center_rms_m;
    r["angle_rms_rad"] = j.angle_rms_rad;
    r["sigma_axis_m"] = j.sigma_axis_m;
    r["sigma_offset_rad"] = j.sigma_offset_rad;
    d["joint_report"] = r;
  }
  // Sections written with calibrate --force although their data could not support them.
  py::list unsupported;
  for (const std::string& u : f.unsupported) unsupported.append(u);
  d["unsupported"] = unsupported;
  return d;
}

void write_camera_file_binding(const std::string& path, const std::string& camera_name, int width,
                               int height, const CArray& K, const CArray& dist,
                               const std::optional<CArray>& R, const std::optional<CArray>& t,
                               double fps, double exposure,
                               std::optional<std::tuple<double, double, double>> joint,
                               const std::vector<std::string>& unsupported, bool force) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  const fs::path folder = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  if (!fs::is_directory(folder)) throw std::invalid_argument("path: no folder " + folder.string());
  if (fs::is_directory(target)) throw std::invalid_argument("path: " + path + " is a folder");
  if (fs::exists(target) && !force)
    throw std::invalid_argument("path: " + path +
                                " exists (force=True overwrites it); flatland never overwrites "
                                "an output unasked");
  camera::CameraFile file;
  file.camera_name = camera_name;
  file.camera = camera_from_arrays(width, height, K, dist, R, t, fps, exposure);
  file.rational_model = dist.size() == 8;
  file.has_table_pose = R.has_value();
  if (joint) {
    camera::JointCalibration j;
    j.axis_table = {std::get<0>(*joint), std::get<1>(*joint)};
    j.encoder_offset = std::get<2>(*joint);
    file.joint = j;
  }
  // A section calibrate --force wrote against its data stays marked when the file is written
  // again (read_camera_file's "unsupported").
  file.unsupported = unsupported;
  // Written whole beside its place and renamed into it (camera::write_camera_file).
  camera::write_camera_file(path, file);
}

py::array_t<double> project_binding(int width, int height, const CArray& K, const CArray& dist,
                                    const std::optional<CArray>& R, const std::optional<CArray>& t,
                                    const CArray& points) {
  const camera::CameraModel m = camera_from_arrays(width, height, K, dist, R, t, 30.0, 0.0);
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw std::invalid_argument("points: an array of shape (N, 3)");
  std::vector<cv::Point3d> table;
  for (py::ssize_t i = 0; i < points.shape(0); ++i)
    table.emplace_back(points.at(i, 0), points.at(i, 1), points.at(i, 2));
  const std::vector<cv::Point2d> px = table.empty() ? std::vector<cv::Point2d>{} : m.project(table);
  py::array_t<double> out({static_cast<py::ssize_t>(px.size()), py::ssize_t{2}});
  for (std::size_t i = 0; i < px.size(); ++i) {
    out.mutable_at(i, 0) = px[i].x;
    out.mutable_at(i, 1) = px[i].y;
  }
  return out;
}

}  // namespace

void bind_camera(py::module_& m) {
  py::class_<PyRenderer>(m, "Renderer")
      .def(py::init<const py::object&, const std::optional<std::string>&, std::optional<double>>(),
           "model"_a, "backend"_a = py::none(), "duration"_a = py::none())
      .def("render_at", &PyRenderer::render_at, "t"_a, "mask"_a = false)
      .def("render_state", &PyRenderer::render_state, "hand_angle"_a, "disk_center"_a,
           "disk_angle"_a, "t"_a, "mask"_a = false)
      .def_property_readonly("t_end", &PyRenderer::t_end)
      .def_property_readonly("gl", &PyRenderer::gl)
      .def_property_readonly("camera", &PyRenderer::camera);
  py::class_<PyTracker>(m, "Tracker")
      .def(py::init<const py::object&, const std::optional<std::string>&>(), "model"_a,
           "method"_a = py::none())
      .def("track", &PyTracker::track, "frame"_a, "theta"_a = py::none())
      .def("reset", &PyTracker::reset);
  m.def("calibrate", &calibrate_binding, "board"_a, "images"_a, "corners"_a, "image_size"_a,
        "fix"_a, "rational"_a);
  m.def("render_calibration", &render_calibration_binding, "scene"_a, "intrinsics_views"_a,
        "table_views"_a, "joint_views"_a, "seed"_a, "board"_a);
  m.def(
      "read_camera_file",
      [](const std::string& path) { return camera_file_to_python(camera::read_camera_file(path)); },
      "path"_a);
  m.def("write_camera_file", &write_camera_file_binding, "path"_a, "camera_name"_a, "width"_a,
        "height"_a, "K"_a, "dist"_a, "R"_a, "t"_a, "fps"_a, "exposure"_a, "joint"_a,
        "unsupported"_a, "force"_a);
  m.def("project", &project_binding, "width"_a, "height"_a, "K"_a, "dist"_a, "R"_a, "t"_a,
        "points"_a);
}

}  // namespace flatland::python
