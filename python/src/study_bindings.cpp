// The speed-accuracy studies (`flatland study NAME`): each returns its CSV, the file the CLI
// writes, which flatland.study turns into one array per column.
#include "convert.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/studies/calibration_study.hpp"
#include "flatland/studies/closed_loop_study.hpp"
#include "flatland/studies/render_study.hpp"
#include "flatland/studies/sim_study.hpp"
#include "flatland/studies/tracker_study.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <thread>

namespace flatland::python {

using namespace pybind11::literals;

namespace {

/// The scene a study runs on: the argument, else the bundled scene the CLI's study takes.
Scene study_scene(const py::object& scene, const std::string& bundled) {
  if (!scene.is_none()) return scene_argument(scene);
  return load_scene(data_directory() + "/scenes/" + bundled);
}

std::shared_ptr<const model::Model> camera_model(const py::object& scene,
                                                 const std::string& study) {
  const auto model = model_argument(
      scene.is_none() ? py::object(py::str(data_directory() + "/scenes/butterfly-camera.yaml"))
                      : scene);
  if (!model->camera)
    throw std::invalid_argument(model->spec.origin +
                                ": camera: the scene has no camera section (needed by study " +
                                study + ")");
  return model;
}

std::string study_binding(const std::string& name, const py::object& scene, bool quick) {
  const auto progress = InterruptScope::progress();
  if (name == "sim") {
    const Scene s = study_scene(scene, "butterfly.yaml");
    return run_interruptible([&] {
      studies::SimStudyOptions options;
      options.quick = quick;
      options.progress = progress;
      return studies::sim_study_csv(studies::run_sim_study(s.sim, options));
    });
  }
  if (name == "calibration") {
    return run_interruptible([&] {
      studies::CalibrationStudyOptions options;
      options.quick = quick;
      options.progress = progress;
      return studies::calibration_study_csv(studies::run_calibration_study(options));
    });
  }
  if (name == "render") {
    const auto model = camera_model(scene, name);
    return run_interruptible([&] {
      studies::RenderStudyOptions options;
      options.quick = quick;
      options.progress = progress;
      return studies::render_study_csv(studies::run_render_study(*model, options));
    });
  }
  if (name == "tracker") {
    const auto model = camera_model(scene, name);
    return run_interruptible([&] {
      studies::TrackerStudyOptions options;
      options.quick = quick;
      options.progress = progress;
      return studies::tracker_study_csv(studies::run_tracker_study(*model, options));
    });
  }
  if (name == "closed-loop") {
    const auto nominal = model::compile(study_scene(scene, "airtable-feedback.yaml"));
    const studies::ClosedLoopGrid grid = studies::closed_loop_grid(*nominal, quick);
    return run_interruptible([&] {
      studies::ClosedLoopStudyOptions options;
      options.threads = std::max(1u, std::thread::hardware_concurrency());
      options.progress = progress;
      return studies::closed_loop_study_csv(
          studies::run_closed_loop_study(*nominal, grid, options));
    });
  }
  throw std::invalid_argument("name: unknown study '" + name +
                              "' (sim, calibration, render, tracker, closed-loop)");
}

}  // namespace

void bind_studies(py::module_& m) {
  m.def("study", &study_binding, "name"_a, "scene"_a, "quick"_a);
}

}  // namespace flatland::python
