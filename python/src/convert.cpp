#include "convert.hpp"

#include "flatland/model/compile.hpp"

#include <pybind11/stl.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <mutex>

#include <signal.h>

namespace flatland::python {

py::object to_python(const api::Json& j) {
  switch (j.type()) {
    case api::Json::value_t::null:
      return py::none();
    case api::Json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case api::Json::value_t::number_integer:
      return py::int_(j.get<long long>());
    case api::Json::value_t::number_unsigned:
      return py::int_(j.get<unsigned long long>());
    case api::Json::value_t::number_float:
      return py::float_(j.get<double>());
    case api::Json::value_t::string:
      return py::str(j.get_ref<const std::string&>());
    case api::Json::value_t::array: {
      py::list list;
      for (const auto& v : j) list.append(to_python(v));
      return list;
    }
    case api::Json::value_t::object: {
      py::dict dict;
      for (const auto& [key, v] : j.items()) dict[py::str(key)] = to_python(v);
      return dict;
    }
    default:
      throw std::logic_error("to_python: a JSON value of an unexpected type");
  }
}

Scene scene_argument(const py::object& scene, bool spatial_ok, const std::string& keyword) {
  if (scene.is_none()) return load_scene(default_scene_path());
  if (py::isinstance<PyModel>(scene)) return scene.cast<const PyModel&>().model->spec;
  const py::object fspath = py::module_::import("os").attr("fspath");
  py::object path;
  try {
    path = fspath(scene);
  } catch (const py::error_already_set&) {
    throw std::invalid_argument(keyword + ": a Model, a path or None, got a " +
                                std::string(py::str(py::type::of(scene).attr("__name__"))));
  }
  if (!py::isinstance<py::str>(path))
    throw std::invalid_argument(keyword + ": a str path is needed");
  Scene loaded = load_scene(path.cast<std::string>());
  if (loaded.spatial && !spatial_ok)
    throw std::invalid_argument(keyword + ": " + loaded.origin +
                                " is a spatial scene (space: 3d); flatland.simulate and "
                                "flatland.Renderer run those, with no Model");
  return loaded;
}

std::shared_ptr<const model::Model> model_argument(const py::object& scene,
                                                   const std::string& keyword) {
  if (py::isinstance<PyModel>(scene)) return scene.cast<const PyModel&>().model;
  return model::compile(scene_argument(scene, false, keyword));
}

py::array image_to_numpy(const cv::Mat& image) {
  if (image.dims != 2) throw std::logic_error("image_to_numpy: not a 2-D image");
  py::dtype dtype = image.depth() == CV_8U    ? py::dtype::of<std::uint8_t>()
                    : image.depth() == CV_32F ? py::dtype::of<float>()
                                              : throw std::logic_error("image_to_numpy: depth");
  // The capsule owns a reference to the Mat's buffer: numpy shares the pixels and releases them.
  auto* owner = new cv::Mat(image);
  py::capsule base(owner, [](void* p) { delete static_cast<cv::Mat*>(p); });
  const auto elem = static_cast<py::ssize_t>(image.elemSize1());
  const int channels = image.channels();
  std::vector<py::ssize_t> shape = {image.rows, image.cols};
  std::vector<py::ssize_t> strides = {static_cast<py::ssize_t>(image.step[0]),
                                      static_cast<py::ssize_t>(image.step[1])};
  if (channels > 1) {
    shape.push_back(channels);
    strides.push_back(elem);
  }
  return py::array(dtype, shape, strides, owner->data, base);
}

cv::Mat numpy_to_image(const py::array& array, const char* argument) {
  const std::string name = argument;
  const int ndim = static_cast<int>(array.ndim());
  if (ndim != 2 && !(ndim == 3 && (array.shape(2) == 3 || array.shape(2) == 1)))
    throw std::invalid_argument(name + ": an image of shape (H, W) or (H, W, 3), got " +
                                std::to_string(ndim) + " dimensions");
  int depth;
  if (array.dtype().is(py::dtype::of<std::uint8_t>()))
    depth = CV_8U;
  else if (array.dtype().is(py::dtype::of<float>()))
    depth = CV_32F;
  else
    throw std::invalid_argument(name + ": uint8 or float32 pixels, got " +
                                std::string(py::str(array.dtype())));
  const int channels = ndim == 3 ? static_cast<int>(array.shape(2)) : 1;
  const auto elem = static_cast<py::ssize_t>(depth == CV_8U ? 1 : 4);
  if (array.shape(0) < 1 || array.shape(1) < 1)
    throw std::invalid_argument(name + ": an empty image");
  if (array.strides(1) != elem * channels || (ndim == 3 && array.strides(2) != elem))
    throw std::invalid_argument(name +
                                ": the pixels of each row must be contiguous "
                                "(numpy.ascontiguousarray)");
  return cv::Mat(static_cast<int>(array.shape(0)), static_cast<int>(array.shape(1)),
                 CV_MAKETYPE(depth, channels), const_cast<void*>(array.data()),
                 static_cast<std::size_t>(array.strides(0)));
}

namespace {

std::atomic<bool> g_interrupted{false};
// Long calls may run at once from several Python threads: the first one in installs the handler,
// the last one out puts Python's back.
std::mutex g_scope_mutex;
int g_scope_depth = 0;
struct sigaction g_python_handler;

extern "C" void on_sigint(int) { g_interrupted.store(true); }

}  // namespace

InterruptScope::InterruptScope() {
  const std::lock_guard<std::mutex> lock(g_scope_mutex);
  if (g_scope_depth++ > 0) return;
  g_interrupted.store(false);
  struct sigaction action {};
  action.sa_handler = on_sigint;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, &g_python_handler);
}

InterruptScope::~InterruptScope() {
  const std::lock_guard<std::mutex> lock(g_scope_mutex);
  if (--g_scope_depth == 0) sigaction(SIGINT, &g_python_handler, nullptr);
}

void InterruptScope::check() {
  if (g_interrupted.load()) throw Interrupted{};
}

bool InterruptScope::interrupted() { return g_interrupted.load(); }

}  // namespace flatland::python
