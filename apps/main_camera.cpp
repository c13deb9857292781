// flatland-camera: the `flatland` commands that need the camera stack (OpenCV, the GL loader,
// Ceres). `flatland` runs it in its place for these commands (main_flatland.cpp); it prints and
// exits exactly as `flatland` does.
#include "command_sets.hpp"
#include "common.hpp"

int main(int argc, char** argv) {
  using namespace flatland::app;
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  return run_cli(argc, argv, camera_commands());
}
