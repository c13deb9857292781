// flatland-camera: the `flatland` commands that need the camera stack (OpenCV, the GL loader,
// Ceres). `flatland` runs it in its place for these commands (main_flatland.cpp); it prints and
// exits exactly as `flatland` does.
#include "commands.hpp"
#include "common.hpp"

int main(int argc, char** argv) {
  using namespace flatland::app;
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  return run_cli(argc, argv,
                 {{"render", add_render_command},
                  {"render-calibration", add_render_calibration_command},
                  {"calibrate", add_calibrate_command},
                  {"track", add_track_command},
                  {"experiment", add_experiment_command},
                  {"montecarlo", add_montecarlo_command},
                  {"identify", add_identify_command},
                  {"study", add_study_command}});
}
