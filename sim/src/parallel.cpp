#include "flatland/sim/parallel.hpp"

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace flatland::sim {

void parallel_for(long n, unsigned threads, const std::function<void(long i)>& body,
                  const std::function<void(long finished)>& done) {
  if (n <= 0) return;
  std::atomic<long> next{0};
  long finished = 0;  // guarded by `mutex`
  std::atomic<bool> stop{false};
  std::mutex mutex;  // guards `error`, `finished` and the `done` callback
  std::exception_ptr error;
  const auto worker = [&] {
    while (!stop.load()) {
      const long i = next.fetch_add(1);
      if (i >= n) return;
      try {
        body(i);
        if (done) {
          std::lock_guard lock(mutex);
          done(++finished);  // under the lock, so the calls count up in order
        }
      } catch (...) {
        // From the body or from `done` (a progress callback that stops the work on Ctrl-C).
        std::lock_guard lock(mutex);
        if (!error) error = std::current_exception();
        stop = true;
        return;
      }
    }
  };
  unsigned count = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
  count = static_cast<unsigned>(std::min<long>(count, n));
  // The calling thread is one of the workers.
  std::vector<std::thread> pool;
  pool.reserve(count - 1);
  for (unsigned t = 1; t < count; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace flatland::sim

namespace flatland::sim {

ThreadSweep::ThreadSweep(unsigned threads)
    : threads_(threads ? threads : std::max(1u, std::thread::hardware_concurrency())) {}

void ThreadSweep::run(long n, const std::function<void(long i)>& body, const ItemCodec&,
                      const std::function<void(long finished)>& done) const {
  parallel_for(n, threads_, body, done);
}

}  // namespace flatland::sim
