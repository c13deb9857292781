// flatland study render / tracker: the renderer's and the tracker's speed-accuracy trade.
#include "study.hpp"

namespace flatland::app {

void run_render_study(const StudyOptions&) {
  throw UsageError("study: 'render' is not implemented yet (available: sim, calibration)");
}

void run_tracker_study(const StudyOptions&) {
  throw UsageError("study: 'tracker' is not implemented yet (available: sim, calibration)");
}

}  // namespace flatland::app
