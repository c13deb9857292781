// Helpers shared by the `flatland` commands: options every command takes, scene loading with
// command-line overrides, JSON and CSV output, staged (atomic) output files, progress bar, gnuplot.
#pragma once

#include "commands.hpp"
#include "flatland/api/reports.hpp"
#include "flatland/api/sim_operations.hpp"
#include "flatland/files/output_set.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/parallel.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include <array>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace flatland::app {

namespace fs = std::filesystem;

using api::UsageError;

/// Files named by shell patterns (glob(3) with ~ and {a,b}; a plain file name matches itself),
/// sorted and without duplicates. A pattern that matches nothing is a UsageError naming `option`.
std::vector<std::string> expand_file_patterns(const std::vector<std::string>& patterns,
                                              const std::string& option);

/// The closed loop's bundled scene (experiment's, montecarlo's and study closed-loop's default):
/// airtable-feedback.yaml beside default_scene_path().
std::string default_experiment_scene();

/// Options every command has; the integrator ones override the scene's `simulator` settings.
struct CommonOptions {
  std::string scene;  ///< empty: default_scene_path()
  bool json = false;
  std::string out;  ///< empty: no files
  bool no_plot = false;
  bool force = false;  ///< --force: replace an existing --out
  double rtol = 0, atol = 0, step = 0, energy_tolerance = 0;
  std::string method, formulation;
  // Set by add_common_options; count() tells whether the user gave the option.
  CLI::Option* energy_tolerance_opt = nullptr;
  CLI::Option* rtol_opt = nullptr;
  CLI::Option* atol_opt = nullptr;
  CLI::Option* step_opt = nullptr;
  CLI::Option* method_opt = nullptr;
  CLI::Option* formulation_opt = nullptr;
};

/// What `out_help` says about --out for this command.
void add_common_options(CLI::App& cmd, CommonOptions& o, const std::string& out_help, bool plots);

/// The scene --scene names (the bundled default without it); SceneError on bad input.
/// Which scenes a command runs: planar ones (every command but simulate) or spatial ones too.
enum class SceneSpaces { kPlanar, kPlanarOrSpatial };
/// The scene of --scene (or the default); a UsageError for a spatial scene (`space: 3d`) unless
/// the command runs them.
Scene load_scene_option(const CommonOptions& o, SceneSpaces spaces = SceneSpaces::kPlanar);
/// Load the scene (SceneError on bad input) and apply the integrator overrides.
Scene load_scene_with_overrides(const CommonOptions& o);

/// --mu: the static friction coefficient for this run (the scene's contact.mu).
struct MuOption {
  double value = 0;
  CLI::Option* opt = nullptr;
};
void add_mu_option(CLI::App& cmd, MuOption& mu, const std::string& help);
/// Set spec.contact.mu from --mu when given (UsageError for a negative value or one below the
/// scene's contact.mu_kinetic).
void apply_mu_option(const MuOption& mu, sim::SimulationSpec& spec);

using api::build_problem_checked;
using api::contact_events_json;
using api::contact_summary_json;
using api::flights_json;
using api::Json;
using api::number;
using api::require_finite;
using api::require_increasing;
using api::require_positive;
using api::s_at_half_period;
using api::solve_report_json;

/// The integrator options the user gave (--method, --rtol, --atol, --step, --formulation).
api::IntegratorOverrides integrator_overrides(const CommonOptions& o);

/// Print the one JSON object on stdout.
void emit_json(const Json& j);

// The trajectory CSV and its number format are sim's (sim/trajectory_csv.hpp).
using sim::format_number;
using sim::sample_column;
using sim::sample_columns;
using sim::samples_csv;

/// --force on `cmd`: replace existing outputs (each command's help names which).
void add_force_option(CLI::App& cmd, bool& force);

/// Refusal of existing outputs, checked with the other bad input before any work: a UsageError
/// naming `option` and the path if `path` exists (a file output) or is a non-empty directory (a
/// directory output), unless `force`. A path of the wrong kind (a directory where a file is
/// written, or the reverse) is refused even with --force: that is a mistake, not a re-run.
void check_output_file(const std::string& option, const fs::path& path, bool force);
void check_output_directory(const std::string& option, const fs::path& path, bool force);

using files::OutputSet;

/// SIGINT and SIGTERM: the handler only writes the signal number to a pipe (async-signal-safe);
/// a watcher thread reads it, kills a running gnuplot, removes every registered staging
/// directory and created parent (under the lock that commit() holds, so outputs are either all
/// in place or none), prints one line and exits 130 (SIGINT) or 143 (SIGTERM). Called once by
/// main before any thread starts.
void install_interrupt_handler();

