#include "commands.hpp"

#include "common.hpp"

#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <stdexcept>
#include <string>

namespace flatland::app {

namespace {

constexpr CommandInfo kCommands[] = {
    {"simulate", false,
     "Simulate the scene once (default: the paper's butterfly, 2T = 1.181 s, k = -1.1393) and "
     "report where the disk ends and the contact forces. Command-line values override the scene."},
    {"solve", false,
     "Find the butterfly solution for one duration 2T: the dip k (or, with --solve-for d, the "
     "hand shape parameter d) for which the disk is at the fingertip, s_h = 0, at t = T, so that "
     "it comes to rest on the back of the hand at t = 2T (paper section 4.3; 2T = 1.181 s gives "
     "k = -1.1393). Reports the contact forces of the solution."},
    {"locus", false,
     "Solve the butterfly for N durations 2T evenly spaced over [FROM, TO] (paper Fig. 7): k "
     "against 2T and the minimum normal force ratio of each solution."},
    {"surface", false,
     "Compute s_h at t = T for every (k, 2T) of a grid (paper Fig. 6); its zero level is the "
     "locus of butterfly solutions. Runs in parallel."},
    {"time-optimal", false,
     "Find the shortest duration 2T in [FROM, TO] whose butterfly solution keeps the normal "
     "force >= 0 throughout (paper section 4.3: 2T = 1.095 s, k = -1.1493) and, with a friction "
     "coefficient (--mu or the scene's contact.mu), needs no more friction than that (mu = 0.306 "
     "gives the paper's 1.181 s). The binding constraint must be violated at FROM and hold at "
     "TO."},
    {"design", false,
     "Design the hand's shape and the butterfly's motion together (docs/DESIGN.md): the "
     "polynomial hand's a, b, c, d and the dip k that need the least friction for one duration "
     "2T, keeping s_h(T) = 0 (the disk ends at rest on the back), a margin on the normal force, "
     "the outline a hand and its wells wider than the disk; exact sensitivities, NLopt's SLSQP. "
     "Prints the start (the paper's search, k alone), the best design and what binds there."},
    {"render", true,
     "Simulate the scene and film it with the scene's camera (its `camera` section): an MP4 "
     "video or PNG frames at the camera's frame rate from the start to the end of the run, with "
     "the ground truth of every frame (CSV: times in s, positions in m, image points in px) and "
     "the camera's intrinsics and pose (JSON)."},
    {"render-calibration", true,
     "Film a synthetic calibration session of the scene's camera: the board held at random "
     "poses (intrinsics/), lying on the table at spread places (table/ and table.csv), and the "
     "hand alone at encoder angles over a half turn (joint/ and joint.csv), with the scene's "
     "effects, plus the true camera file (truth.yaml). Feeds flatland calibrate "
     "(docs/CALIBRATION.md)."},
    {"calibrate", true,
     "Calibrate the camera chain and write one camera file (ROS camera_info YAML plus "
     "flatland's table pose and joint; docs/CALIBRATION.md): the intrinsics and OpenCV "
     "distortion from images of a board held at varied poses (--images, --board; Ceres, "
     "outlier views dropped), the table pose from images of the board lying on the table at "
     "known places (--table), the joint axis and encoder offset from images of the hand at "
     "known encoder angles (--joint). Give any of the three; a section this run does not "
     "calibrate comes from --camera FILE, which is updated in place unless --out is given."},
    {"track", true,
     "Track the disk in a video or an image sequence: per frame its centre (px, sub-pixel), the "
     "centre's 1-sigma uncertainty (px), a quality score (0..1), the track state (found, "
     "tracking, lost) and, with --encoder, the hand contact parameter s_h (CSV)."},
    {"experiment", true,
     "Run one closed-loop butterfly experiment (paper section 5): the 1 kHz vision-feedback (or "
     "open-loop) controller against a synthetic world, a recording or a live camera. Writes "
     "the 1 kHz log (CSV, SI units), the result (JSON) and the plots of theta(t) and s_h(t), "
     "planned vs actual (paper Fig. 10). Exit code 0 whenever the experiment ran, even if the "
     "disk did not reach the goal (see \"success\")."},
    {"montecarlo", true,
     "Robustness of the closed loop: N synthetic experiments per controller, each in a world "
     "perturbed from the scene (uniform draws seeded by --seed and the run number; the loop "
     "assumes the nominal scene). Prints the success counts with Wilson 95 % intervals."},
    {"identify", true,
     "Fit the world's parameters (friction, restitution, rolling resistance, drag, tilt, the "
     "hand's angle and time offsets) to recordings of the disk on the hand, with Ceres on the "
     "simulator (multiple shooting, weighted by the tracker's sigma): each value with its sigma "
     "or why the data do not determine it, the correlations and chi^2; writes the scene with "
     "the fitted values, the residuals and, with --validate, a held-out recording's prediction "
     "error (docs/IDENTIFY.md)."},
    {"study", true,
     "Speed-accuracy studies (docs/ACCURACY.md). 'sim': the simulator's work-precision diagram "
     "(RK4 at several steps, dopri5 and dop853 at rtol 1e-3 ... 1e-13, general and reduced "
     "formulations): error in s_h(T) and in the solved k against CPU time."},
};

}  // namespace

namespace {
std::string g_last_failure;  // fail()'s last message (main's thread only)
}  // namespace

const std::string& last_failure() { return g_last_failure; }

int fail(int code, const std::string& message) {
  std::string line = message;
  for (char& c : line)
    if (c == '\n' || c == '\r') c = ' ';
  g_last_failure = line;
  std::cout.flush();
  std::fprintf(stderr, "flatland: error: %s\n", line.c_str());
  return code;
}

std::span<const CommandInfo> command_table() { return kCommands; }

const CommandInfo& command_info(const std::string& name) {
  for (const CommandInfo& c : kCommands)
    if (name == c.name) return c;
  throw std::logic_error("no command '" + name + "' in the command table");
}

CLI::App* add_command(CLI::App& app, const std::string& name) {
  return app.add_subcommand(name, command_info(name).description);
}

fs::path camera_program_path() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec)
    throw std::runtime_error("cannot locate the flatland program (/proc/self/exe): " +
                             ec.message());
  return self.parent_path().parent_path() / "libexec" / "flatland" / "flatland-camera";
}

