// Uses flatland as a library from its installed prefix: loads the bundled scenes from the
// installed data, solves the paper's butterfly (sim) and projects the disk's start through the
// scene's camera, compiled into a Model. Prints one JSON object; exit 1 on any error.
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
    std::printf("{\"k\": %.17g, \"origin_px\": [%.6f, %.6f], \"default_scene\": \"%s\"}\n",
                solved.k, origin.x, origin.y, flatland::default_scene_path().c_str());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "downstream: %s\n", e.what());
    return 1;
  }
}
