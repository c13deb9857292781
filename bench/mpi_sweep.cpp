// The work distribution's own cost (docs/BENCHMARKS.md, "Sweeps on MPI"): a sweep of items that
// each do `--work-us` of arithmetic, on cluster::MpiSweep (the ranks of this MPI job, `--threads`
// each) and, in rank 0's process before it, on sim::ThreadSweep with one thread and with as
// many threads as the job has workers (the peers in the same run). With --work-us 0 the difference
// per item is what handing out, packing, sending and gathering an item costs. Prints one JSON
// object on rank 0.
//
//   mpirun -np 2 build/bin/flatland_mpi_sweep_bench --items 200000 --work-us 0
#include "flatland/cluster/mpi_sweep.hpp"
#include "flatland/cluster/mpi_session.hpp"
#include "flatland/sim/parallel.hpp"

#include <mpi.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace flatland;

/// About `us` microseconds of arithmetic whose result depends on i (so it is not folded away).
double work(long i, double us) {
  double x = 1.0 + static_cast<double>(i % 97) * 1e-3;
  const long steps = static_cast<long>(us * 100);  // ~10 ns a step
  for (long k = 0; k < steps; ++k) x = std::sqrt(x + 1.0);
  return x;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  cluster::MpiSession session(argc, argv);
  long items = 200000;
  double work_us = 0;
  unsigned threads = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--items"))
      items = std::atol(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--work-us"))
      work_us = std::atof(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--threads"))
      threads = static_cast<unsigned>(std::atoi(argv[i + 1]));
    else {
      std::fprintf(stderr, "usage: mpi_sweep [--items N] [--work-us US] [--threads T]\n");
      return 2;
    }
  }
  std::vector<double> slots(static_cast<std::size_t>(items), 0.0);
  sim::ItemCodec codec;
  codec.pack = [&](long i, sim::ByteWriter& w) { w.put(slots[static_cast<std::size_t>(i)]); };
  codec.unpack = [&](long i, sim::ByteReader& r) { r.get(slots[static_cast<std::size_t>(i)]); };
  const auto body = [&](long i) { slots[static_cast<std::size_t>(i)] = work(i, work_us); };

  // The peers, in rank 0's process while the other ranks wait: one thread, and as many threads
  // as the job has workers (what the machine gives threads without MPI).
  const unsigned workers_n = static_cast<unsigned>(session.size()) * threads;
  double threads_s = 0, all_threads_s = 0;
  if (session.rank() == 0) {
    auto t0 = std::chrono::steady_clock::now();
    sim::ThreadSweep(1).run(items, body, codec);
    threads_s = seconds_since(t0);
    t0 = std::chrono::steady_clock::now();
    sim::ThreadSweep(workers_n).run(items, body, codec);
    all_threads_s = seconds_since(t0);
  }
  // The other ranks wait for the peers without taking a core (a blocking MPI call would spin).
  MPI_Request peers_done;
  MPI_Ibarrier(MPI_COMM_WORLD, &peers_done);
  for (int finished = 0; !finished;) {
    MPI_Test(&peers_done, &finished, MPI_STATUS_IGNORE);
    if (!finished) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const std::vector<double> reference = slots;
  std::fill(slots.begin(), slots.end(), 0.0);
  const cluster::MpiSweep mpi(session, threads);
  const auto t0 = std::chrono::steady_clock::now();
  mpi.run(items, body, codec);  // the other ranks end in here
  const double mpi_s = seconds_since(t0);
  const cluster::MpiSweep::Stats st = mpi.stats();
  const bool same = slots == reference;
  const double workers = static_cast<double>(workers_n);
  std::printf(
      "{\"ranks\": %d, \"threads\": %u, \"items\": %ld, \"work_us\": %g, \"same_results\": %s,\n"
      " \"one_thread_s\": %.6f, \"threads_only_s\": %.6f, \"mpi_s\": %.6f, \"mpi_over_threads\": "
      "%.4f,\n"
      " \"speedup\": %.3f, \"efficiency\": %.3f,\n"
      " \"chunks\": %ld, \"messages\": %ld, \"items_remote\": %ld, \"items_local\": %ld,\n"
      " \"coordinator_us_per_item\": %.4f, \"overhead_us_per_item\": %.4f}\n",
      session.size(), threads, items, work_us, same ? "true" : "false", threads_s, all_threads_s,
      mpi_s, mpi_s / all_threads_s, threads_s / mpi_s, threads_s / mpi_s / workers, st.chunks,
      st.messages, st.items_remote, st.items_local,
      1e6 * st.coordinator_seconds / static_cast<double>(items),
      1e6 * (mpi_s * workers - threads_s) / static_cast<double>(items));
  return same ? 0 : 1;
}
