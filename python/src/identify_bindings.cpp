// flatland.identify and flatland.validate_world: the world's parameters fitted to recordings given
// as arrays (docs/PYTHON.md, docs/IDENTIFY.md). flatland/__init__.py checks the arguments' types
// and shapes; the library checks their values with the CLI's messages.
#include "convert.hpp"

#include "flatland/identify/fitted_scene.hpp"
#include "flatland/identify/identify.hpp"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cmath>
#include <fstream>
#include <sstream>

namespace flatland::python {

using namespace pybind11::literals;

namespace {

py::array_t<double> to_array(const std::vector<double>& v) {
  py::array_t<double> a(static_cast<py::ssize_t>(v.size()));
  std::copy(v.begin(), v.end(), a.mutable_data());
  return a;
}

std::vector<double> vector_of(const py::dict& d, const char* key, const std::string& name) {
  return cast_argument<std::vector<double>>(d[key], name + "." + key, "an array of numbers");
}

/// A recording as __init__.py hands it over: a dict of float arrays t, s_h, sigma, joint_t,
/// joint_theta (sigma already broadcast) and its name.
identify::Recording recording_of(const py::handle& h, const std::string& keyword) {
  const py::dict d = cast_argument<py::dict>(h, keyword, "a dict");
  identify::Recording r;
  r.name = cast_argument<std::string>(d["name"], keyword + ".name", "a str");
  r.t = vector_of(d, "t", keyword);
  r.s_h = vector_of(d, "s_h", keyword);
  r.sigma = vector_of(d, "sigma", keyword);
  r.joint_t = vector_of(d, "joint_t", keyword);
  r.joint_theta = vector_of(d, "joint_theta", keyword);
  identify::check_recording(r);
  return r;
}

py::dict prediction_to_python(const identify::PredictionCheck& c) {
  return py::dict(
      "name"_a = c.name, "s_h0"_a = c.s_h0, "sdot_h0"_a = c.sdot_h0, "t"_a = to_array(c.t),
      "measured"_a = to_array(c.measured), "predicted"_a = to_array(c.predicted),
      "error"_a = to_array(c.error), "normalised_error"_a = to_array(c.normalised_error),
      "rms_error"_a = c.rms_error, "max_abs_error"_a = c.max_abs_error,
      "stopped"_a = c.stopped.empty() ? py::object(py::none()) : py::object(py::str(c.stopped)),
      "time_to_3_sigma"_a =
          c.time_to_3_sigma ? py::object(py::float_(*c.time_to_3_sigma)) : py::object(py::none()));
}

/// The scene file's text, for the fitted scene; empty when the scene is not a readable file.
std::string scene_text(const Scene& scene) {
  std::ifstream in(scene.origin, std::ios::binary);
  if (!in) return {};
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

py::dict result_to_python(const identify::IdentifyResult& r, const Scene& scene,
                          const std::vector<identify::Recording>& recordings,
                          const std::string& command) {
  const auto k = static_cast<py::ssize_t>(r.parameters.size());
  py::array_t<double> values(k), sigmas(k), sigmas_unscaled(k), steps(k), correlation({k, k});
  py::list names;
  py::array_t<bool> determined(k), held(k);
  py::dict why;
  for (py::ssize_t i = 0; i < k; ++i) {
    const identify::ParameterEstimate& p = r.parameters[static_cast<std::size_t>(i)];
    names.append(p.name);
    values.mutable_at(i) = p.value;
    sigmas.mutable_at(i) = p.sigma ? *p.sigma : NAN;
    sigmas_unscaled.mutable_at(i) = p.sigma_unscaled ? *p.sigma_unscaled : NAN;
    steps.mutable_at(i) = p.step_to_minimum;
    held.mutable_at(i) = p.held;
    determined.mutable_at(i) = p.sigma.has_value();
    if (!p.sigma) why[py::str(p.name)] = p.not_determined;
    for (py::ssize_t j = 0; j < k; ++j) correlation.mutable_at(i, j) = r.correlation(i, j);
  }
  py::list fits;
  for (const identify::RecordingFit& f : r.fits)
    fits.append(py::dict("name"_a = f.name, "t"_a = to_array(f.t),
                         "measured"_a = to_array(f.measured), "fitted"_a = to_array(f.fitted),
                         "normalised_residual"_a = to_array(f.normalised_residual)));
  py::list segments;
  for (const identify::SegmentState& s : r.segments)
    segments.append(py::dict(
        "recording"_a = s.recording, "t0"_a = s.t0, "t1"_a = s.t1, "s_h"_a = s.s_h,
        "sdot_h"_a = s.sdot_h,
        "sigma_s_h"_a = s.sigma_s_h ? py::object(py::float_(*s.sigma_s_h)) : py::object(py::none()),
        "sigma_sdot_h"_a =
            s.sigma_sdot_h ? py::object(py::float_(*s.sigma_sdot_h)) : py::object(py::none())));
  // The fitted scene, when the scene came from a file whose text can be edited.
  py::object fitted = py::none();
  const std::string text = scene_text(scene);
  if (!text.empty()) {
    identify::FitProvenance provenance;
    provenance.scene_path = scene.origin;
    provenance.command_line = command;
    for (const identify::Recording& rec : recordings)
      provenance.recordings.push_back(rec.name + " (" + std::to_string(rec.t.size()) + " samples)");
    fitted = py::str(identify::fitted_scene(text, r, provenance));
  }
  return py::dict("names"_a = names, "values"_a = values, "sigmas"_a = sigmas,
                  "sigmas_unscaled"_a = sigmas_unscaled, "determined"_a = determined,
                  "held"_a = held, "not_determined"_a = why, "correlation"_a = correlation,
                  "chi2"_a = r.chi2, "degrees_of_freedom"_a = r.degrees_of_freedom,
                  "chi2_limit"_a = r.chi2_limit, "sigma_scale"_a = r.sigma_scale,
                  "iterations"_a = r.iterations, "converged"_a = r.converged,
                  "steps_to_minimum"_a = steps, "step_in_sigma"_a = r.step_in_sigma,
                  "chi2_decrease_expected"_a = r.chi2_decrease_expected,
                  "termination_type"_a = r.termination_type, "termination"_a = r.termination,
                  "simulations"_a = r.simulations, "wall_time"_a = r.wall_time,
                  "simulation_time"_a = r.simulation_time, "fits"_a = fits, "segments"_a = segments,
                  "warnings"_a = r.warnings, "scene"_a = fitted);
}

py::dict identify_binding(const py::object& scene_arg, const py::list& recordings_arg,
                          const std::vector<std::string>& unknowns, double segment,
                          const std::map<std::string, std::pair<double, double>>& bounds,
                          const std::map<std::string, double>& initial, int max_iterations,
                          int threads, const py::object& validate_arg, const std::string& command) {
  const Scene scene = scene_argument(scene_arg);
  std::vector<identify::Recording> recordings;
  for (std::size_t i = 0; i < recordings_arg.size(); ++i)
    recordings.push_back(recording_of(recordings_arg[i], "recordings[" + std::to_string(i) + "]"));
  std::optional<identify::Recording> held_out;
  if (!validate_arg.is_none()) held_out = recording_of(validate_arg, "validate");
  identify::IdentifyOptions options;
  options.unknowns = unknowns;
  options.segment_duration = segment;
  for (const auto& [name, b] : bounds) options.bounds[name] = {b.first, b.second};
  options.initial = initial;
  options.max_iterations = max_iterations;
  options.threads = threads;
  options.progress = [](const identify::Progress&) { InterruptScope::check(); };
  const auto [result, check] = run_interruptible([&] {
    identify::IdentifyResult r = identify::identify(scene.sim, recordings, options);
    std::optional<identify::PredictionCheck> c;
    if (held_out) {
      identify::ValidateOptions vo;
      vo.angle_offset = r.angle_offset;
      vo.time_offset = r.time_offset;
      c = identify::validate(r.world, *held_out, vo);
    }
    return std::make_pair(std::move(r), std::move(c));
  });
  py::dict out = result_to_python(result, scene, recordings, command);
  out["validation"] = check ? py::object(prediction_to_python(*check)) : py::object(py::none());
  return out;
}

py::dict validate_binding(const py::object& scene_arg, const py::object& recording,
                          double angle_offset, double time_offset) {
  const Scene scene = scene_argument(scene_arg);
  const identify::Recording r = recording_of(recording, "recording");
  identify::ValidateOptions options;
  options.angle_offset = angle_offset;
  options.time_offset = time_offset;
  const identify::PredictionCheck c =
      run_interruptible([&] { return identify::validate(scene.sim, r, options); });
  return prediction_to_python(c);
}

}  // namespace

void bind_identify(py::module_& m) {
  m.def("identify", &identify_binding, "scene"_a, "recordings"_a, "unknowns"_a, "segment"_a,
        "bounds"_a, "initial"_a, "max_iterations"_a, "threads"_a, "validate"_a, "command"_a,
        "flatland.identify's native half (see flatland.identify).");
  m.def("validate_world", &validate_binding, "scene"_a, "recording"_a, "angle_offset"_a,
        "time_offset"_a, "flatland.validate_world's native half (see flatland.validate_world).");
}

}  // namespace flatland::python
