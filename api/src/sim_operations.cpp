#include "flatland/api/sim_operations.hpp"

#include "flatland/sim/format.hpp"

#include <cmath>

namespace flatland::api {

using sim::format_number;

std::string option_name(std::string_view name, Spelling spelling) {
  if (spelling == Spelling::kPython) return std::string(name);
  // A Python keyword takes a trailing underscore (from_); the option has none (--from).
  if (name.size() > 1 && name.back() == '_') name.remove_suffix(1);
  std::string out = "--";
  for (char c : name) out += c == '_' ? '-' : c;
  return out;
}

void require_finite(const std::string& option, double v) {
  if (!std::isfinite(v))
    throw UsageError(option + ": must be a finite number, got " + format_number(v));
}

void require_positive(const std::string& option, double v, const std::string& unit) {
  if (!std::isfinite(v) || !(v > 0))
    throw UsageError(option + ": must be positive and finite" +
                     (unit.empty() ? "" : " (" + unit + ")") + ", got " + format_number(v));
}

void require_sample_spacing(const std::string& option, double dt, double span) {
  require_positive(option, dt, "s");
  const double rows = std::floor(span / dt) + 1;
  if (rows > kMaxSamples)
    throw UsageError(option + ": " + format_number(dt) + " s over " + format_number(span) +
                     " s is " + sim::format_significant(rows, 3) + " rows, more than " +
                     sim::format_significant(kMaxSamples) +
                     " (a wider spacing, or a shorter duration)");
}

void require_increasing(const std::string& from_option, double from, const std::string& to_option,
                        double to) {
  require_finite(from_option, from);
  require_finite(to_option, to);
  if (!(from < to))
    throw UsageError(to_option + ": must be larger than " + from_option + " (got " + from_option +
                     " " + format_number(from) + ", " + to_option + " " + format_number(to) + ")");
}

namespace {

/// `value` if it is one of `choices`, else a UsageError listing them.
const std::string& require_choice(const std::string& option, const std::string& value,
                                  const std::vector<std::string>& choices) {
  for (const auto& c : choices)
    if (value == c) return value;
  std::string list;
  for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
  throw UsageError(option + ": must be one of " + list + ", got '" + value + "'");
}

/// What time-optimal and locus check alike, first: the overrides, a butterfly motion and the
/// bracket of periods [from, to]. Returns the scene's spec.
sim::SimulationSpec& start_period_search(Scene& scene, const IntegratorOverrides& integrator,
                                         double from, double to, Spelling spelling) {
  const std::string from_name = option_name("from_", spelling),
                    to_name = option_name("to", spelling);
  apply_integrator_overrides(integrator, scene, spelling);
  scene.sim.motion.kind = sim::MotionSpec::Kind::kButterfly;
  require_positive(from_name, from, "2T in s");
  require_positive(to_name, to, "2T in s");
  require_increasing(from_name, from, to_name, to);
  return scene.sim;
}

/// ... and last: mu, and the lossless problem at the bracket's start, whose hand must have the
/// palm and back the search goes between (`command` names the search).
void finish_period_search(sim::SimulationSpec& spec, std::optional<double> mu, double from,
                          Spelling spelling, const std::string& command) {
  if (mu) apply_mu(*mu, spec, spelling);
  spec.motion.period = from;
  const auto problem =
      build_problem_checked(sim::paper_model(spec), {{"contact.mu", option_name("mu", spelling)}});
  sim::require_palm_and_back(spec.hand, *problem->hand, command);
}

}  // namespace

namespace {
void apply_method_and_tolerances(const IntegratorOverrides& o, sim::IntegratorSettings& in,
                                 Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  if (o.method) {
    const std::string& m = require_choice(name("method"), *o.method, {"dopri5", "dop853", "rk4"});
    in.method = m == "rk4"      ? sim::Method::kRungeKutta4
                : m == "dop853" ? sim::Method::kDormandPrince853
                                : sim::Method::kDormandPrince54;
  }
  // The bounds sim sets for every input of these settings (integrator_setting_problem).
  const auto checked = [&name](const char* key, double v) {
    const std::string problem = sim::integrator_setting_problem(key, v);
    if (!problem.empty()) throw UsageError(name(key) + ": " + problem);
    return v;
  };
  if (o.rtol) in.rtol = checked("rtol", *o.rtol);
  if (o.atol) in.atol = checked("atol", *o.atol);
  if (o.step) in.fixed_step = checked("step", *o.step);
  if (o.energy_tolerance) in.energy_tolerance = checked("energy_tolerance", *o.energy_tolerance);
}
}  // namespace

void apply_integrator_overrides(const IntegratorOverrides& o, sim::IntegratorSettings& in,
                                Spelling spelling) {
  apply_method_and_tolerances(o, in, spelling);
  if (o.formulation)
    throw UsageError(option_name("formulation", spelling) +
                     ": only for planar scenes (a spatial scene has one formulation, the 11 x 10 "
                     "system)");
}

void apply_integrator_overrides(const IntegratorOverrides& o, Scene& scene, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  apply_method_and_tolerances(o, scene.sim.run.integrator, spelling);
  if (o.formulation) {
    const std::string& f =
        require_choice(name("formulation"), *o.formulation, {"auto", "general", "reduced"});
    scene.sim.run.formulation = f == "general"   ? sim::Formulation::kGeneral
                                : f == "reduced" ? sim::Formulation::kReduced
                                                 : sim::Formulation::kAuto;
  }
}

namespace {
/// A friction coefficient: finite and >= 0. Returns the option's name, for further messages.
std::string require_friction_coefficient(double mu, Spelling spelling) {
  std::string option = option_name("mu", spelling);
  if (!std::isfinite(mu) || mu < 0)
    throw UsageError(option + ": must be a finite number >= 0, got " + format_number(mu));
  return option;
}
}  // namespace

void apply_mu(double mu, sim::SpatialSpec& spec, Spelling spelling) {
  require_friction_coefficient(mu, spelling);
  spec.mu = mu;
}

void apply_mu(double mu, sim::SimulationSpec& spec, Spelling spelling) {
  const std::string option = require_friction_coefficient(mu, spelling);
  if (spec.contact.mu_kinetic && *spec.contact.mu_kinetic > mu)
    throw UsageError(option + ": must not be below the scene's contact.mu_kinetic (" +
                     format_number(*spec.contact.mu_kinetic) + "), got " + format_number(mu));
  spec.contact.mu = mu;
}

std::shared_ptr<const sim::RollingProblem> build_problem_checked(
    const sim::SimulationSpec& spec,
    const std::vector<std::pair<std::string, std::string>>& given) {
  try {
    return sim::build_problem(spec);
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    for (const auto& [field, option] : given)
      if (what.rfind(field + ":", 0) == 0) throw UsageError(what + " (set by " + option + ")");
    throw;
  }
}

sim::SimulationSpec prepare_solve(Scene scene, const SolveRequest& r, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  apply_integrator_overrides(r.integrator, scene, spelling);
  sim::SimulationSpec& spec = scene.sim;
  spec.motion.kind = sim::MotionSpec::Kind::kButterfly;  // the search is over butterfly motions
  if (r.period) {
    require_positive(name("period"), *r.period, "2T in s");
    spec.motion.period = *r.period;
  }
  if (r.k) {
    require_finite(name("k"), *r.k);
    spec.motion.k = *r.k;
  }
  require_choice(name("solve_for"), r.solve_for, {"k", "d"});
  require_positive(name("tolerance"), r.tolerance, "");
  std::vector<std::pair<std::string, std::string>> given;
  if (r.k) given.emplace_back("motion.k", name("k"));
  if (r.period) given.emplace_back("motion.period", name("period"));
  // The scene with the overrides must be valid, and its hand have the palm and the back.
  const auto problem = build_problem_checked(spec, given);
  sim::require_palm_and_back(spec.hand, *problem->hand, "solve");
  if (r.solve_for == "d" && spec.hand.shape != sim::HandSpec::Shape::kPolynomial)
    throw UsageError(name("solve_for") + ": d is the polynomial hand's coefficient; the scene's " +
                     "hand.shape is " + sim::to_string(spec.hand.shape));
  return spec;
}

sim::SimulationSpec prepare_design(Scene scene, const DesignRequest& r, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  const std::string& objective = require_choice(
      name("objective"), r.objective, {"least-friction", "shortest-period", "robustness"});
  if (objective == "shortest-period")
    throw UsageError(name("objective") + ": '" + objective +
                     "' is not built yet (docs/DESIGN.md, \"Not built yet\"); built: "
                     "least-friction, robustness");
  apply_integrator_overrides(r.integrator, scene, spelling);
  sim::SimulationSpec& spec = scene.sim;
  if (spec.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw UsageError("motion.kind: design needs the butterfly motion (its k is designed)");
  if (r.period) {
    require_positive(name("period"), *r.period, "2T in s");
    spec.motion.period = *r.period;
  }
  if (r.mu) {
    if (objective != "robustness")
      throw UsageError(name("mu") +
                       ": only the robustness objective takes a friction coefficient "
                       "(least-friction finds the least one)");
    apply_mu(*r.mu, spec, spelling);
  }
  if (objective == "robustness" && !spec.contact.mu)
    throw UsageError(name("mu") +
                     ": the robustness objective needs a friction coefficient (or "
                     "the scene's contact.mu)");
  if (objective == "robustness" && !(*spec.contact.mu > 0))
    throw UsageError(name("mu") +
                     ": the robustness objective needs a positive friction "
                     "coefficient, got " +
                     format_number(*spec.contact.mu));
  if (spec.hand.shape != sim::HandSpec::Shape::kPolynomial)
    throw UsageError(std::string("hand.shape: design needs the polynomial hand (its a, b, c, d "
                                 "are designed); the scene's is ") +
                     sim::to_string(spec.hand.shape));
  if (!(std::isfinite(r.shape_range) && r.shape_range > 0 && r.shape_range < 1))
    throw UsageError(name("shape_range") +
                     ": must be in (0, 1) (a fraction of each coefficient), "
                     "got " +
                     format_number(r.shape_range));
  require_finite(name("fn_margin"), r.fn_margin);
  if (r.fn_margin < 0)
    throw UsageError(name("fn_margin") + ": must be >= 0 (of the weight), got " +
                     format_number(r.fn_margin));
  if (r.max_evaluations < 1 || r.max_evaluations > 100000)
    throw UsageError(name("max_evaluations") + ": must be in [1, 100000], got " +
                     std::to_string(r.max_evaluations));
  if (!(std::isfinite(r.tolerance) && r.tolerance > 0 && r.tolerance < 1))
    throw UsageError(name("tolerance") + ": must be in (0, 1) (relative), got " +
                     format_number(r.tolerance));
  std::vector<std::pair<std::string, std::string>> given;
  if (r.period) given.emplace_back("motion.period", name("period"));
  const auto problem = build_problem_checked(spec, given);
  sim::require_palm_and_back(spec.hand, *problem->hand, "design");
  return spec;
}

design::DesignResult design(const sim::SimulationSpec& spec, const DesignRequest& r,
                            const std::function<void(const design::Iterate&)>& progress) {
  design::DesignOptions o;
  o.objective = r.objective == "robustness" ? design::Objective::kRobustness
                                            : design::Objective::kLeastFriction;
  if (o.objective == design::Objective::kRobustness) o.mu = *spec.contact.mu;
  o.period = spec.motion.period;
  o.shape_free = !r.motion_only;
  o.shape_range = r.shape_range;
  o.fn_margin = r.fn_margin;
  o.max_evaluations = r.max_evaluations;
  o.tolerance = r.tolerance;
  return design::optimise(spec, o, progress);
}

sim::SolveReport solve(const sim::SimulationSpec& spec, const SolveRequest& r) {
  sim::SearchSettings settings;
  settings.tolerance = r.tolerance;
  return r.solve_for == "d" ? sim::solve_d(spec, spec.motion.period, spec.motion.k, settings)
                            : sim::solve_k(spec, spec.motion.period, settings);
}

sim::SpatialSpec prepare_spatial_simulate(const Scene& scene, const SimulateRequest& r,
                                          Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  if (!scene.spatial) throw std::logic_error("prepare_spatial_simulate: a planar scene");
  sim::SpatialSpec spec = *scene.spatial;
  if (r.model && *r.model != "rolling")
    throw UsageError(name("model") +
                     ": a spatial scene has the rolling model only (it stops where the contact is "
                     "lost or slips)");
  const bool butterfly = spec.motion.kind == sim::SpatialMotionSpec::Kind::kButterfly;
  if ((r.period || r.k) && !butterfly)
    throw UsageError(name(r.period ? "period" : "k") +
                     ": only for a scene whose motion is the butterfly");
  if (r.period) {
    require_positive(name("period"), *r.period, "s");
    spec.motion.period = *r.period;
  }
  if (r.k) {
    require_finite(name("k"), *r.k);
    spec.motion.k = *r.k;
  }
  if (r.duration) {
    require_positive(name("duration"), *r.duration, "s");
    spec.duration = *r.duration;
  }
  if (r.mu) apply_mu(*r.mu, spec, spelling);
  if (!r.stop_on_contact_loss) spec.stop_on_contact_loss = false;
  apply_integrator_overrides(r.integrator, spec.integrator, spelling);
  return spec;
}

PreparedSimulation prepare_simulate(Scene scene, const SimulateRequest& r, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  apply_integrator_overrides(r.integrator, scene, spelling);
  sim::SimulationSpec& spec = scene.sim;
  const bool butterfly = spec.motion.kind == sim::MotionSpec::Kind::kButterfly;
  if ((r.period || r.k) && !butterfly)
    throw UsageError(name("period") + "/" + name("k") +
                     ": the scene's motion is not the butterfly (motion.kind)");
  if (r.period) {
    require_positive(name("period"), *r.period, "2T in s");
    spec.motion.period = *r.period;
    if (!r.duration) spec.duration.reset();  // simulate the new 2T, not the scene's
  }
  if (r.k) {
    require_finite(name("k"), *r.k);
    spec.motion.k = *r.k;
  }
  if (r.duration) {
    require_positive(name("duration"), *r.duration, "s");
    spec.duration = *r.duration;
  }
  if (!r.stop_on_contact_loss) spec.run.events.stop_on_contact_loss = false;
  if (r.mu) apply_mu(*r.mu, spec, spelling);
  if (r.model) {
    const std::string& m = require_choice(name("model"), *r.model, {"rolling", "hybrid"});
    spec.run.model = m == "hybrid" ? sim::ContactModel::kHybrid : sim::ContactModel::kRolling;
  }
  if (!r.stop_on_contact_loss && spec.run.model == sim::ContactModel::kHybrid)
    throw UsageError((spelling == Spelling::kPython ? std::string("stop_on_contact_loss=False")
                                                    : std::string("--no-stop-on-contact-loss")) +
                     ": only for the rolling model (the hybrid model flies where contact is lost)");
  std::vector<std::pair<std::string, std::string>> given;
  if (r.k) given.emplace_back("motion.k", name("k"));
  if (r.period) given.emplace_back("motion.period", name("period"));
  if (r.mu) given.emplace_back("contact.mu", name("mu"));
  if (r.model) given.emplace_back("contact.model", name("model"));
  auto problem = build_problem_checked(spec, given);
  sim::resolve_formulation(*problem, spec.run.formulation);  // e.g. reduced for an ellipse
  try {  // a fixed step the budget cannot reach the end with, named as the caller gave it
    sim::check_fixed_step_budget(spec.run.integrator, spec.end_time() - spec.initial.t0);
  } catch (const std::invalid_argument& e) {
    if (!r.integrator.step && !r.duration) throw;
    throw UsageError(std::string(e.what()) + " (set by " +
                     name(r.integrator.step ? "step" : "duration") + ")");
  }
  return {spec, std::move(problem), r.keep_trajectory};
}

namespace {
// Recent steps a run keeps when its trajectory is not wanted: about 40 MB, and runs of fewer
// steps (the butterfly takes ~500) are never folded.
constexpr long kWindowSteps = 20000;
}  // namespace

sim::RunResult simulate(const PreparedSimulation& p) {
  sim::RunOptions options = sim::run_options(p.spec);
  options.record = true;  // the report needs the dense output and the per-step samples
  if (!p.keep_trajectory) options.keep_steps = kWindowSteps;
  if (p.spec.motion.kind == sim::MotionSpec::Kind::kButterfly)
    options.probe_times.push_back(p.spec.initial.t0 + 0.5 * p.spec.motion.period);  // s_h(T)
  return sim::simulate(p.problem, p.spec.initial, options);
}

sim::SimulationSpec prepare_time_optimal(Scene scene, const TimeOptimalRequest& r,
                                         Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  sim::SimulationSpec& spec = start_period_search(scene, r.integrator, r.from, r.to, spelling);
  require_positive(name("period_tolerance"), r.period_tolerance, "s");
  require_positive(name("tolerance"), r.tolerance, "");
  finish_period_search(spec, r.mu, r.from, spelling, "time-optimal");
  return spec;
}

sim::TimeOptimalReport time_optimal(const sim::SimulationSpec& spec, const TimeOptimalRequest& r) {
  sim::SearchSettings settings;
  settings.tolerance = r.tolerance;
  return sim::time_optimal(spec, r.from, r.to, r.period_tolerance, settings);
}

sim::SimulationSpec prepare_locus(Scene scene, const LocusRequest& r, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  sim::SimulationSpec& spec = start_period_search(scene, r.integrator, r.from, r.to, spelling);
  if (r.n < 1 || r.n > 10000)
    throw UsageError(name("n") +
                     ": must be in [1, 10000] (each is a solve of ~10 simulations), got " +
                     std::to_string(r.n));
  require_positive(name("tolerance"), r.tolerance, "");
  finish_period_search(spec, r.mu, r.from, spelling, "locus");
  return spec;
}

std::vector<sim::SolveReport> locus(const sim::SimulationSpec& spec, const LocusRequest& r,
                                    const sim::Progress& progress) {
  sim::SearchSettings settings;
  settings.tolerance = r.tolerance;
  return sim::locus(spec, r.from, r.to, r.n, settings, progress);
}

sim::SimulationSpec prepare_surface(Scene scene, const SurfaceRequest& r, Spelling spelling) {
  const auto name = [spelling](std::string_view n) { return option_name(n, spelling); };
  apply_integrator_overrides(r.integrator, scene, spelling);
  sim::SimulationSpec& spec = scene.sim;
  spec.motion.kind = sim::MotionSpec::Kind::kButterfly;
  require_increasing(name("k_from"), r.k_from, name("k_to"), r.k_to);
  if (r.k_from <= -2 && r.k_to >= -2)
    throw UsageError(name("k_from") + "/" + name("k_to") +
                     ": the range must not contain k = -2 (the motion is undefined there)");
  require_positive(name("period_from"), r.period_from, "2T in s");
  require_positive(name("period_to"), r.period_to, "2T in s");
  require_increasing(name("period_from"), r.period_from, name("period_to"), r.period_to);
  // Each grid point is one simulation (~0.1 ms to 1 ms): a million points is minutes.
  constexpr long kMaxSide = 10000, kMaxPoints = 1000000;
  if (r.nk < 2 || r.nk > kMaxSide)
    throw UsageError(name("nk") + ": must be in [2, 10000], got " + std::to_string(r.nk));
  if (r.np < 2 || r.np > kMaxSide)
    throw UsageError(name("np") + ": must be in [2, 10000], got " + std::to_string(r.np));
  if (static_cast<long>(r.nk) * r.np > kMaxPoints)
    throw UsageError(name("nk") + "/" + name("np") + ": " +
                     std::to_string(static_cast<long>(r.nk) * r.np) +
                     " grid points; at most 1000000 in one run");
  if (r.threads < 0 || r.threads > 1024)
    throw UsageError(name("threads") + ": must be in [0, 1024] (0 = all cores), got " +
                     std::to_string(r.threads));
  spec.motion.period = r.period_from;
  spec.motion.k = r.k_from;
  sim::require_palm_and_back(spec.hand, *sim::build_problem(spec)->hand, "surface");
  return spec;
}

sim::SurfaceResult surface(const sim::SimulationSpec& spec, const SurfaceRequest& r,
                           const sim::Progress& progress, const sim::SweepEngine* engine) {
  if (engine)
    return sim::surface(spec, r.k_from, r.k_to, r.nk, r.period_from, r.period_to, r.np, *engine,
                        progress);
  return sim::surface(spec, r.k_from, r.k_to, r.nk, r.period_from, r.period_to, r.np, r.threads,
                      progress);
}

}  // namespace flatland::api
