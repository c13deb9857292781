// Linked into the sanitized build's programs only (CMakeLists.txt: FLATLAND_SANITIZE): OpenCV runs
// its parallel loops on the calling thread.
//
// Why: LeakSanitizer checks for leaks at process exit by stopping every thread with a ptrace-based
// tracer, and that tracer now and then crashes ("Tracer caught signal 11 ... LeakSanitizer has
// encountered a fatal error", google/sanitizers#1353) when other threads are alive, which fails a
// test that has passed. Debian's OpenCV 4.6 runs cv::parallel_for_ on oneTBB, whose worker threads
// live until after the leak check. (llvmpipe's threads, the other ones alive at exit, are turned
// off by LP_NUM_THREADS=0 in scripts/test.sh.) flatland's own code is the same either way: OpenCV's
// loop bodies run, serially, and their results do not depend on the number of threads.
#include <opencv2/core/utility.hpp>

namespace {

// Before main, so before any OpenCV call could start oneTBB's workers. 0: no threading at all.
[[maybe_unused]] const bool opencv_runs_serially = [] {
  cv::setNumThreads(0);
  return true;
}();

}  // namespace
