// flatland._flatland: the native half of the Python package `flatland`. The public functions,
// with their signatures and docstrings, are in flatland/__init__.py; these take every argument.
// Errors: std::invalid_argument (bad input, the CLI's exit 2) is ValueError and
// std::runtime_error (the CLI's exit 1) is RuntimeError, pybind11's own translation.
#include "convert.hpp"

PYBIND11_MODULE(_flatland, m) {
  m.doc() = "flatland's native module; use the package flatland (help(flatland)).";
  flatland::python::bind_sim(m);
  flatland::python::bind_camera(m);
  flatland::python::bind_loop_types(m);
  flatland::python::bind_loop(m);
  flatland::python::bind_env(m);
  flatland::python::bind_studies(m);
  flatland::python::bind_identify(m);
  m.def(
      "_noop", [] {}, "A call that does nothing: the binding's own overhead (benchmarks).");
}
