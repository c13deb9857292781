// flatland: command-line front end of the simulator (docs/CLI.md). Exit codes: 0 success,
// 2 bad input (nothing written), 1 runtime failure.
//
// This program links the simulator and the scene loader only. A command that needs the camera
// stack is run by flatland-camera, which this program becomes (execv: same process, arguments,
// standard streams and exit code), so that the simulator's commands do not pay the start-up of
// OpenCV, GStreamer, FFmpeg and Ceres (docs/BENCHMARKS.md, "Start-up").
#include "commands.hpp"
#include "common.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

int main(int argc, char** argv) {
  using namespace flatland::app;
  // Started by mpirun or srun: every command runs in flatland-mpi, which refuses the ones that
  // are not sweeps. Without a launcher nothing here loads MPI.
  if (launched_by_mpi()) {
    std::string program;
    try {
      program = mpi_program_path().string();
    } catch (const std::exception& e) {
      return fail(1, e.what());
    }
    ::execv(program.c_str(), argv);
    return fail(1, "started by an MPI launcher, but flatland-mpi could not be started (" + program +
                       ": " + std::strerror(errno) +
                       "); this flatland was built without MPI: apt-get install libopenmpi-dev "
                       "and build again (docs/CLUSTER.md)");
  }
  if (argc > 1) {
    for (const CommandInfo& c : command_table()) {
      if (!c.camera_stack || std::strcmp(argv[1], c.name) != 0) continue;
      std::string program;
      try {
        program = camera_program_path().string();
      } catch (const std::exception& e) {
        return fail(1, e.what());
      }
      ::execv(program.c_str(), argv);
      return fail(1, std::string("the ") + c.name + " command is run by flatland-camera, which " +
                         "could not be started (" + program + ": " + std::strerror(errno) +
                         "); build the flatland-camera target, or install flatland whole");
    }
  }
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  return run_cli(argc, argv,
                 {{"simulate", add_simulate_command},
                  {"solve", add_solve_command},
                  {"locus", add_locus_command},
                  {"surface", add_surface_command},
                  {"time-optimal", add_time_optimal_command}});
}
