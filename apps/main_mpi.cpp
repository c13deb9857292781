// flatland-mpi: the sweeps (montecarlo, study, surface, locus) on the ranks of an MPI job.
// `flatland` becomes this program when mpirun or srun started it (main_flatland.cpp). Every rank
// parses and checks the same command line; the sweep's runs are spread over the ranks
// (cluster::MpiSweep); rank 0 alone prints, shows progress and writes the outputs, which are the
// same bit for bit as one process's (docs/CLUSTER.md).
#include "command_sets.hpp"
#include "common.hpp"
#include "flatland/cluster/mpi_session.hpp"
#include "flatland/cluster/mpi_sweep.hpp"

#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>

namespace {

using namespace flatland;

/// The ranks other than 0 print nothing: rank 0 says everything once (its errors are theirs, as
/// all ranks check the same input), and the other ranks' failures reach it as messages.
void silence_this_rank() {
  if (!std::freopen("/dev/null", "w", stdout) || !std::freopen("/dev/null", "w", stderr))
    std::perror("flatland-mpi: /dev/null");
}

/// Open MPI binds each rank to one core when there are at most two ranks (to a socket beyond),
/// so a rank's second thread would share its first's core: say so, with the launch that fixes it.
void warn_if_bound_to_fewer_cores(unsigned threads) {
  const int cores = flatland::app::cores_available();
  if (cores >= static_cast<int>(threads)) return;
  std::fprintf(stderr,
               "flatland: warning: this rank may run on %d core%s but has --threads %u: launch "
               "with mpirun --map-by slot:PE=%u (or --bind-to none), or srun --cpus-per-task=%u\n",
               cores, cores == 1 ? "" : "s", threads, threads, threads);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace flatland::app;
  std::unique_ptr<cluster::MpiSession> session;
  try {
    session = std::make_unique<cluster::MpiSession>(argc, argv);
  } catch (const std::exception& e) {
    return fail(1, e.what());
  }
  if (session->rank() != 0) silence_this_rank();
  const std::string command = argc > 1 ? argv[1] : "";
  if (argc > 1 && command[0] != '-' && !is_sweep_command(command))
    return fail(2, "'" + command +
                       "' is not a sweep: run it without mpirun or srun (under MPI: montecarlo, "
                       "study, surface, locus)");

  // The locus is a continuation: each period's search starts from the previous period's k, and
  // started afresh it can land on another branch (measured: at 6 of 60 periods over 0.9-4 s a
  // fresh start finds k = -1.9 where the locus follows k = -1.10, and 7 more find none). It
  // cannot be split without changing its result, so rank 0 runs it whole and the other ranks
  // only check the same input.
  if (command == "locus" && session->rank() != 0) return 0;
  if (command == "locus" && session->size() > 1)
    std::fprintf(stderr,
                 "flatland: locus: a continuation (each period starts from the previous one's "
                 "solution), so rank 0 runs it alone while the other ranks (%d) wait\n",
                 session->size() - 1);

  // The engine the command makes, so that an interruption can say what it was doing.
  std::mutex engine_mutex;
  std::shared_ptr<const cluster::MpiSweep> engine;
  set_sweep_factory([&](unsigned threads, bool threads_given) {
    if (threads_given && threads == 0)
      throw UsageError(
          "--threads: 0 (one per core) is refused under MPI, where several ranks share a "
          "machine's cores; give the threads per rank (default 1)");
    if (threads == 0) threads = 1;
    warn_if_bound_to_fewer_cores(threads);
    auto made = std::make_shared<const cluster::MpiSweep>(*session, threads);
    std::lock_guard lock(engine_mutex);
    if (engine) throw std::logic_error("flatland-mpi: a command made a second sweep engine");
    engine = made;
    return std::shared_ptr<const sim::SweepEngine>(made);
  });
  // The launcher stops every rank with SIGTERM when one ends abnormally: rank 0 names it.
  set_interrupt_explanation([&](int) {
    std::lock_guard lock(engine_mutex);
    return engine ? engine->describe_stop() : std::string();
  });
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  std::map<std::string, AddCommand> commands = simulator_commands();
  commands.merge(camera_commands());
  const int code = run_cli(argc, argv, commands);
  bool swept = false;
  {
    std::lock_guard lock(engine_mutex);
    swept = engine && engine->started();
  }
  // A rank other than 0 that reached its sweep has ended there; one here failed before it, or
  // the command had nothing to sweep (--help).
  if (code != 0 && !swept) cluster::end_before_sweep(*session, code == 2, last_failure());
  return code;
}
