// flatland study: shared pieces of the speed-accuracy studies (issue #6). Each study lives in its
// own file (study_*.cpp) and is dispatched from cmd_study.cpp.
#pragma once

#include "common.hpp"

#include <string>

namespace flatland::app {

struct StudyOptions {
  std::string name;
  std::string scene;
  std::string out;
  bool force = false;
  bool quick = false;
  bool json = false;
  bool no_plot = false;
  double min_cpu = 0.02;  // s: timing repeats until this much CPU time has been spent
};

/// Process CPU time (s).
double cpu_now();

// CPU seconds per call of f, repeated until min_cpu has passed (single runs at loose tolerances
// take microseconds, below the clock's useful resolution).
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

void run_sim_study(const StudyOptions& o);
void run_calibration_study(const StudyOptions& o);
/// Centroid truth error and frames/s against supersampling and resolution (study_render.cpp).
void run_render_study(const StudyOptions& o);
/// Centre error and latency per tracking method against noise and blur (study_tracker.cpp).
void run_tracker_study(const StudyOptions& o);
/// Closed-loop success against camera rate and latency (study_closed_loop.cpp).
void run_closed_loop_study(const StudyOptions& o);

}  // namespace flatland::app
