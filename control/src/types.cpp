#include "flatland/control/types.hpp"

namespace flatland::control {

std::string to_string(Stage s) {
  switch (s) {
    case Stage::kWaiting: return "waiting";
    case Stage::kDip: return "dip";
    case Stage::kServo: return "servo";
    case Stage::kFinish: return "finish";
    case Stage::kOpenLoop: return "open-loop";
    case Stage::kDone: return "done";
    case Stage::kSafeStop: return "safe-stop";
  }
  return "unknown";
}

}  // namespace flatland::control
