// Uses flatland as a library from its installed prefix: loads the bundled scenes from the
// installed data, solves the paper's butterfly (sim), projects the disk's start through the
// scene's camera, compiled into a Model, and runs the quick work-precision study (studies).
// Prints one JSON object; exit 1 on any error.
#include <flatland/flatland.hpp>

#include <cstdio>
#include <exception>

int main() {
  try {
    const flatland::Scene butterfly = flatland::load_scene(DATA_DIR "/scenes/butterfly.yaml");
    const flatland::sim::SolveReport solved =
        flatland::sim::solve_k(butterfly.sim, butterfly.sim.motion.period, {});
    const std::shared_ptr<const flatland::model::Model> filmed =
        flatland::model::compile(flatland::load_scene(DATA_DIR "/scenes/butterfly-camera.yaml"));
    const cv::Point2d origin = filmed->camera->project(cv::Point3d(0, 0, 0));
    flatland::studies::SimStudyOptions quick;
    quick.quick = true;
    quick.min_cpu = 0;
    const flatland::studies::SimStudyResult study =
        flatland::studies::run_sim_study(butterfly.sim, quick);
    std::printf(
        "{\"k\": %.17g, \"origin_px\": [%.6f, %.6f], \"default_scene\": \"%s\", "
        "\"study_k\": %.17g, \"study_rows\": %zu}\n",
        solved.k, origin.x, origin.y, flatland::default_scene_path().c_str(),
        study.reference_reduced.k, study.rows.size());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "downstream: %s\n", e.what());
    return 1;
  }
}
