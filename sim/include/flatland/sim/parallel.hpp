// The one parallel loop of flatland: independent items (grid points of a surface, Monte Carlo
// worlds, study runs) handed out to a pool of threads, or to the ranks of an MPI job and their
// threads (a SweepEngine). Each item writes its own result slot, so the results do not depend on
// the number of threads or ranks.
#pragma once

#include "flatland/sim/item_bytes.hpp"

#include <functional>
#include <string>

namespace flatland::sim {

/// Run body(i) for every i in [0, n) on `threads` threads: 0 means one per core; never more than
/// n; with one, everything runs on the calling thread. Items are handed out in index order as
/// threads come free. The first exception stops handing out items and is rethrown here once the
/// other threads have finished the items they hold. `done` (if set) is called after each item
/// with the number finished so far (1, 2, ... n, in that order), one call at a time; it may throw
/// to stop the work (a progress callback on Ctrl-C), like the body.
void parallel_for(long n, unsigned threads, const std::function<void(long i)>& body,
                  const std::function<void(long finished)>& done = {});

/// One item's result slot as bytes, for an engine that runs items in other processes: `pack`
/// runs in the process that ran item i, `unpack` in the one that gathers the results. A slot
/// packed and unpacked must be equal to the original bit for bit (ByteWriter and ByteReader keep
/// doubles exact), so that outputs do not depend on where an item ran.
struct ItemCodec {
  std::function<void(long i, ByteWriter& out)> pack;
  std::function<void(long i, ByteReader& in)> unpack;
  /// Item i for a person ("run 12 (seed 1) under feedback"), for messages about a failure;
  /// empty: "item i".
  std::function<std::string(long i)> describe;
};

/// Where the items of a sweep run. Two engines: ThreadSweep (this process's threads, as
/// parallel_for) and cluster::MpiSweep (the ranks of an MPI job, each with its threads; only the
/// `flatland-mpi` program links it). Commands and studies take the engine instead of a thread
/// count, so that they run unchanged on either.
class SweepEngine {
 public:
  virtual ~SweepEngine() = default;
  /// As parallel_for: body(i) for every i in [0, n), `done` after each with the count finished
  /// so far, in order, one call at a time, the first exception rethrown. When it returns, every
  /// slot holds its item's result in the process that writes the outputs (rank 0); `codec`
  /// carries them there from other processes (ThreadSweep does not use it).
  virtual void run(long n, const std::function<void(long i)>& body, const ItemCodec& codec,
                   const std::function<void(long finished)>& done = {}) const = 0;
  /// Worker threads in each process (>= 1).
  virtual unsigned threads() const = 0;
  /// Processes that run items (1 for ThreadSweep; the ranks for MpiSweep).
  virtual int processes() const = 0;
};

/// This process's threads: parallel_for.
class ThreadSweep final : public SweepEngine {
 public:
  /// 0: one per core.
  explicit ThreadSweep(unsigned threads);
  void run(long n, const std::function<void(long i)>& body, const ItemCodec& codec,
           const std::function<void(long finished)>& done = {}) const override;
  unsigned threads() const override { return threads_; }
  int processes() const override { return 1; }

 private:
  unsigned threads_;
};

}  // namespace flatland::sim
