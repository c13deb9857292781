// Scene files: one YAML description of an experiment, loaded once, immutable afterwards.
// SI units throughout (m, s, kg, rad); keys ending in _deg are degrees. Sections a scene does not
// contain are simply off. Schema: docs/SCENE.md.
#pragma once

#include "flatland/sim/spatial_spec.hpp"
#include "flatland/sim/spec.hpp"

#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace flatland {

/// Bad scene input. what() is one line: "<origin>: <field>: <reason>".
class SceneError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// Overhead camera (section `camera`). Pinhole + OpenCV distortion (k1, k2, p1, p2, k3); pose in
/// the table frame (x, y in the table plane as in the simulator, origin at the hand pivot, z out
/// of the table towards the camera).
/// How the sensor reads a frame out (keys camera.readout, camera.field_order,
/// camera.readout_time, camera.readout_band_rows). A frame's time stamp is its first row's
/// (mid-exposure) time in every mode.
struct ReadoutSpec {
  /// "global": every row at the frame's time; "interlaced": two fields 1/(2 fps) apart, one of
  /// the even rows (0, 2, ...), one of the odd; "rolling": row y at t + y * time / height.
  std::string mode = "global";
  std::string field_order = "even_first";  ///< interlaced: "even_first" or "odd_first"
  double time = 0.0;                       ///< s, rolling: first row to the frame's end
  /// rolling: rows rendered at one time (the band's middle row's): 1 is exact, more is faster and
  /// shifts a row's time by up to (band_rows - 1) / 2 line times.
  int band_rows = 1;
  bool global() const { return mode == "global"; }
};

struct CameraSpec {
  int width = 640, height = 480;       ///< px
  double fx = 700, fy = 700;           ///< px
  double cx = 319.5, cy = 239.5;       ///< px (OpenCV convention: pixel centres at integers)
  std::array<double, 5> distortion{};  ///< k1, k2, p1, p2, k3
  std::array<double, 3> position{0.0, 0.0, 1.0};  ///< m, camera centre in the table frame
  std::array<double, 3> look_at{0.0, 0.0, 0.0};   ///< m, point on the optical axis
  std::array<double, 3> up{0.0, 1.0, 0.0};        ///< image "up" direction (table frame)
  double fps = 30.0;                              ///< frames per second
  double exposure = 0.0;        ///< s, exposure time (blur when > 0 and effects.blur_subframes > 1)
  double latency = 0.0;         ///< s, capture (mid-exposure) to arrival at the control loop
  double latency_jitter = 0.0;  ///< s, half-width of a uniform spread of the latency
  ReadoutSpec readout;
};

/// The largest camera image side, px (beyond any GL framebuffer flatland renders into; the same
/// bound as camera::kMaxImageSide).
constexpr int kMaxCameraSide = 16384;

/// A rule a section breaks: the field below the section ("position", "look_at") and why.
struct FieldProblem {
  std::string field;
  std::string reason;
};

/// The camera's rules, written once: the scene loader reports the first one broken as
/// "origin: camera.FIELD: reason", model::compile_camera as "camera.FIELD: reason". Size in
/// [1, kMaxCameraSide] px; fx, fy > 0; cx, cy, distortion, position, look_at, up finite; fps > 0;
/// exposure in [0, 1/fps] (an interlaced field's in [0, 1/(2 fps)]); readout global, interlaced
/// or rolling, its field order and rolling time and band only where they apply (readout time in
/// (0, 1/fps], band rows in [1, height]); the camera above the table (z > 0), looking down at it,
/// with `up` a non-zero vector not along the view. nullopt when none is broken.
std::optional<FieldProblem> camera_problem(const CameraSpec& camera);

/// Image effects (section `effects`); each is off unless the scene asks for it.
struct EffectsSpec {
  int supersample = 1;            ///< anti-aliasing: render s x s samples per pixel
  int blur_subframes = 1;         ///< exposure blur: sub-frames averaged over camera.exposure
  double noise_read_dn = 0.0;     ///< read noise sigma, DN (8-bit digital numbers)
  double noise_shot_gain = 0.0;   ///< shot noise: variance += gain * signal (DN)
  bool quantize = true;           ///< round to 8 bits (off gives a float image)
  double vignetting = 0.0;        ///< relative fall-off at the image corner (cos^4-like), 0..1
  double jitter_s = 0.0;          ///< timing jitter sigma, s
  double drop_probability = 0.0;  ///< probability a frame is dropped
  std::uint64_t seed = 1;         ///< randomness is seeded
};

/// A planar calibration target (section `targets`, list).
struct TargetSpec {
  enum class Kind { kChessboard, kCharuco };
  Kind kind = Kind::kChessboard;
  /// Squares along the board's x and y (as cv::aruco::CharucoBoard's squaresX, squaresY). The
  /// scene file counts a chessboard by its inner corners (OpenCV's patternSize) and a ChArUco
  /// board by its squares; the default is OpenCV's sample chessboard, 9x6 inner corners.
  int squares_x = 10, squares_y = 7;
  double square = 0.02;   ///< m
  double marker = 0.015;  ///< m (ChArUco marker side)
  std::string dictionary = "DICT_4X4_50";
  std::array<double, 3> position{0.0, 0.0, 0.0};  ///< m, board origin in the table frame
  std::array<double, 3> rotation{0.0, 0.0, 0.0};  ///< rad, Rodrigues vector board -> table
};

