// flatland study: the command's side of the speed-accuracy studies (issue #6): the studies run in
// flatland::studies (studies/), and each file here (study_*.cpp, cmd_study.cpp) writes one's
// files, plots, JSON and text.
#pragma once

#include "common.hpp"

#include <string>
#include <vector>

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
  std::vector<std::string> controllers;  // closed-loop's controller axis; empty: feedback
};

void run_sim_study(const StudyOptions& o);
void run_calibration_study(const StudyOptions& o);
/// Centroid truth error and frames/s against supersampling and resolution (study_render.cpp).
void run_render_study(const StudyOptions& o);
/// Centre error and latency per tracking method against noise and blur (study_tracker.cpp).
void run_tracker_study(const StudyOptions& o);
/// Closed-loop success against camera rate and latency (study_closed_loop.cpp).
void run_closed_loop_study(const StudyOptions& o);

}  // namespace flatland::app
