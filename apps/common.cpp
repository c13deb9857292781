#include "common.hpp"

#include "flatland/sim/hybrid.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <sstream>
#include <system_error>
#include <thread>

#include <fcntl.h>
#include <glob.h>
#include <sched.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <sys/wait.h>
#include <unistd.h>
#include <cerrno>
#include <cstring>

namespace flatland::app {

void add_common_options(CLI::App& cmd, CommonOptions& o, const std::string& out_help, bool plots) {
  cmd.add_option("--scene", o.scene,
                 "Scene file (YAML, SI units; schema in docs/SCENE.md). Default: the bundled "
                 "paper butterfly, " +
                     default_scene_path())
      ->type_name("FILE");
  cmd.add_flag("--json", o.json,
               "Print exactly one JSON object on stdout (lengths in m, times in s; inf/NaN as "
               "null); logs go to stderr. Default: off (human-readable summary)");
  cmd.add_option("--out", o.out, out_help)->type_name("PATH");
  add_force_option(cmd, o.force);
  if (plots)
    cmd.add_flag("--no-plot", o.no_plot,
                 "Write the CSV files but no gnuplot scripts or PNG plots (no gnuplot needed). "
                 "Default: off");
  const std::string group = "Integrator (defaults: the scene's simulator settings)";
  o.method_opt = cmd.add_option("--method", o.method,
                                "Integrator: dopri5 (adaptive Dormand-Prince 5(4)), dop853 "
                                "(adaptive Dormand-Prince 8(5,3), for tolerances below ~1e-8) or "
                                "rk4 (fixed step). Default: scene, else dopri5")
                     ->check(CLI::IsMember({"dopri5", "dop853", "rk4"}))
                     ->group(group);
  o.rtol_opt =
      cmd.add_option("--rtol", o.rtol,
                     "Relative tolerance of dopri5/dop853 (dimensionless, in [1e-14, 0.1]). "
                     "Default: scene, else 1e-10")
          ->group(group);
  o.atol_opt = cmd.add_option("--atol", o.atol,
                              "Absolute tolerance of dopri5/dop853 (in the state's units: m, rad, "
                              "s_h and their rates per s; in [1e-18, 1]). Default: scene, else "
                              "1e-12")
                   ->group(group);
  o.energy_tolerance_opt =
      cmd.add_option("--energy-tolerance", o.energy_tolerance,
                     "Relative bound of the run's energy balance (in [1e-12, 1]; a run beyond it "
                     "ends as numerical_failure). Default: scene, else 1000 x rtol (1e-6 for "
                     "rk4)")
          ->group(group);
  o.step_opt =
      cmd.add_option("--step", o.step, "Fixed step of rk4, s (> 0). Default: scene, else 0.001 s")
          ->group(group);
  o.formulation_opt =
      cmd.add_option("--formulation", o.formulation,
                     "Equations: auto (reduced for a disk), general (the paper's A x = b) or "
                     "reduced (disk only). Default: scene, else auto")
          ->check(CLI::IsMember({"auto", "general", "reduced"}))
          ->group(group);
}

api::IntegratorOverrides integrator_overrides(const CommonOptions& o) {
  api::IntegratorOverrides v;
  const auto given = [](const CLI::Option* opt) { return opt && opt->count() > 0; };
  if (given(o.method_opt)) v.method = o.method;
  if (given(o.rtol_opt)) v.rtol = o.rtol;
  if (given(o.atol_opt)) v.atol = o.atol;
  if (given(o.step_opt)) v.step = o.step;
  if (given(o.energy_tolerance_opt)) v.energy_tolerance = o.energy_tolerance;
  if (given(o.formulation_opt)) v.formulation = o.formulation;
  return v;
}

Scene load_scene_option(const CommonOptions& o, SceneSpaces spaces) {
  Scene scene = load_scene(o.scene.empty() ? default_scene_path() : o.scene);
  if (scene.spatial && spaces == SceneSpaces::kPlanar)
    throw UsageError("--scene: " + scene.origin +
                     " is a spatial scene (space: 3d); only `flatland simulate` runs those");
  return scene;
}

Scene load_scene_with_overrides(const CommonOptions& o) {
  Scene scene = load_scene_option(o);
  api::apply_integrator_overrides(integrator_overrides(o), scene, api::Spelling::kCommandLine);
  return scene;
}

void emit_json(const Json& j) {
  std::cout << j.dump(2) << '\n';
  std::cout.flush();
}

// ---- outputs: refusal, staging, interruption ---------------------------------------------------

namespace {

/// The gnuplot child an interruption stops (0: none).
std::mutex g_child_mutex;
pid_t g_child = 0;

int g_signal_pipe[2] = {-1, -1};

extern "C" void on_interrupt(int sig) {
  const int saved = errno;
  const unsigned char c = static_cast<unsigned char>(sig);
  [[maybe_unused]] const auto n = ::write(g_signal_pipe[1], &c, 1);
  errno = saved;
}

std::mutex g_explain_mutex;
std::function<std::string(int)> g_explain;  // set_interrupt_explanation

[[noreturn]] void interrupted(int sig) {
  const bool any = files::abandon_outputs([] {
    std::lock_guard lock(g_child_mutex);
    if (g_child > 0) ::kill(g_child, SIGTERM);
  });
  std::string why;
  {
    std::lock_guard lock(g_explain_mutex);
    if (g_explain) why = g_explain(sig);
  }
  std::fprintf(stderr, "\nflatland: error: interrupted by %s%s%s%s\n",
               sig == SIGINT ? "SIGINT" : "SIGTERM", why.empty() ? "" : ": ", why.c_str(),
               any ? "; partial outputs removed" : "; nothing written");
  std::fflush(stderr);
  ::_exit(128 + sig);
}

}  // namespace

void set_interrupt_explanation(std::function<std::string(int signal)> explain) {
  std::lock_guard lock(g_explain_mutex);
  g_explain = std::move(explain);
}

namespace {
SweepFactory g_sweep_factory;  // set once by flatland-mpi's main, before any thread
}  // namespace

void set_sweep_factory(SweepFactory factory) { g_sweep_factory = std::move(factory); }

std::shared_ptr<const sim::SweepEngine> make_sweep_engine(unsigned threads, bool threads_given) {
  if (g_sweep_factory) return g_sweep_factory(threads, threads_given);
  return std::make_shared<const sim::ThreadSweep>(threads);
}

int cores_available() {
  cpu_set_t set;
  CPU_ZERO(&set);
  return ::sched_getaffinity(0, sizeof set, &set) == 0 ? CPU_COUNT(&set) : 1;
}

void rasterise_on_workers(const sim::SweepEngine& engine) {
  if (std::getenv("LP_NUM_THREADS")) return;  // the user's choice
  if (engine.processes() > 1 || static_cast<int>(engine.threads()) >= cores_available())
    ::setenv("LP_NUM_THREADS", "0", 0);  // read by Mesa when it creates a context
}

bool sweeps_on_mpi() { return static_cast<bool>(g_sweep_factory); }

std::string where_it_runs(const sim::SweepEngine& engine) {
  const std::string threads =
      std::to_string(engine.threads()) + (engine.threads() == 1 ? " thread" : " threads");
  if (engine.processes() == 1) return threads;
  return std::to_string(engine.processes()) + " ranks x " + threads;
}

void install_interrupt_handler() {
  if (g_signal_pipe[0] >= 0) return;
  if (::pipe2(g_signal_pipe, O_CLOEXEC) != 0) return;  // no handler: the default (die) remains
  std::thread([] {
    unsigned char c = 0;
    for (;;) {
      const auto n = ::read(g_signal_pipe[0], &c, 1);
      if (n == 1) interrupted(c);
      if (n < 0 && errno == EINTR) continue;
      return;
    }
  }).detach();
  struct sigaction sa {};
  sa.sa_handler = on_interrupt;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
}

void add_force_option(CLI::App& cmd, bool& force) {
  cmd.add_flag("--force", force,
               "Replace existing outputs (an existing file, or a non-empty output directory, "
               "which is replaced as a whole). Default: off (refused, exit 2, nothing written)");
}

void check_output_file(const std::string& option, const fs::path& path, bool force) {
  std::error_code ec;
  const auto st = fs::symlink_status(path, ec);
  if (ec || !fs::exists(st)) return;
  if (fs::is_directory(fs::status(path, ec)))
    throw UsageError(option + ": " + path.string() + " is a directory; give a file name");
  if (!force)
    throw UsageError(option + ": " + path.string() + " already exists; pass --force to replace it");
}

void check_output_directory(const std::string& option, const fs::path& path, bool force) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return;
  if (!fs::is_directory(path, ec))
    throw UsageError(option + ": " + path.string() + " exists and is not a directory");
  if (!force && !fs::is_empty(path, ec))
    throw UsageError(option + ": " + path.string() +
                     " already exists and is not empty; pass --force to replace it, or choose "
                     "another directory");
}

