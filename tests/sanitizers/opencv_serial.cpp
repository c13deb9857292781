// Linked into the sanitized build's programs only (CMakeLists.txt: FLATLAND_SANITIZE): OpenCV runs
// its parallel loops on the calling thread.
//
// Why: speed. Debian's OpenCV 4.6 runs cv::parallel_for_ on oneTBB, and under AddressSanitizer on
// CI's two cores, with ctest running two tests at once, its worker threads cost more than they
// save: the rendered-sequence tracker tests took 42-47 s each with them and 14-16 s without.
// flatland's code is the same either way (the loop bodies run, on the calling thread), and OpenCV's
// results do not depend on the number of threads; stage 1 (Release) runs OpenCV as users do.
#include <opencv2/core/utility.hpp>

namespace {

// Before main, so before any OpenCV call could start oneTBB's workers. 0: no threading at all.
[[maybe_unused]] const bool opencv_runs_serially = [] {
  cv::setNumThreads(0);
  return true;
}();

}  // namespace
