// flatland montecarlo: the closed loop's robustness: N synthetic experiments per controller in
// worlds perturbed from the nominal scene (initial position, tilt, disk radius, camera noise,
// latency, drops, motor friction), with the success rates and their Wilson 95 % intervals.
#include "common.hpp"

#include "flatland/drivers/montecarlo.hpp"
#include "flatland/sim/format.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>

namespace flatland::app {

namespace {

struct MonteCarloOptions {
  CommonOptions common;
  int n = 100;
  std::int64_t seed = 1;  // read signed: a negative seed is refused, not wrapped around
  std::vector<std::string> controllers = {"open-loop", "feedback"};
  unsigned threads = 0;
  CLI::Option* threads_opt = nullptr;
  drivers::Perturbations p;
};

Json perturbations_json(const drivers::Perturbations& p) {
  Json j;
  j["s_h"] = p.s_h;
  j["tilt_deg"] = p.tilt_deg;
  j["radius_rel"] = p.radius_rel;
  j["noise_dn"] = p.noise_dn;
  j["latency"] = p.latency;
  j["latency_jitter"] = p.latency_jitter;
  j["drop"] = p.drop;
  j["friction_rel"] = p.friction_rel;
  j["contact_rel"] = p.contact_rel;
  return j;
}

Json spread_json(const drivers::Spread& s) {
  return {{"n", s.n},
          {"min", number(s.min)},
          {"p05", number(s.p05)},
          {"median", number(s.median)},
          {"p95", number(s.p95)},
          {"max", number(s.max)}};
}

/// Per controller: success with its interval, outcomes, safe stops by cause, the successes'
/// duration and margins (drivers::ControllerReport); the same keys as Python's montecarlo().
Json report_json(const drivers::ControllerReport& c) {
  return {{"controller", c.name},
          {"runs", c.runs},
          {"successes", c.successes},
          {"numerical_failures", c.numerical_failures},
          {"invalid_worlds", c.invalid_worlds},
          {"ci95", Json::array({c.ci.lo, c.ci.hi})},
          {"outcomes", c.outcomes},
          {"safe_stops", c.safe_stops},
          {"duration_s", spread_json(c.duration_s)},
          {"fn_min_ratio", spread_json(c.fn_min_ratio)},
          {"friction_use", spread_json(c.friction_use)}};
}

Json pair_json(const drivers::PairedComparison& p) {
  return {
      {"a", p.a},           {"b", p.b},           {"worlds", p.worlds},   {"both", p.both},
      {"only_a", p.only_a}, {"only_b", p.only_b}, {"neither", p.neither}, {"p_value", p.p_value}};
}

/// The text lines of one controller: its rate, how the others ended, its successes' margins.
void print_report(std::ostream& os, const drivers::ControllerReport& c, std::size_t width) {
  const auto padded = [&](const std::string& text) {
    return text + std::string(width > text.size() ? width - text.size() : 0, ' ');
  };
  const int counted = c.runs - c.numerical_failures - c.invalid_worlds;
  const double pct = counted > 0 ? 100.0 * c.successes / counted : 0.0;
  os << "  " << padded(c.name) << "  " << c.successes << " / " << counted << " succeeded ("
     << std::lround(pct) << " %; 95 % interval " << std::lround(100 * c.ci.lo) << " .. "
     << std::lround(100 * c.ci.hi) << " %)";
  if (c.numerical_failures > 0)
    os << "; " << c.numerical_failures << " world" << (c.numerical_failures == 1 ? "" : "s")
       << " failed numerically, not counted";
  if (c.invalid_worlds > 0)
    os << "; " << c.invalid_worlds << " world" << (c.invalid_worlds == 1 ? "" : "s")
       << " drawn could not exist, not counted";
  os << "\n";
  std::string failures;
  for (const auto& [kind, n] : c.outcomes) {
    if (kind == "success" || kind == "numerical_failure" || kind == "invalid_world" || n == 0)
      continue;
    failures += (failures.empty() ? "" : ", ") + std::to_string(n) + " " + kind;
    if (kind == "safe_stop") {
      std::string causes;
      for (const auto& [cause, k] : c.safe_stops)
        causes += (causes.empty() ? "" : ", ") + std::to_string(k) + " " + cause;
      failures += " (" + causes + ")";
    }
  }
  if (!failures.empty()) os << "  " << padded("") << "  failures: " << failures << "\n";
  if (c.successes == 0) return;
  const auto g3 = [](double v) { return sim::format_significant(v, 3); };
  os << "  " << padded("") << "  successes: duration median " << g3(c.duration_s.median)
     << " s (max " << g3(c.duration_s.max) << "); f_n min / (m g sin tilt) median "
     << g3(c.fn_min_ratio.median) << " (5th percentile " << g3(c.fn_min_ratio.p05) << ", worst "
     << g3(c.fn_min_ratio.min) << "); friction used of mu median " << g3(c.friction_use.median)
     << " (95th percentile " << g3(c.friction_use.p95) << ", worst " << g3(c.friction_use.max)
     << ")\n";
}

/// Bad input, before anything runs or is written: a UsageError (or std::invalid_argument) naming
/// the option.
void check_options(const MonteCarloOptions& o, const Scene& scene) {
  if (o.n < 1 || o.n > 1000000)
    throw UsageError("--n: must be in [1, 1000000], got " + std::to_string(o.n));
  if (o.seed < 0) throw UsageError("--seed: must be >= 0, got " + std::to_string(o.seed));
  if (o.threads > 1024)
    throw UsageError("--threads: must be in [0, 1024] (0 = all cores), got " +
                     std::to_string(o.threads));
  const struct {
    const char* option;
    double value;
  } values[] = {{"--s-h", o.p.s_h},
                {"--tilt-deg", o.p.tilt_deg},
                {"--radius-rel", o.p.radius_rel},
                {"--noise-dn", o.p.noise_dn},
                {"--latency", o.p.latency},
                {"--latency-jitter", o.p.latency_jitter},
                {"--drop", o.p.drop},
                {"--friction-rel", o.p.friction_rel},
                {"--contact-rel", o.p.contact_rel}};
  for (const auto& v : values)
    if (!std::isfinite(v.value) || v.value < 0)
      throw UsageError(std::string(v.option) + ": must be finite and >= 0, got " +
                       format_number(v.value));
  if (o.p.radius_rel >= 1)
    throw UsageError("--radius-rel: must be < 1, got " + format_number(o.p.radius_rel));
  if (o.p.friction_rel >= 1)
    throw UsageError("--friction-rel: must be < 1, got " + format_number(o.p.friction_rel));
  if (o.p.contact_rel >= 1)
    throw UsageError("--contact-rel: must be < 1, got " + format_number(o.p.contact_rel));
  if (o.p.drop >= 1) throw UsageError("--drop: must be < 1, got " + format_number(o.p.drop));
  if (o.p.latency_jitter > o.p.latency)
    throw UsageError("--latency-jitter: must not exceed --latency (" + format_number(o.p.latency) +
                     " s), got " + format_number(o.p.latency_jitter));
  if (o.controllers.empty()) throw UsageError("--controller: no controller given");
  for (std::size_t i = 0; i < o.controllers.size(); ++i) {
    // std::invalid_argument (exit 2) naming --controller and the known names.
    drivers::scene_for_controller(scene, o.controllers[i], "--controller");
    for (std::size_t j = 0; j < i; ++j)
      if (o.controllers[i] == o.controllers[j])
        throw UsageError("--controller: " + o.controllers[i] + " given twice");
  }
  if (!scene.camera)
    throw UsageError(scene.origin +
                     ": camera: the scene has no camera section (needed by the "
                     "closed loop)");
  drivers::require_friction(scene);
}

void run_montecarlo_command(const MonteCarloOptions& o) {
  // ---- bad input first
  CommonOptions common = o.common;
  if (common.scene.empty()) common.scene = default_experiment_scene();
  const Scene scene = load_scene_with_overrides(common);
  check_options(o, scene);
  const fs::path dir = o.common.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.common.force);
  // The scene as every controller assumes it compiles before anything is printed: a bad type or
  // config is the one line of bad input.
  const auto nominal = model::compile(scene);
  drivers::require_plannable(*nominal);
  for (const std::string& name : o.controllers)
    model::compile(drivers::scene_for_controller(scene, name, "--controller"));

