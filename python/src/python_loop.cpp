#include "python_loop.hpp"

#include "flatland/control/choice.hpp"
#include "flatland/drivers/tick_log_csv.hpp"
#include "flatland/sim/format.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <utility>
#include <vector>

namespace flatland::python {

using namespace pybind11::literals;

namespace {

constexpr double kNotGiven = std::numeric_limits<double>::quiet_NaN();

/// A Python object that C++ may copy and destroy without the GIL (the loop runs without it):
/// only the last owner touches the reference count, with the GIL taken.
using SharedObject = std::shared_ptr<py::object>;

SharedObject share(py::object object) {
  return SharedObject(new py::object(std::move(object)), [](py::object* p) {
    py::gil_scoped_acquire gil;
    delete p;
  });
}

std::string type_name(const py::handle& h) {
  return py::str(py::type::of(h).attr("__name__")).cast<std::string>();
}

/// One line: newlines and tabs as spaces.
std::string one_line(std::string text) {
  std::replace_if(
      text.begin(), text.end(), [](char c) { return c == '\n' || c == '\r' || c == '\t'; }, ' ');
  return text;
}

/// "ZeroDivisionError: division by zero" (the type alone when the message is empty).
std::string python_error_text(const py::error_already_set& e) {
  const std::string type = py::str(e.type().attr("__name__")).cast<std::string>();
  const std::string message = one_line(py::str(e.value()).cast<std::string>());
  return message.empty() ? type : type + ": " + message;
}

/// A returned value as a message shows it: "a str ('abc')", its repr cut to 40 characters.
std::string describe_value(const py::handle& h) {
  std::string repr = one_line(py::repr(h).cast<std::string>());
  if (repr.size() > 40) repr = repr.substr(0, 37) + "...";
  return "a " + type_name(h) + " (" + repr + ")";
}

/// A real number: float, int (not bool), or a numpy scalar or 0-d array of a real dtype.
std::optional<double> number_of(const py::handle& h) {
  PyObject* p = h.ptr();
  if (PyFloat_Check(p)) return PyFloat_AS_DOUBLE(p);
  if (PyBool_Check(p)) return std::nullopt;
  if (PyLong_Check(p)) {
    const double v = PyLong_AsDouble(p);
    if (v == -1.0 && PyErr_Occurred()) {  // beyond a double's range
      PyErr_Clear();
      return std::nullopt;
    }
    return v;
  }
  if (py::hasattr(h, "dtype") && py::hasattr(h, "ndim") && h.attr("ndim").cast<int>() == 0) {
    const std::string kind = py::str(h.attr("dtype").attr("kind")).cast<std::string>();
    if (kind == "f" || kind == "i" || kind == "u") return h.attr("__float__")().cast<double>();
  }
  return std::nullopt;
}

/// A keyword of one of the constructors below as a number, ValueError "NAME: a number, ...".
double number_argument(const py::handle& h, const std::string& name) {
  if (const auto v = number_of(h)) return *v;
  throw std::invalid_argument(name + ": a number, got a " + type_name(h));
}

std::optional<double> optional_number_argument(const py::handle& h, const std::string& name) {
  if (h.is_none()) return std::nullopt;
  return number_argument(h, name);
}

bool flag_argument(const py::handle& h, const std::string& name) {
  if (!PyBool_Check(h.ptr()))
    throw std::invalid_argument(name + ": True or False, got a " + type_name(h));
  return h.cast<bool>();
}

std::string at_time(double t) { return " at t = " + sim::format_significant(t, 6) + " s"; }

/// The object's name as the loop reports it: its `name` (a str, or a method returning one), else
/// its class's name.
std::string object_name(const py::object& object, const std::string& keyword) {
  if (!py::hasattr(object, "name")) return type_name(object);
  py::object name = object.attr("name");
  if (PyCallable_Check(name.ptr())) {
    try {
      name = name();
    } catch (py::error_already_set& e) {
      throw std::invalid_argument(keyword + ".name: raised " + python_error_text(e));
    }
  }
  if (!py::isinstance<py::str>(name))
    throw std::invalid_argument(keyword + ".name: a str (or a method returning one), got " +
                                describe_value(name));
  return name.cast<std::string>();
}

/// The bound method `method` of `object`, or nullptr when it has none and it is optional.
SharedObject method_of(const py::object& object, const char* method, const std::string& keyword,
                       bool required) {
  if (py::hasattr(object, method)) {
    py::object m = object.attr(method);
    if (PyCallable_Check(m.ptr())) return share(std::move(m));
    throw std::invalid_argument(keyword + "." + method + ": must be a method, got " +
                                describe_value(m));
  }
  if (!required) return nullptr;
  throw std::invalid_argument(keyword + ": a " + type_name(object) + " has no " + method +
                              " method (a controller needs step; an estimator reset, "
                              "propagate, update and estimate)");
}

// ---------------------------------------------------------------------------------------------

class PythonController final : public control::Controller {
 public:
  PythonController(SharedObject start, SharedObject step, std::string name)
      : start_(std::move(start)), step_(std::move(step)), name_(std::move(name)) {}

