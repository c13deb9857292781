// Infinity, defined once for the simulator's sources.
#pragma once

#include <limits>

namespace flatland::sim {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

}  // namespace flatland::sim
