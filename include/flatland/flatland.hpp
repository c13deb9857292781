// flatland: the whole library in one include (find_package(flatland), flatland::flatland).
// Each module also has its own headers, <flatland/MODULE/...>, for a program that needs less:
// docs/DEVELOPING.md, "Layers", says what each module holds and what it depends on.
#pragma once

#include "flatland/files/output_set.hpp"

#include "flatland/sim/contact.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/format.hpp"
#include "flatland/sim/hybrid.hpp"
#include "flatland/sim/motion.hpp"
#include "flatland/sim/object.hpp"
#include "flatland/sim/parallel.hpp"
#include "flatland/sim/rolling.hpp"
#include "flatland/sim/roots.hpp"
#include "flatland/sim/search.hpp"
#include "flatland/sim/sensitivity.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial.hpp"
#include "flatland/sim/spatial_run.hpp"
#include "flatland/sim/spec.hpp"
#include "flatland/sim/surface.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include "flatland/design/design.hpp"

#include "flatland/scene/scene.hpp"

#include "flatland/api/reports.hpp"
#include "flatland/api/sim_operations.hpp"

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_file.hpp"
#include "flatland/camera/camera_model.hpp"

#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"

#include "flatland/render/distortion_maps.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/gl_context.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/render/video_writer.hpp"

#include "flatland/vision/hand_pose.hpp"
#include "flatland/vision/image_file.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"
#include "flatland/vision/video_reader.hpp"

#include "flatland/calibration/intrinsics.hpp"
#include "flatland/calibration/joint.hpp"
#include "flatland/calibration/report.hpp"
#include "flatland/calibration/session.hpp"

#include "flatland/identify/identify.hpp"

#include "flatland/control/choice.hpp"
#include "flatland/control/controller.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/control/hand_input.hpp"
#include "flatland/control/interfaces.hpp"
#include "flatland/control/rolling_filter.hpp"
#include "flatland/control/transverse.hpp"
#include "flatland/control/types.hpp"
#include "flatland/control/ukf.hpp"

#include "flatland/drivers/calibration_session.hpp"
#include "flatland/drivers/experiment.hpp"
#include "flatland/drivers/interfaces.hpp"
#include "flatland/drivers/live.hpp"
#include "flatland/drivers/montecarlo.hpp"
#include "flatland/drivers/recorded.hpp"
#include "flatland/drivers/synthetic.hpp"
#include "flatland/drivers/tick_log_csv.hpp"

#include "flatland/studies/calibration_study.hpp"
#include "flatland/studies/closed_loop_study.hpp"
#include "flatland/studies/render_study.hpp"
#include "flatland/studies/sim_study.hpp"
#include "flatland/studies/timing.hpp"
#include "flatland/studies/tracker_study.hpp"
