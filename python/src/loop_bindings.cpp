// The closed loop: a synthetic experiment (its result and its 1 kHz log as arrays) and a Monte
// Carlo study of perturbed worlds.
#include "convert.hpp"
#include "python_loop.hpp"

#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/montecarlo.hpp"
#include "flatland/drivers/synthetic.hpp"
#include "flatland/drivers/tick_log_csv.hpp"
#include "flatland/model/compile.hpp"

#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <utility>

namespace flatland::python {

using namespace pybind11::literals;

namespace {

py::object optional_number(const std::optional<double>& v) {
  return v ? py::object(py::float_(*v)) : py::none();
}

py::tuple experiment_binding(const py::object& scene_arg, const py::object& controller,
                             const py::object& estimator) {
  Scene scene = experiment_scene(scene_arg);
  // Names go into the scene (checked when it compiles); Python objects into factories.
  const LoopChoice choice = choose_loop(scene, controller, estimator);
  const std::shared_ptr<const model::Model> nominal = model::compile(scene);
  drivers::require_friction(scene);
  const drivers::SyntheticResult s = run_interruptible([&] {
    const drivers::LoopSetup setup(nominal, choice.controller, choice.estimator);
    drivers::SyntheticOptions options;
    options.progress = [](double, double) { InterruptScope::check(); };
    return drivers::run_synthetic(setup, nominal, options);
  });
  const drivers::LoopResult& loop = s.loop;
  // The keys of `flatland experiment --json` that a synthetic run has.
  py::dict r;
  r["success"] = s.success;
  r["outcome"] = drivers::to_string(s.outcome);
  r["failure"] = s.failure.empty() ? py::object(py::none()) : py::object(py::str(s.failure));
  r["duration_s"] = std::isfinite(loop.duration_s) ? py::object(py::float_(loop.duration_s))
                                                   : py::object(py::none());
  r["s_end"] = s.s_end;
  r["fn_min_ratio"] = s.fn_min_ratio;
  r["mu_max"] = s.mu_max;
  r["frames"] = loop.frames;
  r["frames_lost"] = loop.frames_lost;
  r["frames_damaged"] = loop.frames_damaged;
  r["frames_repeated"] = loop.frames_repeated;
  r["frames_unreadable"] = loop.frames_unreadable;
  r["safe_stop"] = loop.safe_stop;
  r["stop_reason"] =
      loop.stop_reason ? py::object(py::str(loop.stop_reason->detail)) : py::object(py::none());
  r["finished"] = loop.finished;
  r["k"] = loop.k;
  r["period"] = loop.period;
  // The CLI's key: the scene's mode; a Python controller's name.
  r["controller"] = choice.controller ? loop.controller : scene.controller.mode;
  r["nees_mean"] = s.nees_mean;
  r["measurements"] = loop.measurements;
  r["estimator_steps"] = loop.estimator_steps;
  py::dict hand_acceleration;  // where the estimator's hand acceleration came from, in ticks
  hand_acceleration["readings"] = loop.acceleration_from_readings;
  hand_acceleration["command"] = loop.acceleration_from_command;
  r["hand_acceleration"] = hand_acceleration;
  r["ticks"] = static_cast<long>(loop.log.size());
  r["t_stage2"] = optional_number(loop.t_stage2);
  r["t_stage3"] = optional_number(loop.t_stage3);
  r["frames_rendered"] = s.frames_rendered;
  r["frames_dropped"] = s.frames_dropped;
  sim::Sample start;
  start.t = loop.log.empty() ? 0.0 : loop.log.front().t;
  r["contact"] = to_python(
      api::contact_summary_json(s.mode_time, s.mode_changes, s.impacts, s.contact_events, start));
  py::dict world_energy;
  world_energy["worst_balance"] = s.energy_worst;
  world_energy["bound"] = s.energy_worst_bound;
  r["world_energy"] = world_energy;
  r["scene"] = scene.origin;
  return py::make_tuple(r, log_columns(loop.log));
}

py::dict montecarlo_binding(const py::object& scene, int runs, std::uint64_t seed,
                            const std::vector<std::string>& controllers, unsigned threads,
                            const std::optional<py::dict>& perturbations) {
  const std::shared_ptr<const model::Model> nominal = model::compile(experiment_scene(scene));
  drivers::require_friction(nominal->spec);
  drivers::Perturbations p;
  using P = drivers::Perturbations;
  static const std::pair<const char*, double P::*> fields[] = {
      {"s_h", &P::s_h},
      {"tilt_deg", &P::tilt_deg},
      {"radius_rel", &P::radius_rel},
      {"noise_dn", &P::noise_dn},
      {"latency", &P::latency},
      {"latency_jitter", &P::latency_jitter},
      {"drop", &P::drop},
      {"friction_rel", &P::friction_rel},
      {"contact_rel", &P::contact_rel}};
  if (perturbations) {
    for (const auto& [key, value] : *perturbations) {
      const std::string name = py::str(key);
      const auto* field = std::find_if(std::begin(fields), std::end(fields),
                                       [&](const auto& f) { return name == f.first; });
      if (field == std::end(fields)) {
        std::string known;
        // Appended piece by piece: GCC 12 warns falsely (-Wstringop-overflow, under LTO) about
        // "literal" + std::string.
        for (const auto& f : fields) {
          if (!known.empty()) known += ", ";
          known += f.first;
        }
        throw std::invalid_argument("perturbations." + name + ": unknown (" + known + ")");
      }
      p.*(field->second) = cast_argument<double>(value, "perturbations." + name, "a number");
    }
  }
  drivers::validate(p);
  const drivers::MonteCarloResult r = run_interruptible([&] {
    return drivers::run_montecarlo(*nominal, p, runs, seed,
                                   drivers::controllers_by_name(controllers), threads,
                                   InterruptScope::progress());
  });
  py::dict out;
  out["runs"] = r.runs;
  out["success_open_loop"] =
      r.success_open_loop >= 0 ? py::object(py::int_(r.success_open_loop)) : py::object(py::none());
  out["success_feedback"] =
      r.success_feedback >= 0 ? py::object(py::int_(r.success_feedback)) : py::object(py::none());
  out["ci_open_loop"] = py::make_tuple(r.ci_open_loop.lo, r.ci_open_loop.hi);
  out["ci_feedback"] = py::make_tuple(r.ci_feedback.lo, r.ci_feedback.hi);
  // Worlds whose simulation failed: no physical outcome, left out of the rates.
  out["numerical_failures_open_loop"] = r.success_open_loop >= 0
                                            ? py::object(py::int_(r.numerical_failures_open_loop))
                                            : py::object(py::none());
  out["numerical_failures_feedback"] = r.success_feedback >= 0
                                           ? py::object(py::int_(r.numerical_failures_feedback))
                                           : py::object(py::none());
  py::list records;
  for (const drivers::RunRecord& rec : r.records) {
    py::dict d;
    d["run"] = rec.run;
    d["seed"] = rec.seed;
    d["controller"] = rec.controller;
    d["success"] = rec.success;
    d["outcome"] = drivers::to_string(rec.outcome);
    d["failure"] = rec.failure;
    d["slide_s"] = rec.slide_s;
    d["flight_s"] = rec.flight_s;
    d["impacts"] = rec.impacts;
    d["duration_s"] = rec.duration_s;
    d["s_end"] = rec.s_end;
    d["fn_min_ratio"] = rec.fn_min_ratio;
    d["mu_max"] = rec.mu_max;
    d["safe_stop"] = rec.safe_stop;
    d["frames"] = rec.frames;
    d["frames_lost"] = rec.frames_lost;
    d["mu"] = rec.mu;
    d["stop_cause"] = rec.stop_cause ? py::object(py::str(control::to_string(*rec.stop_cause)))
                                     : py::object(py::none());
    records.append(d);
  }
  out["records"] = records;
  // Per controller and per pair (drivers::compare_controllers): the keys of the CLI's
  // "summaries" and "pairs", NaN where the CLI writes null (no successes to take a margin of).
  const drivers::ControllerComparison comparison = drivers::compare_controllers(r);
  const auto spread = [](const drivers::Spread& x) {
    py::dict d;
    d["n"] = x.n;
    d["min"] = x.min;
    d["p05"] = x.p05;
    d["median"] = x.median;
    d["p95"] = x.p95;
    d["max"] = x.max;
    return d;
  };
  py::list summaries, pairs;
  for (const drivers::ControllerReport& c : comparison.controllers) {
    py::dict d;
    d["controller"] = c.name;
    d["runs"] = c.runs;
    d["successes"] = c.successes;
    d["numerical_failures"] = c.numerical_failures;
    d["invalid_worlds"] = c.invalid_worlds;
    d["ci95"] = py::make_tuple(c.ci.lo, c.ci.hi);
    d["outcomes"] = c.outcomes;
    d["safe_stops"] = c.safe_stops;
    d["duration_s"] = spread(c.duration_s);
    d["fn_min_ratio"] = spread(c.fn_min_ratio);
    d["friction_use"] = spread(c.friction_use);
    summaries.append(d);
  }
  for (const drivers::PairedComparison& p : comparison.pairs) {
    py::dict d;
    d["a"] = p.a;
    d["b"] = p.b;
    d["worlds"] = p.worlds;
    d["both"] = p.both;
    d["only_a"] = p.only_a;
    d["only_b"] = p.only_b;
    d["neither"] = p.neither;
    d["p_value"] = p.p_value;
    pairs.append(d);
  }
  out["summaries"] = summaries;
  out["pairs"] = pairs;
  out["seconds"] = r.seconds;
  return out;
}

}  // namespace

void bind_loop(py::module_& m) {
  m.def("experiment", &experiment_binding, "scene"_a, "controller"_a, "estimator"_a);
  m.def("montecarlo", &montecarlo_binding, "scene"_a, "runs"_a, "seed"_a, "controllers"_a,
        "threads"_a, "perturbations"_a);
}

}  // namespace flatland::python
