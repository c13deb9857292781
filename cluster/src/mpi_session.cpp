#include "flatland/cluster/mpi_session.hpp"

#include <mpi.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <stdexcept>

namespace flatland::cluster {

namespace {

constexpr int kHostChars = 256;

}  // namespace

MpiSession::MpiSession(int& argc, char**& argv) {
  int provided = 0;
  if (MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided) != MPI_SUCCESS)
    throw std::runtime_error("MPI could not start (MPI_Init_thread)");
  if (provided < MPI_THREAD_FUNNELED) {
    MPI_Finalize();
    throw std::runtime_error(
        "this MPI library gives no thread support (MPI_THREAD_FUNNELED is needed: a rank's "
        "worker threads run beside the thread that talks to MPI)");
  }
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
  // Where each rank runs: rank 0 can then tell, when the launcher stops the job, which rank on
  // its own host is gone.
  char host[kHostChars] = {};
  ::gethostname(host, sizeof host - 1);
  std::vector<char> hosts(static_cast<std::size_t>(size_) * kHostChars);
  long pid = static_cast<long>(::getpid());
  std::vector<long> pids(static_cast<std::size_t>(size_));
  MPI_Allgather(host, kHostChars, MPI_CHAR, hosts.data(), kHostChars, MPI_CHAR, MPI_COMM_WORLD);
  MPI_Allgather(&pid, 1, MPI_LONG, pids.data(), 1, MPI_LONG, MPI_COMM_WORLD);
  for (int r = 0; r < size_; ++r)
    places_.push_back({std::string(hosts.data() + static_cast<std::size_t>(r) * kHostChars),
                       pids[static_cast<std::size_t>(r)]});
}

MpiSession::~MpiSession() {
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

std::vector<int> MpiSession::gone_ranks_on_this_host() const {
  std::vector<int> gone;
  const std::string& here = places_[static_cast<std::size_t>(rank_)].host;
  for (int r = 0; r < size_; ++r) {
    const Place& p = places_[static_cast<std::size_t>(r)];
    if (r == rank_ || p.host != here) continue;
    if (::kill(static_cast<pid_t>(p.pid), 0) != 0 && errno == ESRCH) gone.push_back(r);
  }
  return gone;
}

}  // namespace flatland::cluster
