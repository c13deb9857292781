#include "flatland/studies/timing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <ctime>

namespace flatland::studies {

double cpu_now() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double quantile(std::vector<double>& v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(p * static_cast<double>(v.size())));
  return v[std::clamp<std::size_t>(rank, 1, v.size()) - 1];
}

double load_average_1min() {
  double load[1] = {0};
  return ::getloadavg(load, 1) == 1 ? load[0] : std::nan("");
}

}  // namespace flatland::studies
