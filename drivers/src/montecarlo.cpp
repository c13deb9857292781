#include "flatland/drivers/montecarlo.hpp"

#include "flatland/sim/format.hpp"
#include "flatland/sim/parallel.hpp"

#include "flatland/drivers/experiment.hpp"

#include <boost/math/distributions/binomial.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <numbers>
#include <random>
#include <stdexcept>

namespace flatland::drivers {
namespace {

/// A uniform double in [0, 1) from the top 53 bits: unlike std::uniform_real_distribution, whose
/// algorithm the standard leaves open, this gives the same draws with every standard library.
double unit(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

/// nominal + U(-half, +half)
double around(std::mt19937_64& rng, double nominal, double half) {
  return nominal + half * (2.0 * unit(rng) - 1.0);
}

void require(bool ok, const std::string& field, const std::string& what, double v) {
  if (!ok)
    throw std::invalid_argument("perturbations." + field + ": " + what + ", got " +
                                std::to_string(v));
}

}  // namespace

void validate(const Perturbations& p) {
  const auto non_negative = [](double v) { return std::isfinite(v) && v >= 0; };
  require(non_negative(p.s_h), "s_h", "must be finite and >= 0", p.s_h);
  require(non_negative(p.tilt_deg), "tilt_deg", "must be finite and >= 0", p.tilt_deg);
  require(non_negative(p.radius_rel) && p.radius_rel < 1, "radius_rel", "must be in [0, 1)",
          p.radius_rel);
  require(non_negative(p.noise_dn), "noise_dn", "must be finite and >= 0", p.noise_dn);
  require(non_negative(p.latency), "latency", "must be finite and >= 0 (s)", p.latency);
  require(non_negative(p.latency_jitter) && p.latency_jitter <= p.latency, "latency_jitter",
          "must be in [0, latency] (a frame cannot arrive before it is captured)",
          p.latency_jitter);
  require(non_negative(p.drop) && p.drop < 1, "drop", "must be in [0, 1)", p.drop);
  require(non_negative(p.friction_rel) && p.friction_rel < 1, "friction_rel", "must be in [0, 1)",
          p.friction_rel);
  require(non_negative(p.contact_rel) && p.contact_rel < 1, "contact_rel", "must be in [0, 1)",
          p.contact_rel);
}

Scene perturb(const Scene& nominal, const Perturbations& p, std::uint64_t seed, int run,
              DrawnPerturbation* drawn) {
  validate(p);
  if (!nominal.camera)
    throw std::invalid_argument(nominal.origin +
                                ": camera: a Monte Carlo run needs the scene's camera section");
  if (run < 0) throw std::invalid_argument("perturb: run must be >= 0");
  // The stream depends on (seed, run) only: run i draws the same world whatever else is run.
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(run)};
  std::mt19937_64 rng(seq);
  constexpr double kDeg = std::numbers::pi / 180.0;

  Scene s = nominal;
  DrawnPerturbation d;
  // A fixed order of draws: adding a perturbation later must append, not reorder.
  d.s_h0 = around(rng, nominal.sim.initial.s_h, p.s_h);
  d.tilt_deg = around(rng, nominal.sim.tilt / kDeg, p.tilt_deg);
  d.radius = nominal.sim.object.radius * around(rng, 1.0, p.radius_rel);
  d.friction_scale = around(rng, 1.0, p.friction_rel);
  d.effects_seed = rng();
  d.mu_scale = around(rng, 1.0, p.contact_rel);
  d.loss_scale = around(rng, 1.0, p.contact_rel);

