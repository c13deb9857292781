// One MPI job's process: MPI started on construction and finished on destruction, its rank and
// the job's size, and where every rank runs (host and process id), gathered once so that rank 0
// can say which rank ended when the launcher stops the job.
#pragma once

#include <string>
#include <vector>

namespace flatland::cluster {

class MpiSession {
 public:
  /// MPI_Init_thread with MPI_THREAD_FUNNELED (only the main thread calls MPI; the worker threads
  /// of a sweep do not). std::runtime_error if MPI cannot start or gives less than that.
  MpiSession(int& argc, char**& argv);
  ~MpiSession();
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;

  int rank() const { return rank_; }
  int size() const { return size_; }

  struct Place {
    std::string host;
    long pid = 0;
  };
  /// Every rank's host and process id, by rank.
  const std::vector<Place>& places() const { return places_; }
  /// Ranks that ran on this host and whose process is gone (checked now; other hosts unknown).
  std::vector<int> gone_ranks_on_this_host() const;

 private:
  int rank_ = 0, size_ = 1;
  std::vector<Place> places_;
};

}  // namespace flatland::cluster
