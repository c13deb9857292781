#include "flatland/cluster/mpi_sweep.hpp"

#include <mpi.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <map>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

namespace flatland::cluster {

namespace {

// Worker -> rank 0: the results of the chunk it ran (none on its first request), asking for more.
constexpr int kTagResults = 1;
// Worker -> rank 0: an item threw; the rank ends after sending it.
constexpr int kTagError = 2;
// Rank 0 -> worker: the next chunk [begin, end); begin == end: stop.
constexpr int kTagChunk = 3;
// How long rank 0's coordinator sleeps when no message waits: from the shortest, doubling while
// none comes, to the longest. Blocking receives would spin (Open MPI polls), taking a core from
// rank 0's own worker threads, and so would waking often: every wake-up takes the core from a
// worker for a moment (polling every 0.2 ms made a sweep of 57 us runs about 7 % slower than
// threads). A chunk is a share of the remaining runs, seconds of work in Monte Carlo, so a few
// milliseconds of latency before the next is nothing.
constexpr auto kPollShortest = std::chrono::microseconds(50);
constexpr auto kPollLongest = std::chrono::microseconds(1000);

enum class ErrorKind : char { kRuntime = 0, kInvalidArgument = 1 };

std::string describe_item(const sim::ItemCodec& codec, long i) {
  return codec.describe ? codec.describe(i) : "item " + std::to_string(i);
}

std::string describe_range(const sim::ItemCodec& codec, long begin, long end) {
  if (end - begin == 1) return describe_item(codec, begin);
  return describe_item(codec, begin) + " to " + describe_item(codec, end - 1);
}

/// A rank's error as bytes: the kind, then the message.
std::string error_message(ErrorKind kind, const std::string& what) {
  std::string bytes;
  sim::ByteWriter w(bytes);
  w.put(kind);
  w.put(what);
  return bytes;
}

/// The item that threw, and what: from a chunk run on this rank's threads.
struct ItemError {
  long item = -1;
  ErrorKind kind = ErrorKind::kRuntime;
  std::string what;
};

/// Run [begin, end) on `threads` threads; the first item that throws, if any.
ItemError run_chunk(long begin, long end, unsigned threads,
                    const std::function<void(long i)>& body) {
  ItemError failed;
  std::mutex mutex;
  try {
    sim::parallel_for(end - begin, threads, [&](long k) {
      try {
        body(begin + k);
      } catch (...) {
        std::lock_guard lock(mutex);
        if (failed.item < 0) {
          failed.item = begin + k;
          try {
            throw;
          } catch (const std::invalid_argument& e) {
            failed.kind = ErrorKind::kInvalidArgument;
            failed.what = e.what();
          } catch (const std::exception& e) {
            failed.what = e.what();
          } catch (...) {
            failed.what = "an exception that is not a std::exception";
          }
        }
        throw;
      }
    });
  } catch (...) {
    // Recorded above.
  }
  return failed;
}

[[noreturn]] void end_rank(int code) {
  MPI_Finalize();
  std::fflush(nullptr);
  std::_Exit(code);
}

/// A rank other than 0: ask for chunks, run them, send their slots back, until told to stop.
[[noreturn]] void serve(unsigned threads, const std::function<void(long i)>& body,
                        const sim::ItemCodec& codec) {
  std::string results;  // empty: the first request
  for (;;) {
    MPI_Send(results.data(), static_cast<int>(results.size()), MPI_BYTE, 0, kTagResults,
             MPI_COMM_WORLD);
    long chunk[2] = {0, 0};
    MPI_Recv(chunk, 2, MPI_LONG, 0, kTagChunk, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    if (chunk[0] >= chunk[1]) end_rank(0);
    const ItemError failed = run_chunk(chunk[0], chunk[1], threads, body);
    if (failed.item >= 0) {
      int rank = 0;
      MPI_Comm_rank(MPI_COMM_WORLD, &rank);
      const std::string bytes =
          error_message(failed.kind, "rank " + std::to_string(rank) + ", " +
                                         describe_item(codec, failed.item) + ": " + failed.what);
      MPI_Send(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, 0, kTagError,
               MPI_COMM_WORLD);
      end_rank(1);
    }
    results.clear();
    sim::ByteWriter w(results);
    w.put(chunk[0]);
    w.put(chunk[1]);
    std::string slot;
    for (long i = chunk[0]; i < chunk[1]; ++i) {
      slot.clear();
      sim::ByteWriter ws(slot);
      codec.pack(i, ws);
      w.put(slot);
    }
  }
}

}  // namespace

struct MpiSweep::State {
  mutable std::mutex mutex;  // guards everything below but `next`
  bool used = false;
  std::atomic<long> next{0};
  long n = 0, finished = 0;
  std::map<int, std::pair<long, long>> held;  // rank -> its unfinished chunk
  sim::ItemCodec codec;                       // for describe_stop
  Stats stats;
};

MpiSweep::MpiSweep(const MpiSession& session, unsigned threads)
    : session_(session), threads_(threads), state_(std::make_unique<State>()) {
  if (threads_ < 1) throw std::invalid_argument("MpiSweep: threads must be >= 1");
}

MpiSweep::~MpiSweep() = default;

int MpiSweep::processes() const { return session_.size(); }

bool MpiSweep::started() const {
  std::lock_guard lock(state_->mutex);
  return state_->used;
}

void end_before_sweep(const MpiSession& session, bool bad_input, const std::string& message) {
  if (session.rank() == 0) {
    const long stop[2] = {0, 0};
    for (int r = 1; r < session.size(); ++r)
      MPI_Send(stop, 2, MPI_LONG, r, kTagChunk, MPI_COMM_WORLD);
    return;
  }
  const std::string bytes =
      error_message(bad_input ? ErrorKind::kInvalidArgument : ErrorKind::kRuntime,
                    "rank " + std::to_string(session.rank()) + ": " + message);
  MPI_Send(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, 0, kTagError, MPI_COMM_WORLD);
}

MpiSweep::Stats MpiSweep::stats() const {
  std::lock_guard lock(state_->mutex);
  return state_->stats;
}

std::string MpiSweep::describe_stop() const {
  std::lock_guard lock(state_->mutex);
  std::string gone;
  for (int r : session_.gone_ranks_on_this_host())
    gone += (gone.empty() ? "rank " : ", rank ") + std::to_string(r) + " (pid " +
            std::to_string(session_.places()[static_cast<std::size_t>(r)].pid) + ")";
  std::string held;
  for (const auto& [rank, chunk] : state_->held)
    held += (held.empty() ? "" : "; ") + std::string("rank ") + std::to_string(rank) + " held " +
            describe_range(state_->codec, chunk.first, chunk.second);
  std::string s = gone.empty() ? "the MPI job was stopped by its launcher (a rank ended or the job "
                                 "was cancelled)"
                               : gone + " ended abnormally and the launcher stopped the job";
  s += " after " + std::to_string(state_->finished) + " of " + std::to_string(state_->n) + " runs";
  if (!held.empty()) s += "; unfinished: " + held;
  return s;
}

void MpiSweep::run(long n, const std::function<void(long i)>& body, const sim::ItemCodec& codec,
                   const std::function<void(long finished)>& done) const {
  State& st = *state_;
  {
    std::lock_guard lock(st.mutex);
    if (st.used)
      throw std::logic_error(
          "MpiSweep: one sweep per process (the other ranks ended with the first)");
    st.used = true;
    st.n = n;
    st.codec = codec;
  }
  const int size = session_.size();
  // Every rank checks this before any message, so all of them refuse alike.
  if (size > n)
    throw std::invalid_argument("mpirun -np " + std::to_string(size) + ": more ranks than the " +
                                std::to_string(n) + (n == 1 ? " run" : " runs") +
                                " of this sweep; use at most " + std::to_string(n) +
                                (n == 1 ? " rank" : " ranks"));
  if (session_.rank() != 0) serve(threads_, body, codec);

  // Rank 0: its threads take single items; its main thread hands out chunks to the other ranks
  // from the same counter and gathers their slots.
  std::exception_ptr error;
  std::string remote_error;
  ErrorKind remote_kind = ErrorKind::kRuntime;
  std::atomic<bool> stop{false};
  const auto finish_item = [&] {  // under st.mutex
    ++st.finished;
    if (done) done(st.finished);
  };
  const auto local = [&] {
    while (!stop.load()) {
      const long i = st.next.fetch_add(1);
      if (i >= n) return;
      try {
        body(i);
        std::lock_guard lock(st.mutex);
        ++st.stats.items_local;
        finish_item();
      } catch (...) {
        std::lock_guard lock(st.mutex);
        if (!error && remote_error.empty()) error = std::current_exception();
        stop = true;
        return;
      }
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < threads_; ++t) pool.emplace_back(local);

  const long workers = static_cast<long>(size) * threads_;
  int active = size - 1;  // ranks not yet told to stop
  std::vector<char> buffer;
  auto poll = kPollShortest;
  while (active > 0) {
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &status);
    if (!flag) {
      std::this_thread::sleep_for(poll);
      poll = std::min(poll * 2, kPollLongest);
      continue;
    }
    poll = kPollShortest;
    const auto busy0 = std::chrono::steady_clock::now();
    int count = 0;
    MPI_Get_count(&status, MPI_BYTE, &count);
    buffer.resize(static_cast<std::size_t>(std::max(count, 1)));
    MPI_Recv(buffer.data(), count, MPI_BYTE, status.MPI_SOURCE, status.MPI_TAG, MPI_COMM_WORLD,
             MPI_STATUS_IGNORE);
    const int source = status.MPI_SOURCE;
    std::lock_guard lock(st.mutex);
    ++st.stats.messages;
    st.held.erase(source);
    if (status.MPI_TAG == kTagError) {
      sim::ByteReader in(std::string_view(buffer.data(), static_cast<std::size_t>(count)));
      std::string what;
      ErrorKind kind{};
      in.get(kind);
      in.get(what);
      if (!error && remote_error.empty()) {
        remote_error = what;
        remote_kind = kind;
      }
      stop = true;
      --active;  // it has ended
      continue;
    }
    try {
      if (count > 0) {
        sim::ByteReader in(std::string_view(buffer.data(), static_cast<std::size_t>(count)));
        long begin = 0, end = 0;
        in.get(begin);
        in.get(end);
        std::string slot;
        for (long i = begin; i < end; ++i) {
          in.get(slot);
          sim::ByteReader slot_in(slot);
          codec.unpack(i, slot_in);
          if (!slot_in.at_end())
            throw std::logic_error("MpiSweep: " + describe_item(codec, i) +
                                   " was packed with more bytes than it was unpacked with");
          ++st.stats.items_remote;
          finish_item();
        }
      }
    } catch (...) {
      if (!error && remote_error.empty()) error = std::current_exception();
      stop = true;
    }
    long chunk[2] = {0, 0};
    if (!stop.load()) {
      // Guided: a share of what is left, smaller as the sweep ends, at least one item per thread.
      const long left = n - std::min(n, st.next.load());
      const long size_wanted = std::max<long>(threads_, left / (2 * workers));
      chunk[0] = std::min(n, st.next.fetch_add(size_wanted));
      chunk[1] = std::min(n, chunk[0] + size_wanted);
    }
    MPI_Send(chunk, 2, MPI_LONG, source, kTagChunk, MPI_COMM_WORLD);
    if (chunk[0] >= chunk[1]) {
      --active;
    } else {
      st.held[source] = {chunk[0], chunk[1]};
      ++st.stats.chunks;
    }
    st.stats.coordinator_seconds +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - busy0).count();
  }
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  if (!remote_error.empty()) {
    if (remote_kind == ErrorKind::kInvalidArgument) throw std::invalid_argument(remote_error);
    throw std::runtime_error(remote_error);
  }
}

}  // namespace flatland::cluster