  const auto engine = make_sweep_engine(o.threads, o.threads_opt->count() > 0);
  const unsigned threads = engine->threads();
  rasterise_on_workers(*engine);
  const long experiments = static_cast<long>(o.n) * static_cast<long>(o.controllers.size());
  std::cerr << "flatland: " << o.n << " runs x " << o.controllers.size() << " controllers on "
            << where_it_runs(*engine) << ", seed " << o.seed << ", " << scene.origin << "\n";
  drivers::MonteCarloResult r;
  {
    ProgressBar bar("montecarlo");
    r = drivers::run_montecarlo(*nominal, o.p, o.n, static_cast<std::uint64_t>(o.seed),
                                drivers::controllers_by_name(o.controllers), *engine,
                                bar.callback());
  }
  const double per_second = r.seconds > 0 ? static_cast<double>(experiments) / r.seconds : 0;

  const auto ci = [](int successes, const drivers::Interval& i) {
    return successes < 0 ? Json(nullptr) : Json::array({i.lo, i.hi});
  };
  const auto count = [](int successes) { return successes < 0 ? Json(nullptr) : Json(successes); };
  Json j;
  j["runs"] = r.runs;
  j["success_open_loop"] = count(r.success_open_loop);
  j["success_feedback"] = count(r.success_feedback);
  j["ci95"] = {{"open_loop", ci(r.success_open_loop, r.ci_open_loop)},
               {"feedback", ci(r.success_feedback, r.ci_feedback)}};
  // Worlds whose simulation failed: no physical outcome, left out of the rates.
  j["numerical_failures"] = {
      {"open_loop", r.success_open_loop < 0 ? Json(nullptr) : Json(r.numerical_failures_open_loop)},
      {"feedback", r.success_feedback < 0 ? Json(nullptr) : Json(r.numerical_failures_feedback)}};
  Json failed = Json::array();
  for (const drivers::RunRecord& x : r.records)
    if (x.outcome == drivers::Outcome::kNumericalFailure)
      failed.push_back(
          {{"run", x.run}, {"seed", x.seed}, {"controller", x.controller}, {"failure", x.failure}});
  j["numerical_failure_runs"] = failed;
  // Worlds the draw made impossible (a rule of the scene broken): each with the seed that draws it.
  Json invalid = Json::array();
  for (const drivers::RunRecord& x : r.records)
    if (x.outcome == drivers::Outcome::kInvalidWorld)
      invalid.push_back(
          {{"run", x.run}, {"seed", x.seed}, {"controller", x.controller}, {"failure", x.failure}});
  j["invalid_world_runs"] = invalid;
  // Every controller's report and every pair's paired comparison (drivers::compare_controllers);
  // "outcomes" (how the runs ended, per controller) is older than "summaries" and kept.
  const drivers::ControllerComparison comparison = drivers::compare_controllers(r);
  Json outcomes, summaries = Json::array(), pairs = Json::array();
  for (const drivers::ControllerReport& c : comparison.controllers) {
    outcomes[c.name] = c.outcomes;
    summaries.push_back(report_json(c));
  }
  for (const drivers::PairedComparison& p : comparison.pairs) pairs.push_back(pair_json(p));
  j["outcomes"] = outcomes;
  j["summaries"] = summaries;
  j["pairs"] = pairs;
  j["perturbations"] = perturbations_json(o.p);
  j["runs_per_second"] = number(per_second);
  j["experiments"] = experiments;
  j["seconds"] = number(r.seconds);
  j["seed"] = o.seed;
  j["threads"] = threads;
  j["ranks"] = engine->processes();
  j["controllers"] = o.controllers;
  j["scene"] = scene.origin;

