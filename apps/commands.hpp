// The `flatland` commands: their names and descriptions in one table, and which program runs
// them. The simulator's commands run in `flatland` itself, which links the simulator and the
// scene loader only and so starts in milliseconds. The commands that need the camera stack
// (OpenCV with its video and image codecs, the GL loader, Ceres) run in `flatland-camera`, which
// `flatland` executes in its place (docs/DEVELOPING.md, "Two programs").
#pragma once

#include <CLI/CLI.hpp>

#include <filesystem>
#include <functional>
#include <map>
#include <span>
#include <string>
#include <vector>

namespace flatland::app {

struct CommandInfo {
  const char* name;
  bool camera_stack;  ///< run by flatland-camera
  const char* description;
};

/// Every command, in the order `flatland --help` lists them.
std::span<const CommandInfo> command_table();
/// The entry of `name`; std::logic_error if there is none.
const CommandInfo& command_info(const std::string& name);
/// The subcommand `name` of `app`, with its description from the table.
CLI::App* add_command(CLI::App& app, const std::string& name);

/// Registered command: its CLI11 subcommand and what to run when it was selected.
struct Command {
  CLI::App* app;
  std::function<void()> run;
};
using AddCommand = Command (*)(CLI::App&);

Command add_simulate_command(CLI::App& app);
Command add_solve_command(CLI::App& app);
Command add_locus_command(CLI::App& app);
Command add_surface_command(CLI::App& app);
Command add_time_optimal_command(CLI::App& app);
Command add_design_command(CLI::App& app);
Command add_render_command(CLI::App& app);
Command add_calibrate_command(CLI::App& app);
Command add_render_calibration_command(CLI::App& app);
Command add_track_command(CLI::App& app);
Command add_experiment_command(CLI::App& app);
Command add_montecarlo_command(CLI::App& app);
Command add_study_command(CLI::App& app);
Command add_identify_command(CLI::App& app);

/// The whole of main: parse, run the selected command, map exceptions to exit codes (0, 1, 2)
/// and one-line errors. Every table entry is registered, in table order, through its entry in
/// `commands`; an entry without one is listed in the help (so that `flatland --help` shows
/// every command) but is run by the other program.
int run_cli(int argc, char** argv, const std::map<std::string, AddCommand>& commands);

/// Print "flatland: error: MESSAGE" as one line on stderr (scripts grep it) and return `code`.
int fail(int code, const std::string& message);
/// The message of the last fail() (flatland-mpi sends a rank's to rank 0).
const std::string& last_failure();

/// flatland-camera, beside flatland in the installed layout (PREFIX/bin/flatland,
/// PREFIX/libexec/flatland/flatland-camera) and in the build tree (build/bin,
/// build/libexec/flatland).
std::filesystem::path camera_program_path();
/// flatland-mpi, beside flatland-camera (built when MPI was found).
std::filesystem::path mpi_program_path();

/// True if an MPI launcher started this process (Open MPI's mpirun; a PMIx or PMI-2 launcher
/// such as Slurm's srun --mpi=pmix): the environment it leaves. No MPI library needed.
bool launched_by_mpi();
/// The commands that are sweeps of independent runs, which flatland-mpi spreads over the ranks.
bool is_sweep_command(const std::string& name);

}  // namespace flatland::app
