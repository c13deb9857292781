// flatland: command-line front end of the simulator (docs/CLI.md). Exit codes: 0 success,
// 2 bad input (nothing written), 1 runtime failure.
#include "common.hpp"

#include <cstdio>
#include <iostream>
#include <string>

namespace {

// Errors are one line so that scripts can grep them.
int fail(int code, const std::string& message) {
  std::string line = message;
  for (char& c : line)
    if (c == '\n' || c == '\r') c = ' ';
  std::cout.flush();
  std::fprintf(stderr, "flatland: error: %s\n", line.c_str());
  return code;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace flatland::app;
  // Before any thread exists, so that every thread inherits the dispositions.
  install_interrupt_handler();
  CLI::App app{
      "flatland: a disk rolling on a one-joint robot hand (the butterfly of Lynch, Shiroma, Arai "
      "and Tanie). All inputs and outputs are SI: lengths in m, times in s, angles in rad, forces "
      "in N; force ratios are relative to the disk's in-plane weight m g sin(tilt) (its weight's "
      "component in the hand's plane; m g on the paper's vertical plane).",
      "flatland"};
  app.footer(
      "Every command reads a scene (--scene, default: the paper's butterfly); command-line "
      "values override the scene's.\nRun 'flatland <command> --help' for its options.\n"
      "Exit codes: 0 success; 2 bad input (scene or option; no files are written); 1 runtime "
      "failure (e.g. no solution bracketed, integrator failure).");
  app.require_subcommand(1);
  std::vector<Command> commands = {add_simulate_command(app),     add_solve_command(app),
                                   add_locus_command(app),        add_surface_command(app),
                                   add_time_optimal_command(app), add_render_command(app)};
  commands.push_back(add_render_calibration_command(app));
  commands.push_back(add_calibrate_command(app));
  commands.push_back(add_track_command(app));
  commands.push_back(add_experiment_command(app));
  commands.push_back(add_montecarlo_command(app));
  commands.push_back(add_study_command(app));
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::string names;
    for (const Command& c : commands) names += (names.empty() ? "" : ", ") + c.app->get_name();
    bool selected = false;
    for (const Command& c : commands) selected = selected || c.app->parsed();
    if (!selected && argc > 1 && argv[1][0] != '-')
      return fail(2, std::string("unknown command '") + argv[1] + "' (commands: " + names + ")");
    if (!selected)
      return fail(2, std::string(e.what()) + " (commands: " + names + "; see flatland --help)");
    return fail(2, e.what());
  }
  try {
    for (const Command& c : commands)
      if (c.app->parsed()) c.run();
    return 0;
  } catch (const std::invalid_argument& e) {  // SceneError, UsageError, sim's input checks
    return fail(2, e.what());
  } catch (const std::bad_alloc&) {
    // Every input is bounded, so this is the machine's memory, not an input's size.
    return fail(1, "out of memory: this run needs more memory than the machine could give "
                   "(lower the resolution, supersampling, grid or number of runs)");
  } catch (const std::exception& e) {  // std::runtime_error: numerical or I/O failure
    return fail(1, e.what());
  }
}
