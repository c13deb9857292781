// Numbers in sim's error messages. Internal to sim/.
#pragma once

#include <sstream>
#include <string>

namespace flatland::sim::detail {

/// Six significant digits: enough to recognise a value a user wrote.
inline std::string fmt(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

}  // namespace flatland::sim::detail