/// How the scene is drawn (section `render`).
struct RenderSpec {
  std::string backend = "osmesa";  ///< osmesa | egl
  std::string view = "overhead";   ///< overhead | side
  double hand_thickness = 0.012;   ///< m, extrusion height of the hand plate
  double disk_thickness = 0.006;   ///< m
  double table_extent = 0.6;       ///< m, half-size of the drawn table
};

/// A surface's highlight under the lamp (Blinn-Phong): strength (a fraction of the light that
/// reaches the surface) and exponent.
struct MaterialSpec {
  double specular = 0.0;   ///< in [0, 1]; 0: matte
  double shininess = 1.0;  ///< in [1, 10000]: the larger, the smaller and sharper the highlight
};

/// A lamp over the table (section `lighting`; docs/SCENE.md): a point light with its colour, an
/// ambient level, diffuse and specular (Blinn-Phong) shading per material, the hand's and the
/// disk's shadows on the table, and the table lit unevenly by the lamp's distance and angle. Off
/// without the section: then the renderer keeps its fixed distant light and flat shading.
struct LightingSpec {
  std::array<double, 3> position{0.3, 0.2, 1.5};  ///< m, the lamp in the table frame, above all
  std::array<double, 3> color{1.0, 1.0, 1.0};     ///< the lamp's colour, each in [0, 1]
  /// The direct light's level on the table straight under the lamp (a white matte surface there
  /// shows ambient + intensity of full scale), >= 0.
  double intensity = 0.65;
  double ambient = 0.35;  ///< light from everywhere (room, walls), in [0, 1]
  bool specular = true;   ///< the materials' highlights
  bool shadows = true;    ///< the hand's and the disk's shadows on the table
  /// Inverse-square and cosine fall-off of the direct light across the table; false: the lamp is
  /// taken as distant, in its direction from the table's origin, and lights the table evenly.
  bool falloff = true;
  MaterialSpec table{0.0, 1.0};   ///< the air table: matte
  MaterialSpec hand{0.25, 24.0};  ///< brushed aluminium: a soft highlight
  MaterialSpec face{0.05, 8.0};   ///< the disk's face (and its marker): nearly matte
  MaterialSpec band{0.5, 40.0};   ///< the rubber O-ring round the disk: glossy
};

/// The lamp's rules, written once: the scene loader reports the first one broken as
/// "origin: lighting.FIELD: reason", the renderer as "lighting.FIELD: reason". position, color
/// finite; the lamp above the hand's and the disk's tops (render.hand_thickness, disk_thickness),
/// whose shadows it casts on the table; color in [0, 1]; intensity >= 0; ambient in [0, 1]; each
/// material's specular in [0, 1] and shininess in [1, 10000]. nullopt when none is broken.
std::optional<FieldProblem> lighting_problem(const LightingSpec& lighting,
                                             const RenderSpec& render);

/// The joint that turns the hand (section `joint`), the paper's scheme: the commanded
/// acceleration is integrated into a reference angle and rate, which a PD torque loop tracks on a
/// motor model; the disk's contact force loads the joint.
struct JointSpec {
  double inertia = 0.05;           ///< kg m^2, hand plate + reflected rotor, about the joint axis
  double viscous = 0.02;           ///< N m s/rad, viscous friction
  double coulomb = 0.05;           ///< N m, Coulomb (dry) friction
  double torque_limit = 10.0;      ///< N m, the drive saturates here
  long encoder_counts = 1048576;   ///< counts per revolution (a 20-bit encoder)
  double kp = 500.0;               ///< N m/rad, PD torque loop
  double kd = 10.0;                ///< N m s/rad
  double velocity_filter = 0.002;  ///< s, time constant of the drive's velocity estimate
  double rate = 1000.0;            ///< Hz, servo and control-loop rate
};

/// The transverse-linearisation controller's LQR (section `controller.transverse`;
/// control/transverse.hpp, docs/CLOSED_LOOP.md). The error is (theta - theta*, theta_dot -
/// theta_dot*, sdot_h - sdot_h*) against the plan at the estimated s_h.
struct TransverseSpec {
  std::array<double, 3> q{100.0, 1.0, 1.0};         ///< running cost's diagonal, >= 0
  double r = 0.1;                                   ///< s^4/rad^2, the acceleration's weight, > 0
  std::array<double, 3> terminal{100.0, 1.0, 1.0};  ///< cost at finish_after, >= 0
  double grid_step = 1e-3;  ///< s of plan time between stored gains, (0, 0.01]
};