/// Let the interruption's one line say what was interrupted (flatland-mpi: which rank ended).
/// `explain` runs on the interrupt watcher thread; it must be safe to call from there.
void set_interrupt_explanation(std::function<std::string(int signal)> explain);

/// Where a command's sweep of independent runs goes: this process's threads, or, in
/// flatland-mpi, the MPI job's ranks (set_sweep_factory). `threads_given`: the user gave
/// --threads (an MPI job refuses 0, "all cores", which its ranks would each take).
std::shared_ptr<const sim::SweepEngine> make_sweep_engine(unsigned threads, bool threads_given);
using SweepFactory =
    std::function<std::shared_ptr<const sim::SweepEngine>(unsigned threads, bool threads_given)>;
/// Called once by flatland-mpi's main before any command runs.
void set_sweep_factory(SweepFactory factory);
/// True in flatland-mpi (a sweep factory is set): the commands that are not sweeps refuse.
bool sweeps_on_mpi();
/// Before a sweep of rendered experiments (montecarlo, study closed-loop): when its workers fill
/// the cores this process may use (or the job has several ranks), tell llvmpipe to rasterise on
/// the calling thread (LP_NUM_THREADS=0) unless the user set it. Its own rasteriser threads
/// help one experiment use an idle core, but beside other workers they only contend: Monte
/// Carlo of 40 worlds on 2 threads took 17.0 s with them and 12.7 s without (2 ranks: 12.8 s).
void rasterise_on_workers(const sim::SweepEngine& engine);
/// The cores this process may run on (its affinity mask; 1 if the mask cannot be read).
int cores_available();

/// "2 threads", or "3 ranks x 2 threads" (for the command's first line on stderr).
std::string where_it_runs(const sim::SweepEngine& engine);

/// A progress bar on stderr, drawn only when stderr is a terminal. Under MPI (flatland-mpi) rank
/// 0's stderr is a pipe to the launcher, whatever the user's terminal: there it prints a line at
/// every tenth of the work instead (which a batch job's log keeps too). Safe to call from threads.
class ProgressBar {
 public:
  explicit ProgressBar(std::string label);
  ~ProgressBar();
  void update(long done, long total);
  /// The callback the sim searches take.
  sim::Progress callback() {
    return [this](long done, long total) { update(done, total); };
  }

 private:
  std::string label_;
  bool enabled_;
  bool lines_;  ///< a line per tenth (MPI) instead of a redrawn bar
  int last_percent_ = -1;
  bool drawn_ = false;
  std::mutex mutex_;
};

/// True if a `gnuplot` executable is on PATH.
bool gnuplot_available();
/// std::runtime_error (exit 1) naming the Debian package unless gnuplot is available. Called
/// before any work so that a missing plotter fails fast.
void require_gnuplot();

/// One gnuplot plot: a script kept next to the data (DIR/<name>.gp) that reads `data_name` and
/// writes `png_name`, both relative to DIR. The script's `datafile` and `outfile` variables can be
/// overridden with -e, which is how it is run on the staged temporaries.
struct PlotJob {
  std::string script_name;  ///< e.g. "locus.gp"
  std::string data_name;    ///< e.g. "locus.csv" (already staged in `outputs`)
  std::string png_name;     ///< e.g. "locus.png"
  std::string body;         ///< plot commands using `datafile` and `outfile`
};
/// Stage the script and the PNG, run gnuplot in `dir`; std::runtime_error if it fails.
void run_plot(OutputSet& outputs, const fs::path& dir, const PlotJob& job);
/// The terminal line shared by all plots: pngcairo if this gnuplot has it, else png.
std::string gnuplot_terminal(int width, int height);

/// Quote for /bin/sh.
std::string shell_quote(const std::string& s);
/// Quote for a gnuplot single-quoted string.
std::string gnuplot_quote(const std::string& s);

/// Human-readable lines for a solve report (stdout when not --json).
std::string solve_report_text(const sim::SolveReport& r);

/// Write DIR/trajectory.csv (every 1 ms) and, unless no_plot, DIR/trajectory.png and
/// DIR/forces.png for a solved motion.
void write_solution_outputs(OutputSet& outputs, const fs::path& dir, const sim::RunResult& run,
                            bool no_plot);

}  // namespace flatland::app
