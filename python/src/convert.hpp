// What every binding file needs: JSON reports as Python dicts, images as numpy arrays (and back),
// the scene a call runs on, and interruption of long calls by Ctrl-C.
#pragma once

#include "flatland/api/reports.hpp"
#include "flatland/model/model.hpp"
#include "flatland/scene/scene.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <opencv2/core.hpp>

#include <functional>
#include <memory>
#include <string>

namespace flatland::python {

namespace py = pybind11;

/// The compiled scene as Python holds it: the Model and nothing else.
struct PyModel {
  std::shared_ptr<const model::Model> model;
};

/// A JSON value as the same Python value (objects keep their key order).
py::object to_python(const api::Json& j);

/// A camera as a dict: width, height, fps, exposure, K (3x3), dist (OpenCV's order, 8 or 14),
/// R (3x3) and t (3): x_cam = R x_table + t.
py::dict camera_to_python(const camera::CameraModel& camera);

/// The scene a call runs on: a Model's (its spec), a file's (str or os.PathLike), or the bundled
/// default (None). A spatial scene (space: 3d) only where `spatial_ok` (simulate, Renderer);
/// elsewhere a ValueError naming the `keyword` it came by and the scene.
Scene scene_argument(const py::object& scene, bool spatial_ok = false,
                     const std::string& keyword = "scene");
/// The same compiled: a Model is used as it is.
std::shared_ptr<const model::Model> model_argument(const py::object& scene,
                                                   const std::string& keyword = "scene");

/// An 8-bit (or float) OpenCV image as a numpy array that shares its pixels (no copy): H x W x C,
/// or H x W for one channel. BGR stays BGR, as OpenCV's Python binding returns images.
py::array image_to_numpy(const cv::Mat& image);
/// A numpy image (H x W or H x W x 3, uint8 or float32) as a cv::Mat over the same memory; the
/// array must stay alive while the Mat is used. ValueError naming `argument` otherwise.
cv::Mat numpy_to_image(const py::array& array, const char* argument);

/// h as a T, or std::invalid_argument (ValueError) "NAME: WHAT, got a TYPE" when it is not one.
template <class T>
T cast_argument(const py::handle& h, const std::string& name, const std::string& what) {
  const auto wrong = [&] {
    return std::invalid_argument(name + ": " + what + ", got a " +
                                 std::string(py::str(py::type::of(h).attr("__name__"))));
  };
  try {
    return h.cast<T>();
  } catch (const py::cast_error&) {
    throw wrong();
  } catch (const py::error_already_set&) {  // a conversion that raised (tuple(5): TypeError)
    throw wrong();
  }
}

/// Thrown by a progress callback after Ctrl-C: not a std::exception, so that no library code
/// that turns exceptions into results (a failed study cell) can swallow it.
struct Interrupted {};

/// For the duration of a long call, whose GIL is released: SIGINT sets a flag instead of
/// Python's handler (which could run only when the call returns). `check` throws Interrupted once
/// it is set; progress callbacks call it, from any thread. At the end of the scope Python's
/// handler is back, and an interruption becomes KeyboardInterrupt.
class InterruptScope {
 public:
  InterruptScope();
  ~InterruptScope();
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;
  static void check();
  /// Whether Ctrl-C came during the scope (also when no callback noticed it).
  static bool interrupted();
  /// A sim::Progress-shaped callback that only checks.
  static std::function<void(long, long)> progress() {
    return [](long, long) { check(); };
  }
};

/// Run `work` with the GIL released and Ctrl-C armed; KeyboardInterrupt if it was interrupted.
/// A call without progress callbacks is not stopped, but its result is dropped.
template <class Work>
auto run_interruptible(Work&& work) {
  const auto keyboard_interrupt = [] {
    PyErr_SetNone(PyExc_KeyboardInterrupt);
    return py::error_already_set();
  };
  std::unique_ptr<InterruptScope> scope;
  try {
    auto result = [&] {
      py::gil_scoped_release release;
      scope = std::make_unique<InterruptScope>();
      return work();
    }();
    const bool interrupted = InterruptScope::interrupted();
    scope.reset();
    if (interrupted) throw keyboard_interrupt();
    return result;
  } catch (const Interrupted&) {
    scope.reset();
    throw keyboard_interrupt();
  }
}

void bind_sim(py::module_& m);
void bind_camera(py::module_& m);
void bind_loop(py::module_& m);
/// Plan, ControllerContext, ControlInput, ControlOutput, ... (python_loop.cpp).
void bind_loop_types(py::module_& m);
/// The native half of flatland.Env (env_bindings.cpp).
void bind_env(py::module_& m);
void bind_studies(py::module_& m);
/// flatland.identify and flatland.validate_world (identify_bindings.cpp).
void bind_identify(py::module_& m);

}  // namespace flatland::python