  void start(const control::ControllerContext& context) override {
    if (!start_) return;
    py::gil_scoped_acquire gil;
    try {
      (*start_)(context);
    } catch (py::error_already_set& e) {
      // A ValueError says the plan or model does not suit the law: bad input, as the interface
      // has it; anything else is a failure of the controller's own.
      const std::string what = "controller '" + name_ + "': start raised " + python_error_text(e);
      if (e.matches(PyExc_ValueError)) throw std::invalid_argument(what);
      throw std::runtime_error(what);
    }
  }

  control::ControlOutput step(const control::ControlInput& input) override {
    py::gil_scoped_acquire gil;
    py::object result;
    try {
      result = (*step_)(input);
    } catch (py::error_already_set& e) {
      // Not std::invalid_argument: the loop stops safely with this message.
      throw std::runtime_error("'" + name_ + "' raised " + python_error_text(e) + at_time(input.t));
    }
    if (py::isinstance<control::ControlOutput>(result)) {
      control::ControlOutput out = result.cast<control::ControlOutput>();
      if (out.mode.empty()) out.mode = name_;
      return out;
    }
    if (const auto value = number_of(result)) {
      control::ControlOutput out;
      out.theta_ddot = *value;
      out.mode = name_;
      out.theta_reference = kNotGiven;
      return out;
    }
    throw std::invalid_argument("controller '" + name_ + "': step returned " +
                                describe_value(result) + at_time(input.t) +
                                "; expected a number (rad/s^2) or a flatland.ControlOutput");
  }

  std::string name() const override { return name_; }

 private:
  SharedObject start_, step_;
  std::string name_;
};

// ---------------------------------------------------------------------------------------------

class PythonEstimator final : public control::Estimator {
 public:
  PythonEstimator(SharedObject reset, SharedObject propagate, SharedObject update,
                  SharedObject estimate, SharedObject counts, std::string name)
      : reset_(std::move(reset)),
        propagate_(std::move(propagate)),
        update_(std::move(update)),
        estimate_(std::move(estimate)),
        counts_(std::move(counts)),
        name_(std::move(name)) {}

  void reset(double t, double s_h, double sdot_h) override {
    py::gil_scoped_acquire gil;
    call(*reset_, "reset", t, t, s_h, sdot_h);
    t_ = t;
  }

  void propagate(double t_next, const control::HandInput& input) override {
    py::gil_scoped_acquire gil;
    call(*propagate_, "propagate", t_, t_next, input);
    t_ = t_next;
    ++steps_;
  }

  control::UpdateReport update(const control::Measurement& z) override {
    py::gil_scoped_acquire gil;
    const py::object r = call(*update_, "update", t_, z);
    ++updates_;
    control::UpdateReport report;
    report.applied = true;
    if (r.is_none()) return report;  // no innovation to report: the loop's gate never strikes
    if (py::isinstance<control::UpdateReport>(r))
      report = r.cast<control::UpdateReport>();
    else if (const auto nis = number_of(r))
      report.nis = *nis;
    else
      throw std::invalid_argument(prefix() + "update returned " + describe_value(r) + at_time(t_) +
                                  "; expected None, the NIS (a number) or a "
                                  "flatland.UpdateReport");
    if (!(std::isfinite(report.nis) && report.nis >= 0))
      throw std::invalid_argument(prefix() + "update returned an NIS of " +
                                  sim::format_significant(report.nis) + at_time(t_) +
                                  "; it must be finite and not negative");
    return report;
  }

