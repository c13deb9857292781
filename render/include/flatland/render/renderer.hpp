// Synthetic camera images of the air table: the tilted table, the hand (its closed outline
// extruded), the pivot, the disk (rim O-ring, off-centre marker) and optional calibration
// targets, seen by the scene's camera with exact geometry and optional image effects.
#pragma once

#include "flatland/camera/board.hpp"
#include "flatland/camera/camera_model.hpp"
#include "flatland/render/effects.hpp"
#include "flatland/render/gl_context.hpp"
#include "flatland/scene/scene.hpp"
#include "flatland/sim/curve.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_run.hpp"

#include <opencv2/core.hpp>

#include <functional>
#include <memory>
#include <optional>
#include <vector>

namespace flatland::render {

/// A spatial scene's poses at one instant (world frame, SI): the hand frame's and the object
/// body's, x_world = R x + p.
struct SpatialPose {
  cv::Matx33d hand_rotation = cv::Matx33d::eye(), object_rotation = cv::Matx33d::eye();
  cv::Vec3d hand_position{0, 0, 0}, object_position{0, 0, 0};
};

/// What the renderer draws at one instant (all table frame, SI).
struct SceneState {
  double t = 0;
  double hand_angle = 0;                                      ///< rad
  cv::Point2d disk_center{0, 0};                              ///< m
  double disk_angle = 0;                                      ///< rad
  double s_h = 0;                                             ///< for truth and overlays
  double force_normal_ratio = 0, force_tangential_ratio = 0;  ///< overlays
  sim::ContactMode mode = sim::ContactMode::kRolling;         ///< overlays
  /// A spatial scene's bodies (space: 3d), drawn instead of the table, hand and disk.
  std::optional<SpatialPose> spatial;
  static SceneState from_sample(const sim::Sample& s);
  /// A spatial run's sample with the hand's pose at its time.
  static SceneState from_spatial_sample(const sim::SpatialSample& s, const sim::HandPose3& hand);
};

/// Ground truth of one frame.
struct FrameTruth {
  double t = 0;  ///< capture time (with jitter), s: the first row's mid-exposure time
  /// When the fields below hold, s: t with a global readout; with a rolling one the time the row
  /// of the disk's centre was read (where the disk's centre is in the rows that show it); with an
  /// interlaced one halfway between the two fields (what the two fields' disks average).
  double t_state = 0;
  double theta = 0, s_h = 0;
  cv::Point3d disk_center_table, marker_table;  ///< m; top face of the disk
  cv::Point2d disk_center_px, marker_px;        ///< cv::projectPoints of the above
  bool dropped = false;
};

/// The segmentation mask's ids (CV_8UC1, one per pixel): the body drawn there, nearest sample,
/// no anti-aliasing, blur or other effect. Board i of RenderSetup::boards is kMaskFirstBoard + i.
enum MaskId : unsigned char {
  kMaskBackground = 0,  ///< nothing drawn (beyond the table)
  kMaskTable = 1,
  kMaskHand = 2,
  kMaskDisk = 3,  ///< the object: disk, ring (its annulus) or ball (its equatorial disk)
  kMaskFirstBoard = 4,
};
/// The most calibration boards a mask can tell apart (ids 4..255).
constexpr int kMaxMaskBoards = 256 - kMaskFirstBoard;

struct Frame {
  cv::Mat image;  ///< CV_8UC3 (BGR), or CV_32FC3 when effects.quantize is false
  cv::Mat mask;   ///< CV_8UC1 MaskId per pixel, when CaptureOptions::mask asked for it
  FrameTruth truth;
};

/// What one capture returns besides its image.
struct CaptureOptions {
  bool mask = false;  ///< the segmentation mask, at the same rows' times as the image
};

/// A spatial scene's bodies: the hand's surface over `hand_extent` of its chart (an infinite side
/// cut at the chart's patch; the drawing is one-sided: seen from behind, a surface is not drawn)
/// and the object's whole surface, its chart's cells in two colours so that its turning shows.
struct SpatialBodies {
  sim::SurfacePtr hand, object;
  sim::SurfacePatch hand_extent;
};

/// The outline of the hand's plate as drawn (m, hand frame, counter-clockwise; its top face, the
/// hand's thickness high): a closed hand's outline over one period (the paper's polynomial hand's
/// right half sampled and mirrored); an open hand's (a line's) curve out to 2 table_extent from
/// the pivot, closed 4 table_extent deep into the body, so that it covers the table at any angle;
/// a circular well's ring (the well to 1.25 times its radius): the ring's outer circle.
std::vector<cv::Point2d> hand_plate_outline(const sim::HandCurve& hand, double table_extent);

/// What a Renderer draws, and how: a compiled scene's part (model::render_setup), or put together
/// by hand.
struct RenderSetup {
  camera::CameraModel camera;
  sim::HandPtr hand;                        ///< the hand's outline (hand_plate_outline, extruded)
  std::vector<camera::PlacedBoard> boards;  ///< calibration boards on the table
  sim::ObjectSpec object;  ///< a disk, ring (annulus) or ball (its equatorial disk): radii
  RenderSpec render;       ///< backend, thicknesses, table extent
  EffectsSpec effects;
  /// A spatial scene: these bodies instead of the hand and the disk (no table); `hand` and
  /// `object` are then unused. Frames come from render_linear / render_8u with SceneState::spatial.
  std::optional<SpatialBodies> spatial;
  /// A lamp over the table (lighting.hpp); absent: the fixed distant light, shading flat faces
  /// evenly, and no shadows (the frames of scenes without a `lighting` section).
  std::optional<LightingSpec> lighting;
  /// How the sensor reads a frame (the scene's camera.readout...): global, interlaced or rolling.
  ReadoutSpec readout;
};

class Renderer {
 public:
  /// Creates the GL context (backend from setup.render.backend unless `backend` is given).
  /// Throws std::invalid_argument on values it cannot draw (an ellipse, no
  /// hand) and std::runtime_error when no GL context can be made.
  explicit Renderer(const RenderSetup& setup, std::optional<GlBackend> backend = std::nullopt);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  const camera::CameraModel& camera() const;
  std::string gl_description() const;
  /// Replaces the scene's calibration boards (RenderSetup::boards), as a lab moves its board
  /// between views: the frames are those of a Renderer made with these boards, without making
  /// the GL context, programs and buffers again.
  void set_boards(std::vector<camera::PlacedBoard> boards);

