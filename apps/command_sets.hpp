// Which program registers which commands: the simulator's (flatland), the camera stack's
// (flatland-camera), both (flatland-mpi). Inline, so that a program links only the command
// library whose set it names (apps/CMakeLists.txt).
#pragma once

#include "commands.hpp"

#include <map>
#include <string>

namespace flatland::app {

inline std::map<std::string, AddCommand> simulator_commands() {
  return {{"simulate", add_simulate_command},
          {"solve", add_solve_command},
          {"locus", add_locus_command},
          {"surface", add_surface_command},
          {"time-optimal", add_time_optimal_command},
          {"design", add_design_command}};
}

inline std::map<std::string, AddCommand> camera_commands() {
  return {{"render", add_render_command},
          {"render-calibration", add_render_calibration_command},
          {"calibrate", add_calibrate_command},
          {"track", add_track_command},
          {"experiment", add_experiment_command},
          {"montecarlo", add_montecarlo_command},
          {"identify", add_identify_command},
          {"study", add_study_command}};
}

}  // namespace flatland::app
