// flatland study closed-loop: success of the vision-feedback loop against camera rate and latency.
#include "study.hpp"

namespace flatland::app {

void run_closed_loop_study(const StudyOptions&) {
  throw UsageError("study: 'closed-loop' is not implemented yet (available: sim, calibration)");
}

}  // namespace flatland::app
