// flatland render-calibration: film a synthetic calibration session of a scene (board views for
// the intrinsics, boards lying on the table, the hand at known encoder angles) with the CSV files
// `flatland calibrate` reads and the true camera file, to test the calibration chain end to end.
#include "common.hpp"

#include "flatland/camera/camera_file.hpp"
#include "flatland/drivers/calibration_session.hpp"

#include <opencv2/imgcodecs.hpp>

#include <iostream>
#include <memory>
#include <sstream>

namespace flatland::app {

namespace {

struct RenderCalibrationOptions {
  std::string scene, out;
  std::string board;
  int intrinsics_views = 16, table_views = 4, joint_views = 8;
  long long seed = 1;
  bool force = false, json = false;
};

void run_render_calibration(const RenderCalibrationOptions& o) {
  if (o.out.empty()) throw UsageError("--out: required (a directory)");
  const auto check_count = [](const char* option, int n, int lo, int hi) {
    if (n < lo || n > hi)
      throw UsageError(std::string(option) + ": must be in [" + std::to_string(lo) + ", " +
                       std::to_string(hi) + "], got " + std::to_string(n));
  };
  check_count("--intrinsics-views", o.intrinsics_views, 3, 200);
  check_count("--table-views", o.table_views, 1, 50);
  check_count("--joint-views", o.joint_views, 3, 100);
  if (o.seed < 0) throw UsageError("--seed: must not be negative, got " + std::to_string(o.seed));
  CommonOptions common;
  common.scene = o.scene;
  const Scene scene = load_scene_with_overrides(common);
  if (!scene.camera)
    throw UsageError(scene.origin +
                     ": camera: missing (render-calibration films the scene's "
                     "camera; e.g. assets/scenes/butterfly-camera.yaml)");
  drivers::SessionOptions so;
  so.intrinsics_views = o.intrinsics_views;
  so.table_views = o.table_views;
  so.joint_views = o.joint_views;
  so.seed = static_cast<std::uint64_t>(o.seed);
  so.board = o.board;
  if (!so.board.empty()) camera::Board::parse(so.board);  // bad input before any work
  const fs::path out = o.out;
  check_output_directory("--out", out, o.force);

  OutputSet outputs(o.force);
  outputs.begin_directory(out);
  for (const char* sub : {"intrinsics", "table", "joint"}) outputs.ensure_directory(out / sub);
  const long total = so.intrinsics_views + so.table_views + so.joint_views;
  long done = 0;
  drivers::CalibrationSession session;
  {
    ProgressBar bar("render-calibration");
    std::vector<unsigned char> png;
    session = drivers::render_calibration_session(
        *model::compile(scene), so, [&](const std::string& path, const cv::Mat& image) {
          if (!cv::imencode(".png", image, png))
            throw std::runtime_error("cannot encode " + path + " as PNG");
          outputs.stage(out / path, std::string(png.begin(), png.end()));
          bar.update(++done, total);
        });
  }
  outputs.stage(out / "table.csv", calibration::table_csv(session.table));
  outputs.stage(out / "joint.csv", calibration::joint_csv(session.joint));
  camera::write_camera_file(outputs.reserve(out / "truth.yaml").string(), session.truth);
  const std::string board = session.board.notation();
  const std::string command =
      "flatland calibrate --images '" + (out / "intrinsics").string() + "/*.png' --board " + board +
      " --table " + (out / "table.csv").string() + " --joint " + (out / "joint.csv").string() +
      " --scene " + scene.origin + " --out camera.yaml";
  Json meta;
  meta["scene"] = scene.origin;
  meta["board"] = board;
  meta["seed"] = o.seed;
  meta["intrinsics_images"] = session.intrinsics_images.size();
  meta["table_images"] = session.table.size();
  meta["joint_images"] = session.joint.size();
  meta["truth"] = (out / "truth.yaml").string();
  meta["calibrate"] = command;
  outputs.stage(out / "session.json", meta.dump(2) + "\n");
  outputs.commit();

  if (o.json) {
    emit_json(meta);
    return;
  }
  std::ostringstream os;
  os << "flatland render-calibration: " << scene.origin << "\n"
     << "  board              " << board << "\n"
     << "  images             " << session.intrinsics_images.size() << " intrinsics, "
     << session.table.size() << " table, " << session.joint.size() << " joint\n"
     << "  wrote              " << out.string()
     << "/ (intrinsics/, table/, joint/, table.csv, joint.csv, truth.yaml, session.json)\n"
     << "  calibrate with     " << command << "\n";
  std::cout << os.str();
}

}  // namespace

Command add_render_calibration_command(CLI::App& app) {
  auto o = std::make_shared<RenderCalibrationOptions>();
  CLI::App* cmd = add_command(app, "render-calibration");
  cmd->add_option("--scene", o->scene,
                  "Scene file with a camera section. Default: the bundled paper butterfly, " +
                      default_scene_path())
      ->type_name("FILE");
  cmd->add_option("--out", o->out, "Directory to write")->required()->type_name("DIR");
  cmd->add_option("--board", o->board,
                  "The board (calibrate's --board notation; a chessboard whose inner-corner "
                  "counts add to an odd number, for the table views). Default: OpenCV's sample "
                  "chessboard, 9x6 inner corners, its square a fortieth of the view's width on "
                  "the table")
      ->type_name("SPEC");
  cmd->add_option("--intrinsics-views", o->intrinsics_views,
                  "Board views for the intrinsics, in [3, 200]. Default: 16");
  cmd->add_option("--table-views", o->table_views,
                  "Board placements on the table, in [1, 50]. Default: 4");
  cmd->add_option("--joint-views", o->joint_views,
                  "Hand images over a half turn, in [3, 100]. Default: 8");
  cmd->add_option("--seed", o->seed, "Seed of the poses, placements and noise, >= 0. Default: 1");
  add_force_option(*cmd, o->force);
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout (scene, board, seed, image counts, "
                "truth, calibrate: the command that calibrates from the session). Default: off");
  return {cmd, [o] { run_render_calibration(*o); }};
}

}  // namespace flatland::app
