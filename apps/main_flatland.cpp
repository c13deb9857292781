// flatland: command-line front end of the simulator (docs/CLI.md). Exit codes: 0 success,
// 2 bad input (nothing written), 1 runtime failure.
//
// This program links the simulator and the scene loader only. A command that needs the camera
// stack is run by flatland-camera, which this program becomes (execv: same process, arguments,
// standard streams and exit code), so that the simulator's commands do not pay the start-up of
// OpenCV, GStreamer, FFmpeg and Ceres (docs/BENCHMARKS.md, "Start-up").
#include "command_sets.hpp"
#include "common.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <string>

namespace {

/// Become the program at locate() (execv: same process, arguments, standard streams and exit
/// code). Returns only if that fails: the one-line error, `why` then what execv said and `fix`.
int become(std::filesystem::path (*locate)(), char** argv, const std::string& why,
           const std::string& fix) {
  std::string program;
  try {
    program = locate().string();
  } catch (const std::exception& e) {
    return flatland::app::fail(1, e.what());
  }
  ::execv(program.c_str(), argv);
  return flatland::app::fail(
      1, why + " could not be started (" + program + ": " + std::strerror(errno) + "); " + fix);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace flatland::app;
  // Started by mpirun or srun: every command runs in flatland-mpi, which refuses the ones that
  // are not sweeps. Without a launcher nothing here loads MPI.
  if (launched_by_mpi())
    return become(mpi_program_path, argv, "started by an MPI launcher, but flatland-mpi",
                  "this flatland was built without MPI: apt-get install libopenmpi-dev and build "
                  "again (docs/CLUSTER.md)");
  if (argc > 1)
    for (const CommandInfo& c : command_table())
      if (c.camera_stack && std::strcmp(argv[1], c.name) == 0)
        return become(camera_program_path, argv,
                      std::string("the ") + c.name + " command is run by flatland-camera, which",
                      "build the flatland-camera target, or install flatland whole");
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  return run_cli(argc, argv, simulator_commands());
}
