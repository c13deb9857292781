// Numbers as text (format.hpp).
#include "flatland/sim/format.hpp"

#include <charconv>
#include <cmath>
#include <sstream>

namespace flatland::sim {

std::string format_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

std::string format_significant(double v, int digits) {
  std::ostringstream os;
  os.precision(digits);
  os << v;
  return os.str();
}

}  // namespace flatland::sim
