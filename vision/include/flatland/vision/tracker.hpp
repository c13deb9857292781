// Disk tracker: the centre of the air-table disk in one camera frame, in pixels (sub-pixel), with
// an uncertainty and a quality score. docs/VISION.md has the measured method comparison.
//
// The default method fits a circle to sub-pixel edge points of the boundary between the disk's
// bright face and its black O-ring band (0.92 of the radius). That boundary is the strongest edge
// in the scene (face 0.92 vs rubber 0.05), lies inside the disk (so the hand touching the rim does
// not cover it), is concentric with the disk, and is far from the off-centre marker dot (which
// biases any plain intensity centroid). Points are found along rays from the predicted centre and
// fitted with an iteratively reweighted geometric circle fit, so occluded or blurred rays are
// down-weighted rather than averaged in.
#pragma once

#include "flatland/camera/camera_model.hpp"

#include <opencv2/core.hpp>

#include <optional>

#include <string>

namespace flatland::vision {

enum class TrackState {
  kFound,     ///< (re-)acquired from the whole frame in this frame
  kTracking,  ///< followed in a region of interest around the prediction
  kLost,      ///< no disk in this frame
};
std::string to_string(TrackState s);  ///< "found", "tracking", "lost"

enum class TrackMethod {
  kEdge,     ///< sub-pixel face/O-ring edge points + robust circle fit (default)
  kMoments,  ///< coverage-weighted moments of the face with the marker filled in
  kHough,    ///< cv::HoughCircles (measured baseline only)
};
std::string to_string(TrackMethod m);
TrackMethod parse_track_method(const std::string& name);  ///< invalid_argument on unknown names

struct TrackerConfig {
  TrackMethod method = TrackMethod::kEdge;
  /// Expected radius of the disk's face/O-ring edge (0.92 of the disk radius) in px. 0: learnt
  /// at acquisition from the face's area and then from the fits.
  double edge_radius_px = 0;
  int rays = 96;             ///< edge rays per fit
  double ray_step_px = 0.5;  ///< sampling step along a ray
  /// Half-width of the window over which an edge point is refined by its profile's area (the
  /// ideal step with the same integral); 0: the linear mid-level crossing only.
  double edge_area_window_px = 1.5;
  double roi_margin_px = 12;  ///< ROI half-size = edge radius + margin (beyond the prediction)
  double min_inlier_fraction = 0.5;  ///< fewer valid edge points than this fraction: lost
  double max_radius_change = 0.25;   ///< relative change of the fitted radius that means "lost"
  double min_contrast_dn = 40;       ///< face minus O-ring level below this: no disk
  /// When the camera (K, distortion, table pose) is known, the edge method fits the circle to the
  /// edge points back-projected onto the plane z = plane_z (the disk's top face) and projects its
  /// centre: exact for an oblique or distorted camera, where the image of the circle is not a
  /// circle and the centre of its image is not the image of its centre. The result does not
  /// depend on plane_z (planes parallel to the table map onto each other by a homothety).
  std::optional<camera::CameraModel> camera;
  double plane_z = 0;  ///< m
};

struct TrackResult {
  TrackState state = TrackState::kLost;
  cv::Point2d center{0, 0};  ///< px (OpenCV convention: pixel centres at integers)
  double radius_px = 0;      ///< fitted edge radius
  double sigma_px = 0;       ///< 1-sigma uncertainty of each centre coordinate, px
  double quality = 0;        ///< 0 (lost) .. 1 (full clean circle)
  int edge_points = 0;       ///< inliers used by the edge fit
  bool ok() const { return state != TrackState::kLost; }
};

/// Stateful tracker: predicts from the last two estimates (constant velocity), searches a region
/// of interest around the prediction, and falls back to whole-frame re-acquisition in the same
/// frame when the ROI fit fails. Frames may be CV_8U or CV_32F, 1 or 3 (BGR) channels.
class Tracker {
 public:
  explicit Tracker(TrackerConfig config = {});
  TrackResult track(const cv::Mat& frame);
  /// Forget the track (the next frame is searched whole); a learnt edge radius is kept to
  /// validate re-acquisition.
  void reset();
  const TrackerConfig& config() const { return config_; }

 private:
  TrackResult locate(const cv::Mat& gray, cv::Point2d guess, double radius, TrackState state,
                     cv::Point2d offset = {0, 0});
  TrackerConfig config_;
  bool have_track_ = false;
  int history_ = 0;
  cv::Point2d last_{0, 0}, velocity_{0, 0};
  double radius_ = 0;
};

/// Building blocks, public for tests and benchmarks.

/// The frame as a single-channel CV_32F image in DN (BGR is averaged; no copy for CV_32FC1).
cv::Mat to_gray_f32(const cv::Mat& frame);

/// Whole-frame search for the disk's face: a bright, near-circular blob. Returns the blob's
/// centre and the edge radius estimated from its area, or state kLost.
TrackResult acquire(const cv::Mat& gray_f32, double expected_edge_radius_px = 0);

/// One refinement from a centre guess and edge radius (px) with the chosen method.
/// `offset`: the full frame's pixel coordinates of gray_f32's (0, 0) when it is a region of
/// interest (the camera-aware fit maps full-frame pixels); guess and result are in gray_f32's.
TrackResult refine_edge(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                        const TrackerConfig& config, cv::Point2d offset = {0, 0});
TrackResult refine_moments(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                           const TrackerConfig& config);
/// cv::HoughCircles in a window around the guess (whole frame if edge_radius <= 0 is unknown).
TrackResult refine_hough(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                         const TrackerConfig& config);

}  // namespace flatland::vision
