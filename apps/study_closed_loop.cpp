// flatland study closed-loop: success of the vision-feedback loop against camera rate and latency.
// Every cell of the grid (rate x latency) runs the same N perturbed worlds (drivers::perturb with
// the default Monte Carlo perturbations and a fixed seed, so the cells differ only in the camera)
// through the feedback controller; the open loop is run once, at the scene's rate and latency, as
// the baseline. Per cell: successes with their Wilson 95 % interval, why the others failed, the
// smallest normal force, the estimator's error while it steers the hand, and what the cell cost.
#include "study.hpp"

#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/montecarlo.hpp"
#include "flatland/sim/parallel.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <thread>

namespace flatland::app {

namespace {

constexpr std::uint64_t kSeed = 1;  // as `flatland montecarlo`'s default: the same worlds
// Worlds per cell. The full grid is 24 feedback cells and the baseline, 750 experiments of
// 0.25 (15 Hz) to 2 s (120 Hz) CPU each: about 8 minutes on two cores (docs/ACCURACY.md). The
// Wilson interval of 30/30 is 88.6-100 %; more worlds would not fit the budget.
constexpr int kRunsFull = 30;
constexpr int kRunsQuick = 2;
// --quick's second latency: beyond the safety monitor's default lost_timeout (0.25 s), so no
// frame arrives before the monitor gives up and every run must end in a safe stop. It makes the
// quick grid a test that can fail (a cell that must fail next to one that should not).
constexpr double kAbsurdLatency = 0.3;

struct Cell {
  double fps = 30, latency = 0, jitter = 0;
  std::string controller = "feedback";
};

/// What one experiment left that the study aggregates.
struct RunSummary {
  bool success = false;
  drivers::Outcome outcome = drivers::Outcome::kNotFinished;
  std::optional<control::StopCause> stop_cause;  // why it stopped safely (outcome kSafeStop)
  double fn_min = NAN, duration = NAN, est_rms = NAN, nees = NAN;
  long frames = 0, frames_lost = 0;
};

struct CellResult {
  Cell cell;
  std::vector<RunSummary> runs;
  int successes = 0;
  drivers::Interval ci;
  std::map<std::string, int> failures;  // failure class -> count
  double fn_min_mean = NAN, fn_min_min = NAN, duration_mean = NAN, est_rms = NAN, nees = NAN;
  double frames_lost_fraction = NAN;
  double wall = 0, cpu = 0;  // s, the whole cell (all its runs, on all threads)
};

/// A short class for how a run failed, for the breakdown per cell: the outcome, and for a safe
/// stop what triggered it.
std::string failure_class(const RunSummary& r) {
  if (r.outcome != drivers::Outcome::kSafeStop) return drivers::to_string(r.outcome);
  if (!r.stop_cause) return "safe_stop (other)";
  return std::string("safe_stop (") + control::to_string(*r.stop_cause) + ")";
}

/// The CSV's failure columns: classes folded into five.
int failure_column(const std::string& cls) {
  if (cls == "dropped") return 0;
  if (cls == "slid_off") return 1;
  if (cls == "wrong_well" || cls == "not_settled") return 2;
  if (cls.rfind("safe_stop", 0) == 0) return 3;
  return 4;
}
const char* const kFailureColumns[] = {"fail_dropped", "fail_slid_off", "fail_wrong_well",
                                       "fail_safe_stop", "fail_other"};

/// The scene the loop assumes in a cell: the nominal scene with the cell's camera. The truth
/// worlds are perturbed from it, so the loop and the world agree on the camera's rate and
/// latency. The estimator's latency compensation rewinds to each frame's capture time stamp (the
/// synthetic camera's stamps are exact), so it compensates the latency a frame really had; the
/// scene's camera.latency only sizes the estimator's history (drivers::LoopSetup), which must
/// reach back that far.
Scene cell_scene(const Scene& nominal, const Cell& c) {
  Scene s = nominal;
  s.controller.mode = c.controller;
  s.camera->fps = c.fps;
  // scene validation: exposure <= 1/fps. A faster camera cannot expose longer than its frame.
  s.camera->exposure = std::min(s.camera->exposure, 1.0 / c.fps);
  s.camera->latency = c.latency;
  s.camera->latency_jitter = c.jitter;
  return s;
}

/// The estimate while it steers the hand (the servo stage, before any failure stops the world):
/// the RMS of its error in s_h over every tick, and its mean NEES at the ticks that folded in a
/// measurement (about 2 for a consistent filter). NaN if the run never servoed. Both are taken
/// over the same window in every run, so a run that failed does not add the estimate's drift
/// against a world that has stopped.
struct ServoStats {
  double err_rms = NAN, nees = NAN;
};
ServoStats servo_stats(const drivers::LoopResult& loop) {
  double sum = 0, nees = 0;
  long n = 0, m = 0;
  for (const drivers::TickLog& row : loop.log) {
    if (row.stage != control::Stage::kServo || !row.estimating || !std::isfinite(row.s_true))
      continue;
    const double e = row.s_est - row.s_true;
    sum += e * e;
    ++n;
    if (row.measured && std::isfinite(row.nees)) {
      nees += row.nees;
      ++m;
    }
  }
  ServoStats s;
  if (n) s.err_rms = std::sqrt(sum / static_cast<double>(n));
  if (m) s.nees = nees / static_cast<double>(m);
  return s;
}

double mean_finite(const std::vector<RunSummary>& runs, double RunSummary::*field,
                   bool successes_only = false) {
  double sum = 0;
  long n = 0;
  for (const RunSummary& r : runs)
    if (std::isfinite(r.*field) && (!successes_only || r.success)) {
      sum += r.*field;
      ++n;
    }
  return n ? sum / static_cast<double>(n) : NAN;
}

/// Run the cell's `n` worlds on `threads` threads (each experiment owns its renderer and GL
/// context). Run i's world is perturb(assumed, p, kSeed, i) in every cell. An exception in any
/// run stops the others and is rethrown (a failed experiment is a result, not an exception).
CellResult run_cell(const Scene& nominal, const Cell& cell, int n, unsigned threads,
                    const std::function<void()>& tick) {
  CellResult out;
  out.cell = cell;
  const Scene assumed = cell_scene(nominal, cell);
  drivers::Perturbations p;
  p.latency = cell.latency;
  p.latency_jitter = cell.jitter;
  const drivers::LoopSetup setup(model::compile(assumed));
  out.runs.resize(static_cast<std::size_t>(n));

  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = cpu_now();
  sim::parallel_for(
      n, std::max(1u, threads),
      [&](long index) {
        const int run = static_cast<int>(index);
        const drivers::SyntheticResult r =
            drivers::run_synthetic(setup, model::compile(drivers::perturb(assumed, p, kSeed, run)));
        RunSummary s;
        s.success = r.success;
        s.outcome = r.outcome;
        if (r.loop.stop_reason) s.stop_cause = r.loop.stop_reason->cause;
        s.fn_min = r.fn_min_ratio;
        s.duration = r.success ? r.loop.duration_s : NAN;
        const ServoStats servo = servo_stats(r.loop);
        s.est_rms = servo.err_rms;
        s.nees = servo.nees;
        s.frames = r.loop.frames;
        s.frames_lost = r.loop.frames_lost;
        out.runs[static_cast<std::size_t>(run)] = std::move(s);
      },
      [&](long) { tick(); });
  out.cpu = cpu_now() - cpu0;
  out.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  long frames = 0, lost = 0;
  for (const RunSummary& r : out.runs) {
    if (r.success)
      ++out.successes;
    else
      ++out.failures[failure_class(r)];
    frames += r.frames;
    lost += r.frames_lost;
    if (r.success && std::isfinite(r.fn_min))
      out.fn_min_min = std::isnan(out.fn_min_min) ? r.fn_min : std::min(out.fn_min_min, r.fn_min);
  }
  out.ci = drivers::wilson_interval(out.successes, n);
  out.fn_min_mean = mean_finite(out.runs, &RunSummary::fn_min, true);
  out.duration_mean = mean_finite(out.runs, &RunSummary::duration, true);
  out.est_rms = mean_finite(out.runs, &RunSummary::est_rms);
  out.nees = mean_finite(out.runs, &RunSummary::nees);
  out.frames_lost_fraction = frames ? static_cast<double>(lost) / static_cast<double>(frames) : NAN;
  return out;
}

std::string csv_header() {
  std::string h =
      "rate[Hz],latency[s],latency_jitter[s],controller,runs,successes,success_rate,ci95_lo,"
      "ci95_hi";
  for (const char* c : kFailureColumns) h += std::string(",") + c;
  return h +
         ",fn_min_ratio_mean,fn_min_ratio_min,duration_mean[s],est_err_rms,nees_mean,"
         "frames_lost_fraction,wall[s],cpu[s]\n";
}

std::string csv_row(const CellResult& c, int n) {
  int fails[5] = {};
  for (const auto& [cls, count] : c.failures) fails[failure_column(cls)] += count;
  std::string s = format_number(c.cell.fps);
  for (double v : {c.cell.latency, c.cell.jitter}) {
    s += ',';
    s += format_number(v);
  }
  s += "," + c.cell.controller + "," + std::to_string(n) + "," + std::to_string(c.successes);
  for (double v : {static_cast<double>(c.successes) / n, c.ci.lo, c.ci.hi}) {
    s += ',';
    s += format_number(v);
  }
  for (int f : fails) s += "," + std::to_string(f);
  for (double v : {c.fn_min_mean, c.fn_min_min, c.duration_mean, c.est_rms, c.nees,
                   c.frames_lost_fraction, c.wall, c.cpu}) {
    s += ',';
    s += format_number(v);
  }
  return s + "\n";
}

Json cell_json(const CellResult& c, int n) {
  Json j;
  j["rate_hz"] = c.cell.fps;
  j["latency_s"] = c.cell.latency;
  j["latency_jitter_s"] = c.cell.jitter;
  j["controller"] = c.cell.controller;
  j["runs"] = n;
  j["successes"] = c.successes;
  j["success_rate"] = static_cast<double>(c.successes) / n;
  j["ci95"] = Json::array({c.ci.lo, c.ci.hi});
  Json f = Json::object();
  for (const auto& [cls, count] : c.failures) f[cls] = count;
  j["failures"] = f;
  j["fn_min_ratio_mean"] = number(c.fn_min_mean);
  j["fn_min_ratio_min"] = number(c.fn_min_min);
  j["duration_mean_s"] = number(c.duration_mean);
  j["est_err_rms"] = number(c.est_rms);
  j["nees_mean"] = number(c.nees);
  j["frames_lost_fraction"] = number(c.frames_lost_fraction);
  j["wall_s"] = c.wall;
  j["cpu_s"] = c.cpu;
  return j;
}

/// 2 x 2 panels against latency (ms), one curve per camera rate (feedback), the open-loop
/// baseline as one black square: success rate with its Wilson interval, the smallest normal force
/// (mean and worst over the successes), the estimator's RMS error in the servo stage, and the CPU
/// time per experiment.
std::string plot_body(const std::vector<double>& rates, double max_latency, int n) {
  const char* colors[] = {"#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02"};
  // `scale` multiplies the column (e.g. "100 * " for percent); `bars` adds the Wilson interval.
  // `col2`: a second column drawn dashed with open points, in the same colours.
  const auto panel = [&](const std::string& title, const std::string& ylabel, int col,
                         const std::string& scale, bool bars, int col2 = 0) {
    const std::string c = std::to_string(col);
    std::string p = "set title '" + title + "'\nset ylabel '" + ylabel + "'\nplot ";
    for (std::size_t i = 0; col2 && i < rates.size(); ++i) {
      const std::string r = format_number(rates[i]);
      const std::string off = format_number(
          1.5 * (static_cast<double>(i) - 0.5 * static_cast<double>(rates.size() - 1)));
      p += "datafile skip 1 using (fx(" + r + ", " + off + ")):(" + scale + "fb(" + r + ", " +
           std::to_string(col2) + ")) with linespoints lw 1 dt 2 pt 6 lc rgb '" + colors[i % 6] +
           "' notitle, \\\n     ";
    }
    for (std::size_t i = 0; i < rates.size(); ++i) {
      const std::string r = format_number(rates[i]);
      // Neighbouring rates are drawn 1.5 ms apart so that their error bars do not overlap.
      const std::string off = format_number(
          1.5 * (static_cast<double>(i) - 0.5 * static_cast<double>(rates.size() - 1)));
      p += std::string(i ? ", \\\n     " : "") + "datafile skip 1 using (fx(" + r + ", " + off +
           ")):(" + scale + "fb(" + r + ", " + c + "))" +
           (bars ? ":(100 * fb(" + r + ", 8)):(100 * fb(" + r + ", 9)) with yerrorlines"
                 : std::string(" with linespoints")) +
           " lw 2 pt 7 lc rgb '" + colors[i % 6] + "' title '" + r + " Hz'";
    }
    p += ", \\\n     datafile skip 1 using (ox(0)):(" + scale + "ol(" + c + "))" +
         (bars ? std::string(":(100 * ol(8)):(100 * ol(9)) with yerrorbars") : " with points") +
         " pt 5 ps 1.5 lc rgb 'black' title 'open loop'\n";
    return p;
  };
  return "set datafile missing 'nan'\n"
         "set grid\nset key bottom left box opaque\nset xlabel 'camera latency (ms)'\n"
         "set xrange [-10:" +
         format_number(std::ceil(1000 * max_latency / 10) * 10 + 10) +
         "]\n"
         "# fb(r, col): column col of the feedback row at rate r; ol(col): of the open-loop row\n"
         "fb(r, col) = (column(1) == r && strcol(4) eq 'feedback') ? column(col) : NaN\n"
         "fx(r, off) = (column(1) == r && strcol(4) eq 'feedback') ? 1000 * column(2) + off : "
         "NaN\n"
         "ol(col) = strcol(4) eq 'open-loop' ? column(col) : NaN\n"
         "ox(off) = strcol(4) eq 'open-loop' ? 1000 * column(2) + off : NaN\n"
         "set multiplot layout 2,2 title 'Closed loop against camera rate and latency (" +
         std::to_string(n) + " perturbed worlds per point)'\n" + "set yrange [0:105]\n" +
         panel("success (Wilson 95 % interval)", "success (%)", 7, "100 * ", true) +
         "set autoscale y\nunset key\n" +
         panel("smallest normal force of the successes: mean, and worst (dashed)",
               "f_n min / (m g sin tilt)", 15, "", false, 16) +
         "set logscale y\n" +
         panel("estimate error in the servo stage", "RMS error of s_h", 18, "", false) +
         panel("cost per experiment", "CPU s per experiment (process, all threads)", 22,
               "1.0 / " + std::to_string(n) + " * ", false) +
         "unset multiplot\n";
}

/// Sorted, with `extra` added unless it is already there (to 1e-9).
std::vector<double> with_value(std::vector<double> v, double extra) {
  if (std::none_of(v.begin(), v.end(), [&](double x) { return std::abs(x - extra) < 1e-9; }))
    v.push_back(extra);
  std::sort(v.begin(), v.end());
  return v;
}

std::string default_closed_loop_scene() {
  return (fs::path(default_scene_path()).parent_path() / "airtable-feedback.yaml").string();
}

std::string percent(double f) { return std::to_string(std::lround(100 * f)); }

}  // namespace

void run_closed_loop_study(const StudyOptions& o) {
  // ---- bad input first: nothing is run or written before these checks pass
  CommonOptions common;
  common.scene = o.scene.empty() ? default_closed_loop_scene() : o.scene;
  const Scene scene = load_scene_with_overrides(common);
  if (!scene.camera)
    throw UsageError(scene.origin +
                     ": camera: the scene has no camera section (needed by the closed loop)");
  if (scene.sim.motion.kind != sim::MotionSpec::Kind::kButterfly)
    throw UsageError(scene.origin +
                     ": motion: study closed-loop needs the butterfly (motion.type: butterfly)");
  const drivers::Perturbations defaults;
  drivers::perturb(scene, defaults, kSeed, 0);  // std::invalid_argument for what it refuses
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();

  // ---- the grid; the scene's own rate and latency are always in it (the nominal cell)
  const double fps0 = scene.camera->fps, latency0 = scene.camera->latency;
  const std::vector<double> rates =
      with_value(o.quick ? std::vector<double>{15} : std::vector<double>{15, 30, 60, 120}, fps0);
  const std::vector<double> latencies =
      with_value(o.quick ? std::vector<double>{kAbsurdLatency}
                         : std::vector<double>{0, 0.033, 0.067, 0.1, 0.15, 0.2},
                 latency0);
  // Each cell keeps the Monte Carlo study's latency spread where it can (it must not exceed the
  // latency: a frame cannot arrive before it is taken).
  const auto jitter = [&](double latency) { return std::min(defaults.latency_jitter, latency); };
  std::vector<Cell> cells;
  for (double r : rates)
    for (double l : latencies) cells.push_back({r, l, jitter(l), "feedback"});
  // The open loop does not use the camera to steer, so one baseline (at the scene's camera) says
  // what feedback adds.
  cells.push_back({fps0, latency0, jitter(latency0), "open-loop"});
  // Every cell's loop set-up is built now, so that a scene the loop cannot run is bad input
  // (exit 2) rather than a failure half-way through.
  for (const Cell& c : cells) drivers::LoopSetup check(model::compile(cell_scene(scene, c)));

  const int n = o.quick ? kRunsQuick : kRunsFull;
  const unsigned threads = std::max(1u, std::thread::hardware_concurrency());
  const long total = static_cast<long>(cells.size()) * n;
  std::cerr << "flatland: study closed-loop: " << cells.size() << " cells (" << rates.size()
            << " rates x " << latencies.size() << " latencies, feedback; open-loop baseline) x "
            << n << " worlds (seed " << kSeed << ") on " << threads << " threads, " << scene.origin
            << "\n";

  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = cpu_now();
  std::vector<CellResult> results;
  {
    ProgressBar bar("study closed-loop");
    long done = 0;
    for (const Cell& c : cells)
      results.push_back(run_cell(scene, c, n, threads, [&] { bar.update(++done, total); }));
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double cpu_seconds = cpu_now() - cpu0;

  Json j;
  j["study"] = "closed-loop";
  j["scene"] = scene.origin;
  j["seed"] = kSeed;
  j["runs_per_cell"] = n;
  j["quick"] = o.quick;
  j["rates_hz"] = rates;
  j["latencies_s"] = latencies;
  j["nominal"] = {{"rate_hz", fps0}, {"latency_s", latency0}};
  j["perturbations"] = {{"s_h", defaults.s_h},
                        {"tilt_deg", defaults.tilt_deg},
                        {"radius_rel", defaults.radius_rel},
                        {"friction_rel", defaults.friction_rel},
                        {"noise_dn", defaults.noise_dn},
                        {"drop", defaults.drop},
                        {"latency_jitter", defaults.latency_jitter}};
  Json rows = Json::array();
  for (const CellResult& c : results) rows.push_back(cell_json(c, n));
  j["rows"] = rows;
  j["threads"] = threads;
  j["seconds"] = seconds;
  j["cpu_seconds"] = cpu_seconds;

  OutputSet outputs(o.force);
  std::vector<std::string> written;
  if (!dir.empty()) {
    outputs.begin_directory(dir);
    std::string csv = csv_header();
    for (const CellResult& c : results) csv += csv_row(c, n);
    outputs.stage(dir / "closed_loop.csv", csv);
    if (plots)
      run_plot(outputs, dir,
               {"closed_loop.gp", "closed_loop.csv", "closed_loop.png",
                plot_body(rates, latencies.back(), n)});
    outputs.stage(dir / "closed_loop.json", j.dump(2) + "\n");
    outputs.commit();
    written = outputs.paths();
  }
  if (o.json) {
    j["files"] = written;
    emit_json(j);
    return;
  }
  std::ostringstream os;
  os << "flatland study closed-loop: " << scene.origin << ", " << n << " worlds per cell (seed "
     << kSeed << "), " << format_number(std::round(seconds)) << " s\n";
  for (const CellResult& c : results) {
    char line[160];
    std::snprintf(line, sizeof line, "  %5g Hz %5.0f ms  %-9s %3d/%d  (95 %%: %3s..%3s %%)",
                  c.cell.fps, 1000 * c.cell.latency, c.cell.controller.c_str(), c.successes, n,
                  percent(c.ci.lo).c_str(), percent(c.ci.hi).c_str());
    os << line << "  fn_min " << format_number(std::round(c.fn_min_mean * 1000) / 1000);
    for (const auto& [cls, count] : c.failures) os << "; " << cls << " " << count;
    os << "\n";
  }
  for (const std::string& p : written) os << "  wrote " << p << "\n";
  std::cout << os.str();
}

}  // namespace flatland::app