/// The paper's vision-feedback controller (section `controller`, section 5 of the paper).
struct ControllerSpec {
  /// The control law by name: paper (section 5's three stages; the keys below up to
  /// finish_after are its own) | transverse (section `controller.transverse`).
  std::string type = "paper";
  std::string mode = "feedback";  ///< feedback | open-loop
  /// Plan: the scene's motion as given ("scene") or with k solved for the scene's period ("solve").
  std::string plan = "scene";
  double kp = 900.0;              ///< 1/s^2, stage 2: theta'' = kp (theta_p(s) - theta) + ...
  double kd = 120.0;              ///< 1/s (over-damped with kp: see docs/CLOSED_LOOP.md)
  std::string law = "paper";      ///< paper | time-scaled (stage 2's law, docs/CLOSED_LOOP.md)
  double dip_until = -0.9;        ///< stage 1 ends when the estimated s_h exceeds this
  double finish_after = 0.9;      ///< stage 3 starts when the estimated s_h exceeds this
  double lost_timeout = 0.25;     ///< s without a usable measurement -> safe stop
  double innovation_gate = 50.0;  ///< NIS above this (chi-square, 1 dof) is implausible
  int innovation_strikes = 3;     ///< consecutive implausible innovations -> safe stop
  double max_joint_jump =
      0.05;  ///< rad, a reading further than this from the prediction is a glitch
  double stop_deceleration = 20.0;  ///< rad/s^2, safe stop
  double settle = 1.0;              ///< s the loop keeps running after the hand stops
  TransverseSpec transverse;        ///< type transverse's own keys
};

/// The unscented filter's sigma points (section `estimator.ukf`; control::UkfConfig).
struct UkfSpec {
  double alpha = 1.0;  ///< spread scaling, in [1e-4, 1]
  double beta = 2.0;   ///< prior's kurtosis term (2: Gaussian), >= 0
  double kappa = 1.0;  ///< secondary scaling, >= 0 (n + kappa = 3: points at +-sqrt(3) sigma)
};

/// The contact estimator (section `estimator`).
struct EstimatorSpec {
  std::string type = "ekf";       ///< ekf (extended Kalman filter) | ukf (unscented)
  std::string model = "rolling";  ///< rolling | constant-velocity
  bool latency_compensation = true;
  /// 1/s^2 per sqrt(Hz), white noise on sddot_h: calibrated for consistency (NEES) on the
  /// air-table worlds (hybrid, with losses the estimator does not model) perturbed as in the Monte
  /// Carlo study, with the hand's acceleration estimated from the joint's readings
  /// (docs/CLOSED_LOOP.md, docs/ESTIMATOR.md).
  double process_noise = 0.016;
  UkfSpec ukf;  ///< type ukf's own parameters
};

/// Faults injected into a synthetic experiment (section `faults`), to test the safe stop.
struct FaultSpec {
  std::optional<double> camera_stop;     ///< s, no frames after this
  std::optional<double> camera_stall;    ///< s, frames freeze (the same image, stale stamps)
  std::optional<double> occlusion;       ///< s, the disk is hidden from here ...
  double occlusion_duration = 0.5;       ///< s, ... for this long
  std::optional<double> encoder_glitch;  ///< s, one encoder reading jumps ...
  double encoder_glitch_size = 0.5;      ///< rad, ... by this much
};

struct Scene {
  std::string origin;  ///< file path (or "<string>")
  std::string name;    ///< optional `name:` key
  /// A spatial scene (`space: 3d`): a ball or an ellipsoid on a surface hand in space. Only
  /// `flatland simulate` runs one; every other section below then keeps its defaults, unused.
  std::optional<sim::SpatialSpec> spatial;
  sim::SimulationSpec sim;
  std::optional<CameraSpec> camera;  ///< absent: nothing is rendered
  EffectsSpec effects;
  RenderSpec render;
  std::optional<LightingSpec> lighting;  ///< absent: the renderer's fixed, even light
  std::vector<TargetSpec> targets;
  JointSpec joint;
  ControllerSpec controller;
  EstimatorSpec estimator;
  FaultSpec faults;
};

/// Parse and validate a scene (strict: unknown keys, wrong types, NaN/inf, missing required keys,
/// physically invalid values such as negative radius, k = -2 or an unusable hand shape are errors).
Scene parse_scene(const std::string& yaml_text, const std::string& origin = "<string>");
/// Read a file and parse it; an unreadable file is a SceneError too.
Scene load_scene(const std::string& path);
/// The directory of flatland's bundled data (scenes/, boards/, shapes/), found at run time: the
/// environment's FLATLAND_DATA_DIR when set; else share/flatland beside the running program
/// (PREFIX/bin/../share/flatland, or from PREFIX/libexec/flatland/; the build tree has
/// build/share/flatland); else the installed PREFIX/share/flatland. The first that holds
/// scenes/butterfly.yaml; when none does, the first of them (loading a scene from it then names
/// the missing file).
std::string data_directory();
/// The bundled default scene (the paper's butterfly): data_directory()/scenes/butterfly.yaml.
std::string default_scene_path();

}  // namespace flatland