// ---- ProgressBar ------------------------------------------------------------------------------

ProgressBar::ProgressBar(std::string label)
    : label_(std::move(label)),
      enabled_(::isatty(STDERR_FILENO) == 1 || sweeps_on_mpi()),
      lines_(::isatty(STDERR_FILENO) != 1) {}

ProgressBar::~ProgressBar() {
  if (drawn_) std::cerr << '\n' << std::flush;
}

void ProgressBar::update(long done, long total) {
  if (!enabled_ || total <= 0) return;
  std::lock_guard lock(mutex_);
  const int percent =
      static_cast<int>(100.0 * static_cast<double>(done) / static_cast<double>(total));
  if (percent == last_percent_) return;  // redraw only when something visible changes
  if (lines_) {
    if (percent / 10 == last_percent_ / 10 && last_percent_ >= 0) return;
    last_percent_ = percent;
    std::fprintf(stderr, "flatland: %s: %d%% (%ld/%ld)\n", label_.c_str(), percent / 10 * 10, done,
                 total);
    std::fflush(stderr);
    return;
  }
  last_percent_ = percent;
  constexpr int width = 40;
  const int filled = percent * width / 100;
  std::string bar(static_cast<std::size_t>(filled), '=');
  bar.resize(width, ' ');
  std::fprintf(stderr, "\r%s [%s] %3d%% (%ld/%ld)", label_.c_str(), bar.c_str(), percent, done,
               total);
  std::fflush(stderr);
  drawn_ = true;
}

