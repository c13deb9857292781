// sim::parallel_for, the one parallel loop: every item once, results independent of the thread
// count, the first exception rethrown, progress one call at a time.
#include "flatland/sim/parallel.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

namespace {

using flatland::sim::parallel_for;

TEST(ParallelFor, EveryItemOnceWhateverTheThreadCount) {
  constexpr long n = 1000;
  std::vector<double> reference;
  for (unsigned threads : {1u, 2u, 3u, 8u, 0u, 5000u}) {
    std::vector<int> calls(n, 0);
    std::vector<double> out(n, 0.0);
    std::vector<long> finished;
    std::set<std::thread::id> ids;
    std::atomic<int> inside{0};
    bool overlapping_done = false;
    parallel_for(
        n, threads,
        [&](long i) {
          ++calls[i];  // each slot is written by one item only
          double x = 0;
          for (long k = 1; k <= 200 + i % 7; ++k) x += 1.0 / static_cast<double>(k * (i + 1));
          out[i] = x;
        },
        [&](long f) {
          if (inside.fetch_add(1) != 0) overlapping_done = true;
          finished.push_back(f);
          ids.insert(std::this_thread::get_id());
          inside.fetch_sub(1);
        });
    EXPECT_TRUE(std::all_of(calls.begin(), calls.end(), [](int c) { return c == 1; }))
        << threads << " threads";
    EXPECT_FALSE(overlapping_done) << threads << " threads";
    // `finished` counts 1..n, each once, in the order the calls were made.
    ASSERT_EQ(finished.size(), static_cast<std::size_t>(n));
    for (long k = 0; k < n; ++k) EXPECT_EQ(finished[static_cast<std::size_t>(k)], k + 1);
    if (threads == 1) {
      EXPECT_EQ(ids, std::set<std::thread::id>{std::this_thread::get_id()});
      reference = out;
    } else {
      EXPECT_EQ(out, reference) << threads << " threads";
    }
  }
}

TEST(ParallelFor, FirstExceptionIsRethrownAndStopsTheLoop) {
  for (unsigned threads : {1u, 4u}) {
    std::atomic<long> started{0};
    try {
      parallel_for(100000, threads, [&](long i) {
        ++started;
        if (i == 10) throw std::invalid_argument("item 10 is bad");
      });
      ADD_FAILURE() << "no exception";
    } catch (const std::invalid_argument& e) {
      EXPECT_STREQ(e.what(), "item 10 is bad");
    }
    // Items after the failure are not handed out (each thread finishes the one it holds).
    EXPECT_LT(started.load(), 100000) << threads << " threads";
    if (threads == 1) {
      EXPECT_EQ(started.load(), 11);
    }
  }
}

TEST(ParallelFor, NoItemsMeansNoCalls) {
  bool called = false;
  parallel_for(
      0, 4, [&](long) { called = true; }, [&](long) { called = true; });
  parallel_for(-3, 4, [&](long) { called = true; });
  EXPECT_FALSE(called);
}

}  // namespace