fs::path mpi_program_path() { return camera_program_path().parent_path() / "flatland-mpi"; }

bool launched_by_mpi() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMIX_RANK", "PMI_RANK"})
    if (const char* v = std::getenv(name); v && *v) return true;
  return false;
}

bool is_sweep_command(const std::string& name) {
  return name == "montecarlo" || name == "study" || name == "surface" || name == "locus";
}

int run_cli(int argc, char** argv, const std::map<std::string, AddCommand>& programs) {
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
  std::vector<Command> commands;
  for (const CommandInfo& info : kCommands) {
    const auto it = programs.find(info.name);
    if (it != programs.end()) {
      commands.push_back(it->second(app));
      continue;
    }
    // Listed so that the help names every command; the other program runs it (main_flatland.cpp
    // executes flatland-camera before parsing), so reaching it here is a wiring mistake.
    CLI::App* listed = add_command(app, info.name);
    listed->allow_extras();
    const std::string name = info.name;
    commands.push_back({listed, [name] {
                          throw std::logic_error(
                              "the " + name + " command is run by " +
                              (command_info(name).camera_stack ? "flatland-camera" : "flatland"));
                        }});
  }
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
    return fail(1,
                "out of memory: this run needs more memory than the machine could give "
                "(lower the resolution, supersampling, grid or number of runs)");
  } catch (const std::exception& e) {  // std::runtime_error: numerical or I/O failure
    return fail(1, e.what());
  }
}

}  // namespace flatland::app