  s.sim.initial.s_h = d.s_h0;
  s.sim.tilt = d.tilt_deg * kDeg;
  s.sim.object.radius = d.radius;
  // A ring drawn larger or smaller as a whole; a disk's inner radius is 0 and stays 0.
  s.sim.object.inner_radius *= d.radius / nominal.sim.object.radius;
  s.joint.viscous *= d.friction_scale;
  s.joint.coulomb *= d.friction_scale;
  s.effects.noise_read_dn = p.noise_dn;
  s.effects.drop_probability = p.drop;
  s.effects.seed = d.effects_seed;
  sim::ContactLaw& law = s.sim.contact;
  if (law.mu) *law.mu *= d.mu_scale;
  if (law.mu_kinetic) *law.mu_kinetic *= d.mu_scale;
  law.rolling_resistance *= d.loss_scale;
  law.drag *= d.loss_scale;
  law.drag_angular *= d.loss_scale;
  s.camera->latency = p.latency;
  s.camera->latency_jitter = p.latency_jitter;
  if (drawn) *drawn = d;
  return s;
}

std::shared_ptr<const model::Model> compile_world(const Scene& nominal, const Perturbations& p,
                                                  std::uint64_t seed, int run,
                                                  DrawnPerturbation* drawn, const WorldEdit& edit) {
  Scene world = perturb(nominal, p, seed, run, drawn);
  if (edit) edit(world, run);
  try {
    return model::compile(std::move(world));
  } catch (const std::invalid_argument& e) {
    throw InvalidWorld("world (seed " + std::to_string(seed) + ", run " + std::to_string(run) +
                       ") cannot exist: " + e.what());
  }
}

Interval wilson_interval(long k, long n, double z) {
  if (n <= 0) return {0.0, 1.0};
  if (k < 0 || k > n) throw std::invalid_argument("wilson_interval: need 0 <= k <= n");
  const double nn = static_cast<double>(n);
  const double phat = static_cast<double>(k) / nn;
  const double z2 = z * z;
  const double denom = 1.0 + z2 / nn;
  const double centre = (phat + z2 / (2.0 * nn)) / denom;
  const double half = z / denom * std::sqrt(phat * (1.0 - phat) / nn + z2 / (4.0 * nn * nn));
  // Rounding can push the ends a hair outside [0, 1] at k = 0 or k = n.
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

Scene scene_for_controller(const Scene& nominal, const std::string& name,
                           const std::string& field) {
  Scene assumed = nominal;
  if (name == "open-loop") {
    assumed.controller.type = "paper";
    assumed.controller.mode = "open-loop";
    return assumed;
  }
  assumed.controller.mode = "feedback";
  if (name == "feedback") return assumed;
  const auto& types = control::controller_types();
  if (std::find(types.begin(), types.end(), name) == types.end()) {
    std::vector<std::string> known{"open-loop", "feedback"};
    known.insert(known.end(), types.begin(), types.end());
    throw std::invalid_argument(control::unknown_type_message(field, name, known));
  }
  assumed.controller.type = name;
  return assumed;
}

std::vector<MonteCarloController> controllers_by_name(const std::vector<std::string>& names) {
  std::vector<MonteCarloController> controllers;
  for (const std::string& name : names) controllers.emplace_back(name);
  return controllers;
}

MonteCarloResult run_montecarlo(const model::Model& nominal_model, const Perturbations& p, int n,
                                std::uint64_t seed,
                                const std::vector<MonteCarloController>& controllers,
                                unsigned threads, const MonteCarloProgress& progress,
                                const WorldEdit& edit) {
  return run_montecarlo(nominal_model, p, n, seed, controllers, sim::ThreadSweep(threads), progress,
                        edit);
}

sim::ItemCodec records_codec(std::vector<RunRecord>& records) {
  sim::ItemCodec codec;
  codec.pack = [&records](long i, sim::ByteWriter& w) {
    const RunRecord& r = records[static_cast<std::size_t>(i)];
    w.put(r.run);
    w.put(r.seed);
    w.put(r.controller);
    w.put(r.success);
    w.put(r.outcome);
    w.put(r.failure);
    for (double v : {r.slide_s, r.flight_s}) w.put(v);
    w.put(r.impacts);
    for (double v : {r.duration_s, r.s_end, r.fn_min_ratio, r.mu_max}) w.put(v);
    w.put(r.safe_stop);
    w.put(r.frames);
    w.put(r.frames_lost);
    static_assert(std::is_trivially_copyable_v<DrawnPerturbation>);
    w.put(r.drawn);
    w.put(r.stop_cause);
    w.put(r.mu);
  };
  codec.unpack = [&records](long i, sim::ByteReader& in) {
    RunRecord& r = records[static_cast<std::size_t>(i)];
    in.get(r.run);
    in.get(r.seed);
    in.get(r.controller);
    in.get(r.success);
    in.get(r.outcome);
    in.get(r.failure);
    in.get(r.slide_s);
    in.get(r.flight_s);
    in.get(r.impacts);
    in.get(r.duration_s);
    in.get(r.s_end);
    in.get(r.fn_min_ratio);
    in.get(r.mu_max);
    in.get(r.safe_stop);
    in.get(r.frames);
    in.get(r.frames_lost);
    in.get(r.drawn);
    in.get(r.stop_cause);
    in.get(r.mu);
  };
  return codec;
}

MonteCarloResult run_montecarlo(const model::Model& nominal_model, const Perturbations& p, int n,
                                std::uint64_t seed,
                                const std::vector<MonteCarloController>& controllers,
                                const sim::SweepEngine& engine, const MonteCarloProgress& progress,
                                const WorldEdit& edit) {
  const Scene& nominal = nominal_model.spec;
  validate(p);
  if (n < 1) throw std::invalid_argument("run_montecarlo: n must be >= 1");
  if (controllers.empty()) throw std::invalid_argument("run_montecarlo: no controller given");
  for (std::size_t i = 0; i < controllers.size(); ++i) {
    if (controllers[i].name.empty())
      throw std::invalid_argument("controller: a controller without a name");
    for (std::size_t j = 0; j < i; ++j)
      if (controllers[j].name == controllers[i].name)
        throw std::invalid_argument("controller: '" + controllers[i].name + "' given twice");
  }
  // Bad perturbations or scenes fail here, before any thread starts.
  perturb(nominal, p, seed, 0);
  require_friction(nominal);

  // One setup per controller, shared read-only by the workers (the plan is simulated once).
  std::vector<std::unique_ptr<const LoopSetup>> setups;
  for (const MonteCarloController& c : controllers) {
    Scene assumed = c.make ? nominal : scene_for_controller(nominal, c.name);
    setups.push_back(
        std::make_unique<const LoopSetup>(model::compile(std::move(assumed)), c.make, c.estimator));
  }

  const std::size_t nc = controllers.size();
  const long total = static_cast<long>(n) * static_cast<long>(nc);
  MonteCarloResult out;
  out.runs = n;
  out.records.resize(static_cast<std::size_t>(total));

  sim::ItemCodec codec = records_codec(out.records);
  codec.describe = [&](long job) {
    return "run " + std::to_string(job / static_cast<long>(nc)) + " (seed " + std::to_string(seed) +
           ") under " + controllers[static_cast<std::size_t>(job % static_cast<long>(nc))].name;
  };
  const auto start = std::chrono::steady_clock::now();
  // Experiment `job` is run job / nc under controller job % nc, whichever thread takes it.
  engine.run(
      total,
      [&](long job) {
        const int run = static_cast<int>(job / static_cast<long>(nc));
        const std::size_t ci = static_cast<std::size_t>(job % static_cast<long>(nc));
        RunRecord rec;
        rec.run = run;
        rec.seed = seed;
        rec.controller = controllers[ci].name;
        // Each world is its perturbed scene compiled anew (as MuJoCo edits a spec and recompiles).
        SyntheticResult r;
        try {
          const std::shared_ptr<const model::Model> world =
              compile_world(nominal, p, seed, run, &rec.drawn, edit);
          if (world->spec.sim.contact.mu) rec.mu = *world->spec.sim.contact.mu;
          r = run_synthetic(*setups[ci], world);
        } catch (const InvalidWorld& e) {
          // A draw the scene's rules refuse is no world: recorded with its (seed, run), and the
          // study goes on.
          rec.outcome = Outcome::kInvalidWorld;
          rec.failure = e.what();
          out.records[static_cast<std::size_t>(job)] = std::move(rec);
          return;
        } catch (const std::runtime_error& e) {
          // One world whose simulation fails does not end the study: it is recorded, with the
          // (seed, run) that rebuilds it, and counted apart from the physical outcomes.
          rec.outcome = Outcome::kNumericalFailure;
          rec.failure = e.what();
          out.records[static_cast<std::size_t>(job)] = std::move(rec);
          return;
        }
        rec.success = r.success;
        rec.outcome = r.outcome;
        rec.failure = r.failure;
        rec.slide_s = r.mode_time[static_cast<int>(sim::ContactMode::kSliding)];
        rec.flight_s = r.mode_time[static_cast<int>(sim::ContactMode::kFlight)];
        rec.impacts = r.impacts;
        rec.duration_s = r.loop.duration_s;
        rec.s_end = r.s_end;
        rec.fn_min_ratio = r.fn_min_ratio;
        rec.mu_max = r.mu_max;
        rec.safe_stop = r.loop.safe_stop;
        if (r.loop.stop_reason) rec.stop_cause = r.loop.stop_reason->cause;
        rec.frames = r.loop.frames;
        rec.frames_lost = r.loop.frames_lost;
        out.records[static_cast<std::size_t>(job)] = std::move(rec);
      },
      codec,
      [&](long finished) {
        if (progress) progress(finished, total);
      });
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  // A world that failed numerically has no physical outcome: the rates are over the others.
  for (const MonteCarloController& c : controllers) {
    ControllerSummary sum;
    sum.name = c.name;
    for (const RunRecord& r : out.records) {
      if (r.controller != c.name) continue;
      sum.numerical_failures += r.outcome == Outcome::kNumericalFailure;
      sum.invalid_worlds += r.outcome == Outcome::kInvalidWorld;
      sum.successes += r.success;
    }
    sum.ci = wilson_interval(sum.successes, n - sum.numerical_failures - sum.invalid_worlds);
    if (c.name == "open-loop") {
      out.success_open_loop = sum.successes;
      out.numerical_failures_open_loop = sum.numerical_failures;
      out.ci_open_loop = sum.ci;
    } else if (c.name == "feedback") {
      out.success_feedback = sum.successes;
      out.numerical_failures_feedback = sum.numerical_failures;
      out.ci_feedback = sum.ci;
    }
    out.summaries.push_back(std::move(sum));
  }
  return out;
}

double quantile(std::vector<double> values, double q) {
  if (!(q >= 0 && q <= 1)) throw std::invalid_argument("quantile: q must be in [0, 1]");
  if (values.empty()) return NAN;
  for (double v : values)
    if (!std::isfinite(v)) throw std::invalid_argument("quantile: a value is not finite");
  std::sort(values.begin(), values.end());
  const double h = static_cast<double>(values.size() - 1) * q;
  const std::size_t lo = static_cast<std::size_t>(std::floor(h));
  if (lo + 1 >= values.size()) return values.back();
  return values[lo] + (h - static_cast<double>(lo)) * (values[lo + 1] - values[lo]);
}

Spread spread(const std::vector<double>& values) {
  Spread s;
  s.n = static_cast<int>(values.size());
  if (values.empty()) return s;
  s.min = quantile(values, 0);
  s.p05 = quantile(values, 0.05);
  s.median = quantile(values, 0.5);
  s.p95 = quantile(values, 0.95);
  s.max = quantile(values, 1);
  return s;
}

double mcnemar_exact_p(long only_a, long only_b) {
  if (only_a < 0 || only_b < 0) throw std::invalid_argument("mcnemar_exact_p: counts must be >= 0");
  const long discordant = only_a + only_b;
  if (discordant == 0) return 1.0;
  // Boost.Math's binomial CDF (through the incomplete beta function): exact to rounding for any
  // count, where summing the terms by hand would underflow past about a thousand worlds.
  const boost::math::binomial_distribution<double> coin(static_cast<double>(discordant), 0.5);
  const double tail = boost::math::cdf(coin, static_cast<double>(std::min(only_a, only_b)));
  return std::min(1.0, 2.0 * tail);
}

namespace {

/// Every outcome, in the enum's order: the reports list them all, zeros included.
constexpr Outcome kOutcomes[] = {
    Outcome::kSuccess,     Outcome::kDropped,          Outcome::kSlidOff,
    Outcome::kWrongWell,   Outcome::kNotSettled,       Outcome::kSafeStop,
    Outcome::kNotFinished, Outcome::kNumericalFailure, Outcome::kInvalidWorld};

ControllerReport report_of(const std::string& name, const std::vector<const RunRecord*>& runs) {
  ControllerReport rep;
  rep.name = name;
  rep.runs = static_cast<int>(runs.size());
  for (Outcome o : kOutcomes) rep.outcomes[to_string(o)] = 0;
  std::vector<double> duration, fn_min, friction;
  for (const RunRecord* r : runs) {
    ++rep.outcomes[to_string(r->outcome)];
    if (!has_physical_outcome(r->outcome)) {
      ++(r->outcome == Outcome::kInvalidWorld ? rep.invalid_worlds : rep.numerical_failures);
      continue;
    }
    if (r->outcome == Outcome::kSafeStop)
      ++rep.safe_stops[r->stop_cause ? control::to_string(*r->stop_cause) : "other"];
    if (!r->success) continue;
    ++rep.successes;
    if (std::isfinite(r->duration_s)) duration.push_back(r->duration_s);
    if (std::isfinite(r->fn_min_ratio)) fn_min.push_back(r->fn_min_ratio);
    if (std::isfinite(r->mu_max) && std::isfinite(r->mu) && r->mu > 0)
      friction.push_back(r->mu_max / r->mu);
  }
  rep.ci = wilson_interval(rep.successes, rep.runs - rep.numerical_failures - rep.invalid_worlds);
  rep.duration_s = spread(duration);
  rep.fn_min_ratio = spread(fn_min);
  rep.friction_use = spread(friction);
  return rep;
}

}  // namespace

ControllerComparison compare_controllers(const MonteCarloResult& result) {
  const std::size_t nc = result.summaries.size();
  const std::size_t worlds = static_cast<std::size_t>(std::max(result.runs, 0));
  // by_world[run][c]: the record of world `run` under controller c.
  std::vector<std::vector<const RunRecord*>> by_world(worlds,
                                                      std::vector<const RunRecord*>(nc, nullptr));
  for (const RunRecord& r : result.records) {
    std::size_t c = 0;
    while (c < nc && result.summaries[c].name != r.controller) ++c;
    if (c == nc || r.run < 0 || static_cast<std::size_t>(r.run) >= worlds ||
        by_world[static_cast<std::size_t>(r.run)][c])
      throw std::invalid_argument("compare_controllers: record of run " + std::to_string(r.run) +
                                  " under '" + r.controller +
                                  "' is unknown, out of range or repeated");
    by_world[static_cast<std::size_t>(r.run)][c] = &r;
  }
  ControllerComparison out;
  for (std::size_t c = 0; c < nc; ++c) {
    std::vector<const RunRecord*> runs;
    for (std::size_t w = 0; w < worlds; ++w) {
      if (!by_world[w][c])
        throw std::invalid_argument("compare_controllers: run " + std::to_string(w) +
                                    " has no record under '" + result.summaries[c].name + "'");
      runs.push_back(by_world[w][c]);
    }
    out.controllers.push_back(report_of(result.summaries[c].name, runs));
  }
  const auto counted = [](const RunRecord* r) { return has_physical_outcome(r->outcome); };
  for (std::size_t a = 0; a < nc; ++a)
    for (std::size_t b = a + 1; b < nc; ++b) {
      PairedComparison pair;
      pair.a = result.summaries[a].name;
      pair.b = result.summaries[b].name;
      for (std::size_t w = 0; w < worlds; ++w) {
        const RunRecord* ra = by_world[w][a];
        const RunRecord* rb = by_world[w][b];
        if (!counted(ra) || !counted(rb)) continue;
        ++pair.worlds;
        if (ra->success && rb->success)
          ++pair.both;
        else if (ra->success)
          ++pair.only_a;
        else if (rb->success)
          ++pair.only_b;
        else
          ++pair.neither;
      }
      pair.p_value = mcnemar_exact_p(pair.only_a, pair.only_b);
      out.pairs.push_back(std::move(pair));
    }
  return out;
}

namespace {
/// A CSV field: quoted (with doubled quotes) when it holds a comma, quote or line break.
std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}
}  // namespace

std::string runs_csv(const MonteCarloResult& r) {
  using sim::format_number;
  std::string s =
      "run,controller,success,failure,duration_s,s_end,fn_min_ratio,mu_max,safe_stop,frames,"
      "frames_lost,s_h0,tilt_deg,radius_m,friction_scale,effects_seed,outcome,slide_s,flight_s,"
      "impacts,mu_scale,loss_scale,seed,mu,stop_cause\n";
  for (const RunRecord& x : r.records)
    s += std::to_string(x.run) + "," + x.controller + "," + (x.success ? "1" : "0") + "," +
         csv_field(x.failure) + "," + format_number(x.duration_s) + "," + format_number(x.s_end) +
         "," + format_number(x.fn_min_ratio) + "," + format_number(x.mu_max) + "," +
         (x.safe_stop ? "1" : "0") + "," + std::to_string(x.frames) + "," +
         std::to_string(x.frames_lost) + "," + format_number(x.drawn.s_h0) + "," +
         format_number(x.drawn.tilt_deg) + "," + format_number(x.drawn.radius) + "," +
         format_number(x.drawn.friction_scale) + "," + std::to_string(x.drawn.effects_seed) + "," +
         to_string(x.outcome) + "," + format_number(x.slide_s) + "," + format_number(x.flight_s) +
         "," + std::to_string(x.impacts) + "," + format_number(x.drawn.mu_scale) + "," +
         format_number(x.drawn.loss_scale) + "," + std::to_string(x.seed) + "," +
         format_number(x.mu) + "," + (x.stop_cause ? control::to_string(*x.stop_cause) : "") + "\n";
  return s;
}

}  // namespace flatland::drivers
