// flatland.load and the simulator's operations: solve, simulate, time_optimal, locus, surface,
// design.
// The options are checked by flatland::api as the CLI's are, with messages naming the keyword.
#include "convert.hpp"

#include "flatland/api/sim_operations.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/sim/spatial_spec.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include <pybind11/stl.h>

namespace flatland::python {

namespace {

constexpr api::Spelling kPy = api::Spelling::kPython;

api::IntegratorOverrides integrator(const std::optional<std::string>& method,
                                    std::optional<double> rtol, std::optional<double> atol,
                                    std::optional<double> step,
                                    std::optional<double> energy_tolerance,
                                    const std::optional<std::string>& formulation) {
  return {method, rtol, atol, step, energy_tolerance, formulation};
}

/// Samples as one numpy array per trajectory column (the CSV's columns; `mode` as str objects).
py::dict trajectory_columns(const std::vector<sim::Sample>& samples) {
  const auto& names = sim::sample_columns();
  const std::size_t n = samples.size();
  std::vector<py::array_t<double>> numbers;
  std::vector<double*> data;
  for (std::size_t c = 0; c < sim::kSampleNumbers; ++c) {
    numbers.emplace_back(static_cast<py::ssize_t>(n));
    data.push_back(numbers.back().mutable_data());
  }
  py::list modes;
  for (std::size_t i = 0; i < n; ++i) {
    const auto v = sim::sample_numbers(samples[i]);
    for (std::size_t c = 0; c < v.size(); ++c) data[c][i] = v[c];
    modes.append(py::str(sim::to_string(samples[i].mode)));
  }
  py::dict columns;
  for (std::size_t c = 0, j = 0; c < names.size(); ++c)
    columns[py::str(names[c])] = names[c] == "mode"
                                     ? py::module_::import("numpy").attr("array")(modes, "U8")
                                     : py::object(numbers[j++]);
  return columns;
}

py::dict solve_binding(std::optional<double> period, const py::object& scene,
                       std::optional<double> k, const std::string& solve_for, double tolerance,
                       const std::optional<std::string>& method, std::optional<double> rtol,
                       std::optional<double> atol, std::optional<double> step,
                       std::optional<double> energy_tolerance,
                       const std::optional<std::string>& formulation) {
  api::SolveRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.period = period;
  request.k = k;
  request.solve_for = solve_for;
  request.tolerance = tolerance;
  const sim::SimulationSpec spec = api::prepare_solve(scene_argument(scene), request, kPy);
  const sim::SolveReport r = run_interruptible([&] { return api::solve(spec, request); });
  api::Json j = api::solve_report_json(r);
  if (solve_for == "d") j["d"] = api::number(r.d);
  return to_python(j);
}

/// A spatial scene's run, as `flatland simulate --json --out FILE.csv` has it: the report and
/// the CSV's text (every step, or one row every sample_dt s), which flatland.simulate turns into
/// one array per column.
py::tuple simulate_spatial(const Scene& scene, const api::SimulateRequest& request,
                           std::optional<double> sample_dt) {
  const sim::SpatialSpec spec = api::prepare_spatial_simulate(scene, request, kPy);
  if (sample_dt) api::require_sample_spacing("sample_dt", *sample_dt, spec.end_time());
  sim::SpatialSetup setup;
  try {
    setup = sim::build_spatial(spec);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(scene.origin + ": " + e.what());
  }
  if (sample_dt) setup.options.sample_dt = *sample_dt;
  setup.options.record = true;
  setup.options.progress = [](double) { InterruptScope::check(); };
  std::string csv;
  const sim::SpatialRunResult r = run_interruptible([&] {
    sim::SpatialRunResult run = sim::run_spatial(setup);
    csv = sim::spatial_samples_csv(run.samples);
    return run;
  });
  return py::make_tuple(to_python(api::spatial_simulate_json(spec, r)), py::str(csv));
}

py::tuple simulate_binding(const py::object& scene, std::optional<double> period,
                           std::optional<double> k, std::optional<double> duration,
                           std::optional<double> mu, const std::optional<std::string>& model,
                           bool stop_on_contact_loss, std::optional<double> sample_dt,
                           const std::optional<std::string>& method, std::optional<double> rtol,
                           std::optional<double> atol, std::optional<double> step,
                           std::optional<double> energy_tolerance,
                           const std::optional<std::string>& formulation) {
  api::SimulateRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.period = period;
  request.k = k;
  request.duration = duration;
  request.mu = mu;
  request.model = model;
  request.stop_on_contact_loss = stop_on_contact_loss;
  Scene loaded = scene_argument(scene, true);
  if (loaded.spatial) return simulate_spatial(loaded, request, sample_dt);
  const api::PreparedSimulation prepared = api::prepare_simulate(std::move(loaded), request, kPy);
  if (sample_dt)
    api::require_sample_spacing("sample_dt", *sample_dt,
                                prepared.spec.end_time() - prepared.spec.initial.t0);
  std::vector<sim::Sample> rows;
  const sim::RunResult r = run_interruptible([&] {
    sim::RunResult run = api::simulate(prepared);
    if (sample_dt && !run.trajectory.empty()) rows = run.trajectory.resample(*sample_dt);
    return run;
  });
  const py::dict trajectory = trajectory_columns(sample_dt ? rows : r.steps);
  return py::make_tuple(to_python(api::simulate_json(prepared.spec, r)), trajectory);
}

py::dict time_optimal_binding(const py::object& scene, std::optional<double> mu, double from,
                              double to, double period_tolerance, double tolerance,
                              const std::optional<std::string>& method, std::optional<double> rtol,
                              std::optional<double> atol, std::optional<double> step,
                              std::optional<double> energy_tolerance,
                              const std::optional<std::string>& formulation) {
  api::TimeOptimalRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.mu = mu;
  request.from = from;
  request.to = to;
  request.period_tolerance = period_tolerance;
  request.tolerance = tolerance;
  const sim::SimulationSpec spec = api::prepare_time_optimal(scene_argument(scene), request, kPy);
  const sim::TimeOptimalReport r =
      run_interruptible([&] { return api::time_optimal(spec, request); });
  return to_python(api::time_optimal_json(r, spec));
}

py::dict design_binding(const py::object& scene, const std::string& objective,
                        std::optional<double> period, std::optional<double> mu, bool motion_only,
                        double shape_range, double fn_margin, int max_evaluations, double tolerance,
                        const std::optional<std::string>& method, std::optional<double> rtol,
                        std::optional<double> atol, std::optional<double> step,
                        std::optional<double> energy_tolerance,
                        const std::optional<std::string>& formulation) {
  api::DesignRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.objective = objective;
  request.period = period;
  request.mu = mu;
  request.motion_only = motion_only;
  request.shape_range = shape_range;
  request.fn_margin = fn_margin;
  request.max_evaluations = max_evaluations;
  request.tolerance = tolerance;
  const sim::SimulationSpec spec = api::prepare_design(scene_argument(scene), request, kPy);
  const design::DesignResult r = run_interruptible([&] { return api::design(spec, request); });
  return to_python(api::design_json(r, spec));
}

py::dict locus_binding(const py::object& scene, double from, double to, int n,
                       std::optional<double> mu, double tolerance,
                       const std::optional<std::string>& method, std::optional<double> rtol,
                       std::optional<double> atol, std::optional<double> step,
                       std::optional<double> energy_tolerance,
                       const std::optional<std::string>& formulation) {
  api::LocusRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.mu = mu;
  request.from = from;
  request.to = to;
  request.n = n;
  request.tolerance = tolerance;
  const sim::SimulationSpec spec = api::prepare_locus(scene_argument(scene), request, kPy);
  const std::vector<sim::SolveReport> points =
      run_interruptible([&] { return api::locus(spec, request, InterruptScope::progress()); });
  // Each field as an array over the periods, besides the CLI's JSON points.
  const auto column = [&](double sim::SolveReport::*field) {
    py::array_t<double> a(static_cast<py::ssize_t>(points.size()));
    for (std::size_t i = 0; i < points.size(); ++i) a.mutable_at(i) = points[i].*field;
    return a;
  };
  py::dict out = to_python(api::locus_json(points, spec));
  out["period"] = column(&sim::SolveReport::period);
  out["k"] = column(&sim::SolveReport::k);
  out["fn_min_ratio"] = column(&sim::SolveReport::fn_min_ratio);
  out["fn_apex_ratio"] = column(&sim::SolveReport::fn_apex_ratio);
  out["mu_required"] = column(&sim::SolveReport::mu_required);
  out["friction_margin"] = column(&sim::SolveReport::friction_margin);
  return out;
}

py::dict surface_binding(const py::object& scene, double k_from, double k_to, int nk,
                         double period_from, double period_to, int np, int threads,
                         const std::optional<std::string>& method, std::optional<double> rtol,
                         std::optional<double> atol, std::optional<double> step,
                         std::optional<double> energy_tolerance,
                         const std::optional<std::string>& formulation) {
  api::SurfaceRequest request;
  request.integrator = integrator(method, rtol, atol, step, energy_tolerance, formulation);
  request.k_from = k_from;
  request.k_to = k_to;
  request.nk = nk;
  request.period_from = period_from;
  request.period_to = period_to;
  request.np = np;
  request.threads = threads;
  const sim::SimulationSpec spec = api::prepare_surface(scene_argument(scene), request, kPy);
  const sim::SurfaceResult s =
      run_interruptible([&] { return api::surface(spec, request, InterruptScope::progress()); });
  py::array_t<double> s_T(
      {static_cast<py::ssize_t>(s.k.size()), static_cast<py::ssize_t>(s.period.size())});
  std::copy(s.s_T.begin(), s.s_T.end(), s_T.mutable_data());
  py::dict out;
  out["k"] = py::array_t<double>(static_cast<py::ssize_t>(s.k.size()), s.k.data());
  out["period"] = py::array_t<double>(static_cast<py::ssize_t>(s.period.size()), s.period.data());
  out["s_T"] = s_T;
  out["rhs_evals"] = s.rhs_evals;
  py::list failed;  // points whose run failed numerically (s_T is NaN there)
  for (const auto& f : s.numerical_failures) {
    py::dict d;
    d["k"] = s.k[f.i];
    d["period"] = s.period[f.j];
    d["failure"] = f.what;
    failed.append(d);
  }
  out["numerical_failures"] = failed;
  return out;
}

}  // namespace

void bind_sim(py::module_& m) {
  using namespace pybind11::literals;
  py::class_<PyModel>(m, "Model", "A compiled scene (flatland.load): immutable, shared by calls.")
      .def_property_readonly("origin", [](const PyModel& p) { return p.model->spec.origin; })
      .def_property_readonly("name", [](const PyModel& p) { return p.model->spec.name; })
      .def_property_readonly("has_camera",
                             [](const PyModel& p) { return p.model->camera.has_value(); })
      .def_property_readonly("camera",
                             [](const PyModel& p) -> py::object {
                               if (!p.model->camera) return py::none();
                               return camera_to_python(*p.model->camera);
                             })
      .def("__repr__", [](const PyModel& p) {
        return "<flatland.Model " + p.model->spec.origin +
               (p.model->spec.name.empty() ? "" : " (" + p.model->spec.name + ")") + ">";
      });

  m.def(
      "load", [](const py::object& path) { return PyModel{model_argument(path, "path")}; },
      "path"_a = py::none());
  m.def("default_scene_path", &default_scene_path);
  m.def("data_directory", &data_directory);
  m.def("solve", &solve_binding, "period"_a, "scene"_a, "k"_a, "solve_for"_a, "tolerance"_a,
        "method"_a, "rtol"_a, "atol"_a, "step"_a, "energy_tolerance"_a, "formulation"_a);
  m.def("simulate", &simulate_binding, "scene"_a, "period"_a, "k"_a, "duration"_a, "mu"_a,
        "model"_a, "stop_on_contact_loss"_a, "sample_dt"_a, "method"_a, "rtol"_a, "atol"_a,
        "step"_a, "energy_tolerance"_a, "formulation"_a);
  m.def("time_optimal", &time_optimal_binding, "scene"_a, "mu"_a, "from_"_a, "to"_a,
        "period_tolerance"_a, "tolerance"_a, "method"_a, "rtol"_a, "atol"_a, "step"_a,
        "energy_tolerance"_a, "formulation"_a);
  m.def("design", &design_binding, "scene"_a, "objective"_a, "period"_a, "mu"_a, "motion_only"_a,
        "shape_range"_a, "fn_margin"_a, "max_evaluations"_a, "tolerance"_a, "method"_a, "rtol"_a,
        "atol"_a, "step"_a, "energy_tolerance"_a, "formulation"_a);
  m.def("locus", &locus_binding, "scene"_a, "from_"_a, "to"_a, "n"_a, "mu"_a, "tolerance"_a,
        "method"_a, "rtol"_a, "atol"_a, "step"_a, "energy_tolerance"_a, "formulation"_a);
  m.def("surface", &surface_binding, "scene"_a, "k_from"_a, "k_to"_a, "nk"_a, "period_from"_a,
        "period_to"_a, "np"_a, "threads"_a, "method"_a, "rtol"_a, "atol"_a, "step"_a,
        "energy_tolerance"_a, "formulation"_a);
}

}  // namespace flatland::python