  /// One geometric image of the state: anti-aliasing and distortion applied, no noise/blur/
  /// quantisation (CV_32FC3, 0..255 DN).
  cv::Mat render_linear(const SceneState& state);
  /// The same as an 8-bit BGR image; without supersampling or distortion it is the GL readback
  /// itself (the fast path).
  cv::Mat render_8u(const SceneState& state);
  /// One camera frame at nominal time t from a run's dense output: exposure blur over the
  /// exposure ending at t (sub-frames from the trajectory), timing jitter, noise, vignetting,
  /// quantisation, dropped frames, per the scene's effects. The renderer's RNG
  /// (scene.effects.seed) advances frame by frame, so a scene and seed give identical frames.
  ///
  /// With an interlaced readout the frame's fields are each such a frame at their own times (t
  /// and t + 1/(2 fps), the first field's rows per readout.field_order), with a rolling one row y
  /// is one at t + y * readout.time / height (to the band's middle row with readout.band_rows >
  /// 1); noise, vignetting and quantisation then apply to the whole frame.
  Frame capture(const sim::Trajectory& trajectory, double t, const CaptureOptions& options = {});
  /// The same for a world that is not a finished run (a closed loop in progress): `state_at`
  /// gives the scene at any time the exposure needs (it clamps to what it knows).
  using StateAt = std::function<SceneState(double t)>;
  Frame capture(const StateAt& state_at, double t, const CaptureOptions& options = {});
  /// How long after a frame's time stamp its last row is taken, s (0 for a global readout): a
  /// caller rendering as a world runs must have simulated to t + this + exposure / 2.
  double readout_duration() const;
  /// The segmentation mask of one state (CV_8UC1, MaskId), at the camera's resolution. Throws
  /// std::invalid_argument for a spatial scene or more than kMaxMaskBoards boards.
  cv::Mat render_mask(const SceneState& state);
  /// Truth for a state (also usable without rendering).
  FrameTruth truth(const SceneState& state) const;

 private:
  /// Vignetting, noise and quantisation on a frame's geometric image, into frame.image.
  void finish_frame(cv::Mat& linear, Frame& frame);
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flatland::render
