// Controllers and estimators written in Python behind the loop's interfaces
// (control/interfaces.hpp), and the loop's plain data as small Python classes: a controller is
// any object with a step method (start and name optional), an estimator any object with reset,
// propagate, update and estimate (counts and name optional). Each tick passes light objects
// (ControlInput, HandInput, Measurement: a few floats each), never numpy arrays. The adapters
// take the GIL inside each call only, so the loop runs with it released.
#pragma once

#include "convert.hpp"

#include "flatland/drivers/experiment.hpp"

#include <memory>
#include <string>
#include <vector>

namespace flatland::python {

/// The scene of an experiment: `scene` (a Model, a path) or, for None, the bundled closed-loop air
/// table (scenes/airtable-feedback.yaml), as `flatland experiment` has it.
Scene experiment_scene(const py::object& scene);

/// A loop's 1 kHz log as one array per column of log.csv, named without the unit (t, theta,
/// theta_dot, ...); stage and mode_true as str arrays.
py::dict log_columns(const std::vector<drivers::TickLog>& log);

/// A factory of controllers that call `controller`'s methods (one object serves every run it
/// makes). ValueError naming `keyword` at the call when it has no callable step, or a name that
/// is not a str.
drivers::ControllerFactory python_controller_factory(const py::object& controller,
                                                     const std::string& keyword = "controller");

/// The same for an estimator: reset, propagate, update and estimate must be callable.
drivers::EstimatorFactory python_estimator_factory(const py::object& estimator,
                                                   const std::string& keyword = "estimator");

/// What the caller chose for a loop: a built-in controller or estimator type by name goes into
/// the scene (`controller.type`, `estimator.type`; "feedback" and "open-loop" into
/// `controller.mode`), a Python object into a factory. ValueError for an unknown name.
struct LoopChoice {
  drivers::ControllerFactory controller;  ///< empty: the scene's
  drivers::EstimatorFactory estimator;    ///< empty: the scene's
};
LoopChoice choose_loop(Scene& scene, const py::object& controller, const py::object& estimator);

}  // namespace flatland::python