// ---- gnuplot ----------------------------------------------------------------------------------

bool gnuplot_available() {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::stringstream ss(path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    if (dir.empty()) dir = ".";
    const fs::path p = fs::path(dir) / "gnuplot";
    if (::access(p.c_str(), X_OK) == 0 && !fs::is_directory(p)) return true;
  }
  return false;
}

void require_gnuplot() {
  if (!gnuplot_available())
    throw std::runtime_error(
        "gnuplot not found on PATH; install it (Debian: apt-get install gnuplot-nox) or pass "
        "--no-plot to skip the plots");
}

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string gnuplot_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("''") : std::string(1, c);
  return q + "'";
}

std::string gnuplot_terminal(int width, int height) {
  const std::string size = " size " + std::to_string(width) + "," + std::to_string(height);
  // pngcairo draws anti-aliased text and lines; plain png (libgd) is the fallback.
  return "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
         "  set terminal pngcairo noenhanced" +
         size +
         " font 'Sans,10'\n"
         "} else {\n"
         "  set terminal png noenhanced" +
         size +
         "\n"
         "}\n";
}

void run_plot(OutputSet& outputs, const fs::path& dir, const PlotJob& job) {
  std::string script = "# Generated by flatland. Re-run in this directory with: gnuplot " +
                       job.script_name + "\n" +
                       "if (!exists('datafile')) datafile = " + gnuplot_quote(job.data_name) +
                       "\n" + "if (!exists('outfile')) outfile = " + gnuplot_quote(job.png_name) +
                       "\n" + "set datafile separator comma\n" + gnuplot_terminal(1000, 700) +
                       "set output outfile\n" + job.body + "unset output\n";
  const fs::path script_tmp = outputs.stage(dir / job.script_name, script);
  const fs::path data_tmp = outputs.temp_path(dir / job.data_name);
  if (data_tmp.empty()) throw std::logic_error("run_plot: " + job.data_name + " is not staged");
  const fs::path png_tmp = outputs.reserve(dir / job.png_name);
  const std::string vars = "datafile=" + gnuplot_quote(data_tmp.filename().string()) +
                           "; outfile=" + gnuplot_quote(png_tmp.filename().string());
  // Run in the staging directory, which holds the script, the data and the PNG. Spawned rather
  // than std::system: system() ignores SIGINT while the child runs, and the interrupt watcher
  // must be able to stop gnuplot (it is registered as the child to kill).
  std::cout.flush();
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addchdir_np(&actions, script_tmp.parent_path().c_str());
  // gnuplot's own output goes to stderr: stdout is reserved for the result (--json).
  posix_spawn_file_actions_adddup2(&actions, STDERR_FILENO, STDOUT_FILENO);
  std::string a0 = "gnuplot", a1 = "-e", a3 = script_tmp.filename().string();
  std::string a2 = vars;
  char* argv[] = {a0.data(), a1.data(), a2.data(), a3.data(), nullptr};
  pid_t pid = 0;
  int status = -1;
  {
    std::lock_guard lock(g_child_mutex);
    if (::posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv, environ) == 0)
      g_child = pid;
    else
      pid = 0;
  }
  posix_spawn_file_actions_destroy(&actions);
  if (pid > 0) {
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    std::lock_guard lock(g_child_mutex);
    g_child = 0;
  }
  std::error_code ec;
  if (pid <= 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0 || !fs::exists(png_tmp, ec) ||
      fs::file_size(png_tmp, ec) == 0)
    throw std::runtime_error("gnuplot failed on " + (dir / job.script_name).string() +
                             (pid > 0 && WIFEXITED(status)
                                  ? " (exit status " + std::to_string(WEXITSTATUS(status)) + ")"
                                  : " (did not run or was killed)"));
}

// ---- reports ----------------------------------------------------------------------------------

void add_mu_option(CLI::App& cmd, MuOption& mu, const std::string& help) {
  mu.opt = cmd.add_option("--mu", mu.value, help);
}