  control::Estimate estimate() const override {
    py::gil_scoped_acquire gil;
    const py::object r = call(*estimate_, "estimate", t_);
    if (!py::isinstance<control::Estimate>(r))
      throw std::invalid_argument(prefix() + "estimate returned " + describe_value(r) +
                                  at_time(t_) + "; expected a flatland.Estimate");
    const control::Estimate e = r.cast<control::Estimate>();
    if (!(std::isfinite(e.t) && std::isfinite(e.s_h) && std::isfinite(e.sdot_h) &&
          e.covariance.allFinite()))
      throw std::invalid_argument(prefix() + "estimate returned a non-finite belief (s_h " +
                                  sim::format_significant(e.s_h) + ", sdot_h " +
                                  sim::format_significant(e.sdot_h) + ")" + at_time(t_));
    return e;
  }

  control::EstimatorCounts counts() const override {
    if (!counts_) return {steps_, 0, updates_};
    py::gil_scoped_acquire gil;
    const py::object r = call(*counts_, "counts", t_);
    if (!py::isinstance<control::EstimatorCounts>(r))
      throw std::invalid_argument(prefix() + "counts returned " + describe_value(r) +
                                  "; expected a flatland.EstimatorCounts");
    return r.cast<control::EstimatorCounts>();
  }

  std::string name() const override { return name_; }

 private:
  std::string prefix() const { return "estimator '" + name_ + "': "; }

  /// The method called with the GIL held; a Python exception becomes a runtime failure that
  /// names the method (the loop does not stop safely for an estimator: the run fails).
  template <class... Args>
  py::object call(const py::object& method, const char* what, double t, Args&&... args) const {
    try {
      return method(std::forward<Args>(args)...);
    } catch (py::error_already_set& e) {
      throw std::runtime_error(prefix() + what + " raised " + python_error_text(e) + at_time(t));
    }
  }

