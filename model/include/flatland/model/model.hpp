// The compiled Model: a parsed Scene (the file's shape) turned once into the typed, validated
// values every module runs on, immutable afterwards and shared as std::shared_ptr<const Model>,
// as MuJoCo separates mjModel from mjData. A change of a world (a Monte Carlo draw, a study's cell,
// a rendered calibration view) edits the Scene and compiles it again; nothing edits a Model.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/control/choice.hpp"
#include "flatland/control/controller.hpp"
#include "flatland/control/estimator.hpp"
#include "flatland/render/renderer.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/rolling.hpp"
#include "flatland/sim/spatial_spec.hpp"
#include "flatland/vision/mapping.hpp"
#include "flatland/vision/tracker.hpp"

#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace flatland::model {

struct Model {
  /// What the Model was compiled from. The sections that are typed values already (effects,
  /// render, joint, faults, the simulation's run options) are read from here.
  Scene spec;

  /// The scene's rolling problem (sim::build_problem of spec.sim): the world.
  std::shared_ptr<const sim::RollingProblem> plant;
  /// The plant's hand (scene `hand.shape`: the paper's polynomial, a line, a circular well), the
  /// same object as plant->hand: meshes, the pixel -> s_h mapping, the calibration session.
  sim::HandPtr hand;
  /// The same without losses (sim::paper_model): what the plan and the estimator assume.
  std::shared_ptr<const sim::RollingProblem> paper_plant;

  /// The scene's camera (section `camera`); absent: nothing is rendered or tracked.
  std::optional<camera::CameraModel> camera;
  /// The scene's calibration boards (section `targets`), in the file's order.
  std::vector<camera::PlacedBoard> boards;

  /// Tracked pixel -> table -> hand -> s_h, with the joint axis at the table origin (a synthetic
  /// world's; a real one's comes from a camera file). Present with a camera and an object the
  /// tracker can follow (tracking_problem).
  std::optional<vision::HandMapping> mapping;
  /// The tracker, knowing the camera and the plane of the disk's top face.
  vision::TrackerConfig tracker;

  /// The closed loop (sections `controller`, `estimator`, `joint`).
  /// The controller and estimator the scene chose (`controller.type`, `estimator.type`) with
  /// their typed configs; drivers::LoopSetup makes one of each per run from them.
  control::ControllerChoice controller;
  control::SafetyConfig safety;
  control::EstimatorChoice estimator;
  double control_dt = 1e-3;  ///< s, the control period (1 / joint.rate)
};

/// Compile a parsed scene: builds the plant (sim::build_problem's checks, its messages naming the
/// field), the camera (compile_camera), the boards (compile_target), the mapping and the loop's
/// configs. std::invalid_argument on a value none of them can use.
std::shared_ptr<const Model> compile(Scene scene);

/// What a render::Renderer needs of a compiled scene: its camera, hand, boards, object, render and
/// effects sections. std::invalid_argument naming camera unless the scene has one.
render::RenderSetup render_setup(const Model& model);
/// The same for a spatial scene (space: 3d) built as `setup` (sim::build_spatial of its spec):
/// the camera, the hand's surface (the part drawn: a sphere or ellipsoid whole, a plane or an
/// extruded hand out to render.table_extent) and the object's. std::invalid_argument naming the
/// scene's camera unless it has one, or its effects when they ask for what spatial frames do not
/// have (only supersampling and the lens are built for them). `flatland render` and Python's
/// Renderer both draw a spatial scene through it.
render::RenderSetup spatial_render_setup(const Scene& scene, const sim::SpatialSetup& setup);

/// Why the tracker cannot follow this object, as "FIELD: reason", or nullopt when it can. The
/// tracker's model is a solid disk's face seen whole: it follows a disk and a ball rolling on the
/// hand's edge (drawn as its equatorial disk of radius R, which is then also its rolling radius);
/// not a ring (its hole), a ball on rails (its part beyond the rolling radius reaches between the
/// rails, behind the hand), nor an ellipse (no centre on an offset curve).
std::optional<std::string> tracking_problem(const sim::ObjectSpec& object);

/// The pixel -> s_h mapping of a compiled scene's hand and object seen by `camera` (the scene's,
/// or a calibrated camera file's), the joint axis at `axis_table`; the centre's offset from the
/// hand is the plant's rolling radius. std::invalid_argument naming the object's field
/// (tracking_problem) unless the tracker can follow the object.
vision::HandMapping hand_mapping(const Model& model, const camera::CameraModel& camera,
                                 cv::Point2d axis_table = {0, 0});

}  // namespace flatland::model