void apply_mu_option(const MuOption& mu, sim::SimulationSpec& spec) {
  if (mu.opt && mu.opt->count()) api::apply_mu(mu.value, spec, api::Spelling::kCommandLine);
}

std::string solve_report_text(const sim::SolveReport& r) {
  std::ostringstream os;
  os << "  2T (period)        " << format_number(r.period) << " s\n"
     << "  k                  " << format_number(r.k) << "\n"
     << "  s_h(T)             " << format_number(r.s_T) << "\n"
     << "  s_h(2T), rate      " << format_number(r.s_end) << ", " << format_number(r.sdot_end)
     << " 1/s\n"
     << "  f_n at apex        " << format_number(r.fn_apex_ratio) << " m g sin(tilt)\n"
     << "  min f_n            " << format_number(r.fn_min_ratio) << " m g sin(tilt)"
     << (r.fn_min_ratio < 0 ? "  (contact lost: the hand would throw the disk)" : "") << "\n"
     << "  required mu        " << format_number(r.mu_required) << "\n";
  if (std::isfinite(r.friction_margin))
    os << "  friction margin    " << format_number(r.friction_margin)
       << " m g sin(tilt): min (mu f_n - |f_t|)"
       << (r.friction_margin < 0 ? ": the disk would slip" : "") << ")\n";
  os << "  simulations        " << r.simulations << " (" << r.rhs_evals << " rhs evaluations)\n";
  return os.str();
}

void write_solution_outputs(OutputSet& outputs, const fs::path& dir, const sim::RunResult& run,
                            bool no_plot) {
  if (run.trajectory.empty()) throw std::runtime_error("the solution run recorded no trajectory");
  outputs.begin_directory(dir);
  outputs.stage(dir / "trajectory.csv", samples_csv(run.trajectory.resample(1e-3)));
  if (no_plot) return;
  const std::string t = std::to_string(sample_column("t"));
  auto col = [](const char* name) { return std::to_string(sample_column(name)); };
  run_plot(outputs, dir,
           {"trajectory.gp", "trajectory.csv", "trajectory.png",
            "set multiplot layout 2,1 title 'Butterfly solution'\n"
            "set grid\n"
            "set xlabel 't (s)'\n"
            "set ylabel 'hand angle theta (rad)'\n"
            "plot datafile skip 1 using " +
                t + ":" + col("theta") +
                " with lines lw 2 title 'theta(t)'\n"
                "set ylabel 'hand contact parameter s_h'\n"
                "set yrange [-1.1:1.1]\n"
                "plot datafile skip 1 using " +
                t + ":" + col("s_h") +
                " with lines lw 2 title 's_h(t)'\n"
                "unset multiplot\n"});
  run_plot(outputs, dir,
           {"forces.gp", "trajectory.csv", "forces.png",
            "mu_clip = 2.0  # mu = |f_t|/f_n grows without bound as f_n -> 0\n"
            "set multiplot layout 2,1 title 'Contact forces'\n"
            "set grid\n"
            "set xlabel 't (s)'\n"
            "set ylabel 'force / (m g sin(tilt)), the in-plane weight'\n"
            "plot datafile skip 1 using " +
                t + ":" + col("fn_ratio") +
                " with lines lw 2 title 'normal f_n', \\\n"
                "     datafile skip 1 using " +
                t + ":" + col("ft_ratio") +
                " with lines lw 2 title 'tangential f_t', 0 with lines lc 'black' notitle\n"
                "set ylabel sprintf('required mu (clipped at %g)', mu_clip)\n"
                "set yrange [0:*]\n"
                "plot datafile skip 1 using " +
                t + ":(column(" + col("mu_required") + ") > mu_clip ? mu_clip : column(" +
                col("mu_required") +
                ")) with lines lw 2 title '|f_t|/f_n'\n"
                "unset multiplot\n"});
}

std::string default_experiment_scene() {
  return (fs::path(default_scene_path()).parent_path() / "airtable-feedback.yaml").string();
}

std::vector<std::string> expand_file_patterns(const std::vector<std::string>& patterns,
                                              const std::string& option) {
  std::vector<std::string> files;
  for (const std::string& p : patterns) {
    glob_t g{};
    const int rc = ::glob(p.c_str(), GLOB_TILDE | GLOB_BRACE, nullptr, &g);
    if (rc == 0)
      for (std::size_t i = 0; i < g.gl_pathc; ++i) files.emplace_back(g.gl_pathv[i]);
    ::globfree(&g);
    if (rc == GLOB_NOMATCH) throw UsageError(option + ": no file matches '" + p + "'");
    if (rc != 0) throw UsageError(option + ": cannot expand '" + p + "'");
  }
  std::sort(files.begin(), files.end());
  files.erase(std::unique(files.begin(), files.end()), files.end());
  return files;
}

}  // namespace flatland::app
