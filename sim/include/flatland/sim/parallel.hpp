// The one parallel loop of flatland: independent items (grid points of a surface, Monte Carlo
// worlds, study runs) handed out to a pool of threads. Each item writes its own result slot, so
// the results do not depend on the number of threads.
#pragma once

#include <functional>

namespace flatland::sim {

/// Run body(i) for every i in [0, n) on `threads` threads: 0 means one per core; never more than
/// n; with one, everything runs on the calling thread. Items are handed out in index order as
/// threads come free. The first exception stops handing out items and is rethrown here once the
/// other threads have finished the items they hold. `done` (if set) is called after each item
/// with the number finished so far (1, 2, ... n, in that order), one call at a time; it may throw
/// to stop the work (a progress callback on Ctrl-C), like the body.
void parallel_for(long n, unsigned threads, const std::function<void(long i)>& body,
                  const std::function<void(long finished)>& done = {});

}  // namespace flatland::sim
