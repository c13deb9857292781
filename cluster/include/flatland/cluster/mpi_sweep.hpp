// A sweep on the ranks of an MPI job (sim::SweepEngine): rank 0 hands out small chunks of items
// on demand, runs items on its own threads too, gathers every item's result slot (ItemCodec) and
// alone goes on to write the outputs. The other ranks run their chunks on their threads, send the
// slots back and, when the sweep is done, end (their part of the command is over).
#pragma once

#include "flatland/cluster/mpi_session.hpp"
#include "flatland/sim/parallel.hpp"

#include <functional>
#include <memory>
#include <string>

namespace flatland::cluster {

class MpiSweep final : public sim::SweepEngine {
 public:
  /// `threads` per rank (>= 1). The session must outlive the engine.
  MpiSweep(const MpiSession& session, unsigned threads);
  ~MpiSweep() override;

  /// sim::SweepEngine::run, with these differences. One sweep per process: a second call throws
  /// std::logic_error (the other ranks have ended). On a rank other than 0 it does not return: the
  /// rank serves chunks until rank 0 says stop, finishes MPI and exits (0, or 1 after reporting
  /// an item's exception to rank 0). std::invalid_argument on every rank if there are more ranks
  /// than items. An item's exception (on any rank) stops the sweep and is rethrown on rank 0,
  /// naming the rank and the item (codec.describe).
  void run(long n, const std::function<void(long i)>& body, const sim::ItemCodec& codec,
           const std::function<void(long finished)>& done = {}) const override;
  unsigned threads() const override { return threads_; }
  int processes() const override;

  /// What rank 0 knows of the sweep when the launcher stops the job (it sends SIGTERM to every
  /// rank when one ends abnormally): which ranks are gone, which held unfinished items. Safe to
  /// call from another thread.
  std::string describe_stop() const;

  /// True once run() was called in this process.
  bool started() const;

  /// Messages, chunks and items of the last sweep, and the µs rank 0's coordinator spent per
  /// item (the work distribution's own cost), for the benchmarks.
  struct Stats {
    long chunks = 0, messages = 0, items_remote = 0, items_local = 0;
    double coordinator_seconds = 0;
  };
  Stats stats() const;

 private:
  struct State;
  const MpiSession& session_;
  unsigned threads_;
  std::unique_ptr<State> state_;
};

/// A rank whose command ended before its sweep (bad input, a missing file on its machine): rank 0
/// tells the other ranks to stop (they would wait for chunks); another rank sends rank 0 its
/// error, which rank 0's sweep reports naming the rank (as std::invalid_argument if
/// `bad_input`). Ranks that failed alike have nothing to receive it: nothing waits.
void end_before_sweep(const MpiSession& session, bool bad_input, const std::string& message);

}  // namespace flatland::cluster
