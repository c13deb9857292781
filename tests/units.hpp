// Constants several test files share: one degree in radians and the gravity of the simulator's
// and the scenes' defaults.
#pragma once

#include <numbers>

namespace flatland_test {

inline constexpr double kDeg = std::numbers::pi / 180.0;  ///< rad
inline constexpr double kG = 9.8;                         ///< m/s^2

}  // namespace flatland_test
