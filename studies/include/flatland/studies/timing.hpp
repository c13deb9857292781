// The studies' cost columns: process CPU seconds, the CPU per call of a short function repeated
// until enough has passed to be measured, quantiles of timings, the machine's load.
#pragma once

#include <vector>

namespace flatland::studies {

/// The p-quantile (0..1, nearest rank) of `v` (NaN when empty); sorts `v`.
double quantile(std::vector<double>& v, double p);

/// The 1-minute load average (NaN if unavailable): timings on a shared machine mean little
/// without it.
double load_average_1min();

/// Process CPU time (s), all threads.
double cpu_now();

/// CPU seconds per call of f, repeated until min_cpu has passed or 1000 calls (single runs at
/// loose tolerances take microseconds, below the clock's useful resolution).
template <class F>
double cpu_per_call(F&& f, double min_cpu) {
  const double start = cpu_now();
  long n = 0;
  do {
    f();
    ++n;
  } while (cpu_now() - start < min_cpu && n < 1000);
  return (cpu_now() - start) / static_cast<double>(n);
}

}  // namespace flatland::studies
