// sim::parallel_for, the one parallel loop: every item once, results independent of the thread
// count, the first exception rethrown, progress one call at a time.
#include "flatland/sim/parallel.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
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

namespace {

using flatland::sim::ByteReader;
using flatland::sim::ByteWriter;

TEST(ItemBytes, ValuesComeBackBitForBit) {
  // A NaN with a payload, -0, the extremes: what a result slot holds must survive the trip.
  double payload_nan = 0;
  const std::uint64_t bits = 0x7ff8000000abcdefULL;
  std::memcpy(&payload_nan, &bits, sizeof bits);
  const std::vector<double> doubles = {payload_nan,
                                       -0.0,
                                       std::numeric_limits<double>::infinity(),
                                       std::numeric_limits<double>::denorm_min(),
                                       1.0 / 3.0,
                                       -std::numeric_limits<double>::max()};
  const std::string text("a\0b\nc", 5);
  const std::optional<int> some = -7, none;
  std::string bytes;
  ByteWriter w(bytes);
  for (double d : doubles) w.put(d);
  w.put(text);
  w.put(some);
  w.put(none);
  w.put(std::int64_t{-1234567890123});

  ByteReader r(bytes);
  for (double d : doubles) {
    double back = 1;
    r.get(back);
    EXPECT_EQ(std::memcmp(&back, &d, sizeof d), 0);
  }
  std::string text_back;
  r.get(text_back);
  EXPECT_EQ(text_back, text);
  std::optional<int> some_back, none_back = 3;
  r.get(some_back);
  r.get(none_back);
  EXPECT_EQ(some_back, some);
  EXPECT_FALSE(none_back.has_value());
  std::int64_t big = 0;
  r.get(big);
  EXPECT_EQ(big, -1234567890123);
  EXPECT_TRUE(r.at_end());
}

TEST(ItemBytes, AShortSlotIsAnErrorNotGarbage) {
  std::string bytes;
  ByteWriter w(bytes);
  w.put(std::string(10, 'x'));
  bytes.resize(bytes.size() - 1);  // a slot cut short
  ByteReader r(bytes);
  std::string s;
  EXPECT_THROW(r.get(s), std::runtime_error);
  ByteReader empty("");
  double d = 0;
  EXPECT_THROW(empty.get(d), std::runtime_error);
}

TEST(ThreadSweep, IsParallelForWithItsThreadCount) {
  const flatland::sim::ThreadSweep two(2), all(0);
  EXPECT_EQ(two.threads(), 2u);
  EXPECT_GE(all.threads(), 1u);
  EXPECT_EQ(two.processes(), 1);
  std::vector<long> out(500, -1);
  std::vector<long> finished;
  two.run(
      500, [&](long i) { out[static_cast<std::size_t>(i)] = i * i; }, {},
      [&](long f) { finished.push_back(f); });
  for (long i = 0; i < 500; ++i) EXPECT_EQ(out[static_cast<std::size_t>(i)], i * i);
  ASSERT_EQ(finished.size(), 500u);
  for (long i = 0; i < 500; ++i) EXPECT_EQ(finished[static_cast<std::size_t>(i)], i + 1);
}

}  // namespace