  OutputSet outputs(o.common.force);
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    outputs.stage(dir / "runs.csv", drivers::runs_csv(r));
    outputs.stage(dir / "result.json", j.dump(2) + "\n");
    outputs.commit();
  }

  if (o.common.json) {
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland montecarlo: " << scene.origin << ", " << r.runs << " runs, seed " << o.seed
     << "\n";
  std::size_t width = 0;
  for (const std::string& c : o.controllers) width = std::max(width, c.size());
  for (const drivers::ControllerReport& c : comparison.controllers) print_report(os, c, width);
  for (const drivers::PairedComparison& p : comparison.pairs)
    os << "  paired: " << p.a << " vs " << p.b << " on " << p.worlds << " worlds: both succeeded "
       << p.both << ", only " << p.a << " " << p.only_a << ", only " << p.b << " " << p.only_b
       << ", neither " << p.neither
       << " (exact McNemar p = " << sim::format_significant(p.p_value, 2) << ")\n";
  os << "  speed  " << format_number(std::round(per_second * 100) / 100) << " experiments/s on "
     << threads << " threads (" << format_number(std::round(r.seconds)) << " s)\n";
  for (const std::string& p : outputs.paths()) os << "  wrote  " << p << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_montecarlo_command(CLI::App& app) {
  auto o = std::make_shared<MonteCarloOptions>();
  CLI::App* cmd = add_command(app, "montecarlo");
  add_common_options(*cmd, o->common,
                     "Directory for runs.csv (one row per experiment) and result.json; created, "
                     "and refused if it exists and is not empty. Default: no files",
                     false);
  cmd->get_option("--scene")->description(
      "Scene file (YAML, SI units; schema in docs/SCENE.md). Default: the bundled closed-loop "
      "scene, " +
      default_experiment_scene());
  cmd->add_option("--n", o->n,
                  "Runs (perturbed worlds) per controller (1 to 1000000). Default: 100");
  cmd->add_option("--seed", o->seed,
                  "Seed of the draws, 0 to 2^63 - 1 (with the run number: run i is the same world "
                  "whatever N and --threads are). Default: 1");
  std::string known = "open-loop, feedback";
  for (const std::string& type : control::controller_types()) known += ", " + type;
  cmd->add_option(
         "--controller", o->controllers,
         "Controllers to compare on the same worlds, comma-separated or repeated: " + known +
             " (open-loop: the paper's plan played back; feedback: the scene's "
             "controller.type; a type: that controller in feedback mode). Default: "
             "open-loop,feedback")
      ->delimiter(',');
  o->threads_opt = cmd->add_option(
      "--threads", o->threads,
      "Worker threads, each running whole experiments with its own GL context (0 = all cores). "
      "Under mpirun: per rank, >= 1 (default 1). Results do not depend on it. Default: 0");
  const std::string g = "Perturbations (uniform +-half-widths around the scene's values)";
  const drivers::Perturbations d;
  const auto def = [](double v) { return " Default: " + format_number(v); };
  cmd->add_option("--s-h", o->p.s_h, "Initial s_h: +- this (dimensionless)." + def(d.s_h))
      ->group(g);
  cmd->add_option("--tilt-deg", o->p.tilt_deg, "Table tilt: +- this, deg." + def(d.tilt_deg))
      ->group(g);
  cmd->add_option("--radius-rel", o->p.radius_rel,
                  "Disk radius: +- this fraction (< 1)." + def(d.radius_rel))
      ->group(g);
  cmd->add_option("--friction-rel", o->p.friction_rel,
                  "Joint viscous and Coulomb friction: scaled by 1 +- this (< 1), one factor for "
                  "both." +
                      def(d.friction_rel))
      ->group(g);
  cmd->add_option("--contact-rel", o->p.contact_rel,
                  "The contact's friction coefficients (mu, mu_kinetic) scaled by 1 +- this, its "
                  "losses (rolling resistance, drag) by another factor 1 +- this (< 1)." +
                      def(d.contact_rel))
      ->group(g);
  cmd->add_option("--noise-dn", o->p.noise_dn,
                  "Camera read noise sigma, DN (set in every run)." + def(d.noise_dn))
      ->group(g);
  cmd->add_option("--latency", o->p.latency,
                  "Camera latency, s (set in every run)." + def(d.latency))
      ->group(g);
  cmd->add_option(
         "--latency-jitter", o->p.latency_jitter,
         "Half-width of the latency's uniform spread, s (<= --latency)." + def(d.latency_jitter))
      ->group(g);
  cmd->add_option("--drop", o->p.drop,
                  "Probability that a frame is dropped (< 1; set in every run)." + def(d.drop))
      ->group(g);
  return {cmd, [o] { run_montecarlo_command(*o); }};
}

}  // namespace flatland::app