  SharedObject reset_, propagate_, update_, estimate_, counts_;
  std::string name_;
  double t_ = 0;
  long steps_ = 0, updates_ = 0;
};

// ---------------------------------------------------------------------------------------------

py::tuple covariance_tuple(const Eigen::Matrix2d& c) {
  return py::make_tuple(py::make_tuple(c(0, 0), c(0, 1)), py::make_tuple(c(1, 0), c(1, 1)));
}

Eigen::Matrix2d covariance_argument(const py::handle& h) {
  const std::string name = "Estimate.covariance";
  const auto wrong = [&] {
    return std::invalid_argument(name + ": 2 x 2 numbers ((var_s, cov), (cov, var_sdot)), got " +
                                 describe_value(h));
  };
  // A numpy array as nested lists; then a sequence of two sequences of two numbers.
  const py::object rows =
      py::hasattr(h, "tolist") ? h.attr("tolist")() : py::reinterpret_borrow<py::object>(h);
  const auto pair = [](const py::handle& x) {
    return py::isinstance<py::sequence>(x) && !py::isinstance<py::str>(x) && py::len(x) == 2;
  };
  if (!pair(rows)) throw wrong();
  Eigen::Matrix2d c;
  for (int i = 0; i < 2; ++i) {
    const py::object row = rows[py::int_(i)];
    if (!pair(row)) throw wrong();
    for (int j = 0; j < 2; ++j) {
      const auto v = number_of(row[py::int_(j)]);
      if (!v) throw wrong();
      c(i, j) = *v;
    }
  }
  if (!c.allFinite()) throw std::invalid_argument(name + ": every entry must be finite");
  if (!(c(0, 0) >= 0 && c(1, 1) >= 0))
    throw std::invalid_argument(name + ": the variances (the diagonal) must not be negative");
  return c;
}

std::string stop_detail(const std::optional<control::StopReason>& stop) {
  return stop ? stop->detail : std::string();
}

void bind_plan(py::module_& m) {
  py::class_<control::Plan, std::shared_ptr<control::Plan>>(
      m, "Plan",
      "The planned motion (nominal model, no losses) and the disk's planned s_h along it, "
      "read-only.")
      .def_property_readonly("duration", &control::Plan::duration, "s, the plan's length")
      .def(
          "hand",
          [](const control::Plan& p, double t) {
            const sim::HandKinematics k = p.hand(t);
            return py::make_tuple(k.angle, k.angular_velocity, k.angular_acceleration);
          },
          "t"_a, "(angle rad, rate rad/s, acceleration rad/s^2) of the planned hand at time t")
      .def("time_at", &control::Plan::time_at, "s_h"_a,
           "the planned time at which s_h is reached (clamped to [s_from, s_to])")
      .def("s_h_at", &control::Plan::s_h_at, "t"_a, "the planned s_h at time t")
      .def("sdot_h_at", &control::Plan::sdot_h_at, "t"_a, "the planned rate of s_h at time t")
      .def_property_readonly("s_from", &control::Plan::s_from,
                             "the lookup's lower end (controller.dip_until)")
      .def_property_readonly("s_to", &control::Plan::s_to,
                             "the lookup's upper end (controller.finish_after)");
}

void bind_controller_types(py::module_& m) {
  py::class_<control::ControllerContext>(m, "ControllerContext",
                                         "What a controller is given once, before the first tick.")
      .def_property_readonly(
          "plan",
          [](const control::ControllerContext& c) {
            return std::const_pointer_cast<control::Plan>(c.plan);
          },
          "the planned motion (flatland.Plan)")
      .def_readonly("dt", &control::ControllerContext::dt, "s, the control period")
      .def_readonly("t_start", &control::ControllerContext::t_start, "s, the first tick")
      .def_readonly("s_h_start", &control::ControllerContext::s_h_start,
                    "the s_h the scene starts the disk at");
  py::class_<control::JointReading>(m, "JointReading", "The joint as read at one tick.")
      .def_readonly("t", &control::JointReading::t)
      .def_readonly("theta", &control::JointReading::theta, "rad, the encoder's angle")
      .def_readonly("theta_dot", &control::JointReading::theta_dot,
                    "rad/s, the drive's velocity estimate")
      .def("__repr__", [](const control::JointReading& r) {
        return "JointReading(t=" + sim::format_significant(r.t) +
               ", theta=" + sim::format_significant(r.theta) +
               ", theta_dot=" + sim::format_significant(r.theta_dot) + ")";
      });
  py::class_<control::Measurement>(m, "Measurement", "One vision measurement of s_h.")
      .def_readonly("t_capture", &control::Measurement::t_capture, "s, mid-exposure")
      .def_readonly("t_arrival", &control::Measurement::t_arrival, "s, when it reached the loop")
      .def_readonly("s_h", &control::Measurement::s_h)
      .def_readonly("sigma", &control::Measurement::sigma, "its 1-sigma uncertainty")
      .def("__repr__", [](const control::Measurement& z) {
        return "Measurement(t_capture=" + sim::format_significant(z.t_capture) +
               ", s_h=" + sim::format_significant(z.s_h) +
               ", sigma=" + sim::format_significant(z.sigma) + ")";
      });
  py::class_<control::Estimate>(m, "Estimate", "A belief over (s_h, sdot_h) at time t.")
      .def(py::init([](const py::object& t, const py::object& s_h, const py::object& sdot_h,
                       const py::object& covariance) {
             control::Estimate e;
             e.t = number_argument(t, "Estimate.t");
             e.s_h = number_argument(s_h, "Estimate.s_h");
             e.sdot_h = number_argument(sdot_h, "Estimate.sdot_h");
             e.covariance = covariance_argument(covariance);
             return e;
           }),
           "t"_a, "s_h"_a, "sdot_h"_a, "covariance"_a)
      .def_readonly("t", &control::Estimate::t)
      .def_readonly("s_h", &control::Estimate::s_h)
      .def_readonly("sdot_h", &control::Estimate::sdot_h)
      .def_property_readonly(
          "covariance", [](const control::Estimate& e) { return covariance_tuple(e.covariance); },
          "((var_s, cov), (cov, var_sdot))")
      .def("__repr__", [](const control::Estimate& e) {
        return "Estimate(t=" + sim::format_significant(e.t) +
               ", s_h=" + sim::format_significant(e.s_h) +
               ", sdot_h=" + sim::format_significant(e.sdot_h) + ")";
      });
  py::class_<control::ControlInput>(m, "ControlInput", "What a controller sees at one tick.")
      .def_readonly("t", &control::ControlInput::t, "s, this tick")
      .def_readonly("joint", &control::ControlInput::joint, "the joint as read at t")
      .def_readonly("estimate", &control::ControlInput::estimate,
                    "the belief at t (s_h_start until the first measurement)")
      .def_readonly("estimating", &control::ControlInput::estimating,
                    "False until the first measurement")
      .def_readonly("measurement", &control::ControlInput::measurement,
                    "the measurement folded in at this tick, or None");
  py::class_<control::ControlOutput>(m, "ControlOutput", "What a controller commands for a tick.")
      .def(py::init([](const py::object& theta_ddot, const py::object& mode,
                       const py::object& theta_reference, const py::object& done,
                       const py::object& t_done, const py::object& stop) {
             control::ControlOutput c;
             c.theta_ddot = number_argument(theta_ddot, "ControlOutput.theta_ddot");
             if (!mode.is_none()) {
               if (!py::isinstance<py::str>(mode))
                 throw std::invalid_argument("ControlOutput.mode: a str, got a " + type_name(mode));
               c.mode = mode.cast<std::string>();
             }
             c.theta_reference =
                 optional_number_argument(theta_reference, "ControlOutput.theta_reference")
                     .value_or(kNotGiven);
             c.done = flag_argument(done, "ControlOutput.done");
             c.t_done = optional_number_argument(t_done, "ControlOutput.t_done");
             if (!stop.is_none()) {
               if (!py::isinstance<py::str>(stop))
                 throw std::invalid_argument("ControlOutput.stop: a str (the reason), got a " +
                                             type_name(stop));
               std::string reason = one_line(stop.cast<std::string>());
               const std::string prefix = control::to_string(control::StopCause::kController);
               if (reason.rfind(prefix + ":", 0) != 0) reason = prefix + ": " + reason;
               c.stop = control::StopReason{control::StopCause::kController, reason};
             }
             return c;
           }),
           "theta_ddot"_a, "mode"_a = py::none(), "theta_reference"_a = py::none(),
           "done"_a = false, "t_done"_a = py::none(), "stop"_a = py::none())
      .def_readonly("theta_ddot", &control::ControlOutput::theta_ddot, "rad/s^2")
      .def_readonly("mode", &control::ControlOutput::mode)
      .def_readonly("theta_reference", &control::ControlOutput::theta_reference)
      .def_readonly("done", &control::ControlOutput::done)
      .def_readonly("t_done", &control::ControlOutput::t_done)
      .def_property_readonly(
          "stop",
          [](const control::ControlOutput& c) {
            return c.stop ? py::object(py::str(stop_detail(c.stop))) : py::object(py::none());
          },
          "the safe stop's reason, or None");
}

void bind_estimator_types(py::module_& m) {
  py::class_<control::HandInput>(m, "HandInput",
                                 "The hand's kinematics an estimator propagates with over a tick.")
      .def_readonly("theta", &control::HandInput::theta, "rad, read at the tick's start")
      .def_readonly("theta_dot", &control::HandInput::theta_dot, "rad/s")
      .def_readonly("theta_ddot", &control::HandInput::theta_ddot, "rad/s^2, held over the tick");
  py::class_<control::UpdateReport>(m, "UpdateReport", "What one measurement update did.")
      .def(py::init([](const py::object& applied, const py::object& innovation,
                       const py::object& innovation_sigma, const py::object& nis,
                       const py::object& repropagated_steps) {
             control::UpdateReport r;
             r.applied = flag_argument(applied, "UpdateReport.applied");
             r.innovation = number_argument(innovation, "UpdateReport.innovation");
             r.innovation_sigma =
                 number_argument(innovation_sigma, "UpdateReport.innovation_sigma");
             r.nis = number_argument(nis, "UpdateReport.nis");
             r.repropagated_steps = cast_argument<int>(
                 repropagated_steps, "UpdateReport.repropagated_steps", "an integer");
             return r;
           }),
           "applied"_a = true, "innovation"_a = 0.0, "innovation_sigma"_a = 0.0, "nis"_a = 0.0,
           "repropagated_steps"_a = 0)
      .def_readonly("applied", &control::UpdateReport::applied)
      .def_readonly("innovation", &control::UpdateReport::innovation)
      .def_readonly("innovation_sigma", &control::UpdateReport::innovation_sigma)
      .def_readonly("nis", &control::UpdateReport::nis)
      .def_readonly("repropagated_steps", &control::UpdateReport::repropagated_steps);
  py::class_<control::EstimatorCounts>(m, "EstimatorCounts", "The work an estimator did.")
      .def(py::init([](const py::object& steps, const py::object& repropagated,
                       const py::object& updates) {
             const auto count = [](const py::object& h, const std::string& name) {
               if (PyBool_Check(h.ptr()))
                 throw std::invalid_argument(name + ": an integer, got a bool");
               return cast_argument<long>(h, name, "an integer");
             };
             return control::EstimatorCounts{count(steps, "EstimatorCounts.steps"),
                                             count(repropagated, "EstimatorCounts.repropagated"),
                                             count(updates, "EstimatorCounts.updates")};
           }),
           "steps"_a = 0, "repropagated"_a = 0, "updates"_a = 0)
      .def_readonly("steps", &control::EstimatorCounts::steps)
      .def_readonly("repropagated", &control::EstimatorCounts::repropagated)
      .def_readonly("updates", &control::EstimatorCounts::updates);
}

}  // namespace

Scene experiment_scene(const py::object& scene) {
  if (!scene.is_none()) return scene_argument(scene, false, "model");
  return load_scene(data_directory() + "/scenes/airtable-feedback.yaml");
}

py::dict log_columns(const std::vector<drivers::TickLog>& log) {
  const auto& columns = drivers::tick_log_columns();
  const py::object numpy_array = py::module_::import("numpy").attr("array");
  py::dict out;
  for (int c = 0; c < static_cast<int>(columns.size()); ++c) {
    const std::string name = drivers::tick_log_column_name(columns[c]);
    if (drivers::tick_log_column_is_text(c)) {
      py::list values;
      for (const auto& row : log) values.append(py::str(drivers::tick_log_text(row, c)));
      // As wide as the longest word: a Python controller's mode may be long.
      out[py::str(name)] = numpy_array(values, "U");
      continue;
    }
    py::array_t<double> values(static_cast<py::ssize_t>(log.size()));
    double* data = values.mutable_data();
    for (std::size_t i = 0; i < log.size(); ++i) data[i] = drivers::tick_log_number(log[i], c);
    out[py::str(name)] = values;
  }
  return out;
}

void bind_loop_types(py::module_& m) {
  bind_plan(m);
  bind_controller_types(m);
  bind_estimator_types(m);
}

drivers::ControllerFactory python_controller_factory(const py::object& controller,
                                                     const std::string& keyword) {
  const SharedObject step = method_of(controller, "step", keyword, true);
  const SharedObject start = method_of(controller, "start", keyword, false);
  const std::string name = object_name(controller, keyword);
  return [start, step, name]() -> std::unique_ptr<control::Controller> {
    return std::make_unique<PythonController>(start, step, name);
  };
}

drivers::EstimatorFactory python_estimator_factory(const py::object& estimator,
                                                   const std::string& keyword) {
  const SharedObject reset = method_of(estimator, "reset", keyword, true);
  const SharedObject propagate = method_of(estimator, "propagate", keyword, true);
  const SharedObject update = method_of(estimator, "update", keyword, true);
  const SharedObject estimate = method_of(estimator, "estimate", keyword, true);
  const SharedObject counts = method_of(estimator, "counts", keyword, false);
  const std::string name = object_name(estimator, keyword);
  return [=](std::shared_ptr<const sim::RollingProblem>) -> std::unique_ptr<control::Estimator> {
    return std::make_unique<PythonEstimator>(reset, propagate, update, estimate, counts, name);
  };
}

LoopChoice choose_loop(Scene& scene, const py::object& controller, const py::object& estimator) {
  LoopChoice choice;
  const auto known = [](const std::vector<std::string>& names) {
    std::string list;
    for (const std::string& n : names) {
      if (!list.empty()) list += ", ";
      list += n;
    }
    return list;
  };
  if (py::isinstance<py::str>(controller)) {
    const std::string name = controller.cast<std::string>();
    const auto& types = control::controller_types();
    if (name == "open-loop" || name == "feedback")
      scene.controller.mode = name;
    else if (std::find(types.begin(), types.end(), name) != types.end())
      scene.controller.type = name;
    else
      throw std::invalid_argument("controller: unknown '" + name +
                                  "' (a mode: feedback, open-loop; a type: " + known(types) +
                                  "; or an object with a step method)");
  } else if (!controller.is_none()) {
    choice.controller = python_controller_factory(controller, "controller");
  }
  if (py::isinstance<py::str>(estimator)) {
    const std::string name = estimator.cast<std::string>();
    const auto& types = control::estimator_types();
    if (std::find(types.begin(), types.end(), name) == types.end())
      throw std::invalid_argument("estimator: unknown '" + name + "' (a type: " + known(types) +
                                  "; or an object with reset, propagate, update and estimate)");
    scene.estimator.type = name;
  } else if (!estimator.is_none()) {
    choice.estimator = python_estimator_factory(estimator, "estimator");
  }
  return choice;
}

}  // namespace flatland::python
