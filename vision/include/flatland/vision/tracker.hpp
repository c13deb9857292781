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
  /// The obvious OpenCV tracker, the peer the edge fit is measured against: Otsu's threshold,
  /// cv::findContours and cv::fitEllipse, on the whole frame at full resolution (re-acquisition)
  /// or a window around the prediction (tracking).
  kContour,
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
  /// The edge fit casts its rays from the guess, fits, and casts them again from the fitted
  /// centre (so that they meet the edge at right angles) only when that centre is farther than
  /// this from the guess (px). 0: always two passes, the default: one pass from a close guess
  /// (1 px) is as accurate but its sigma is too large (the rays meet the edge obliquely): the
  /// closed loop's mean NEES fell from 2.02 to 1.87, below its 95 % bounds [1.90, 2.10].
  /// docs/VISION.md has the accuracy of one pass against two.
  double second_pass_shift_px = 0.0;
  /// When the camera (K, distortion, table pose) is known, the edge method fits the circle to the
  /// edge points back-projected onto the plane z = plane_z (the disk's top face) and projects its
  /// centre: exact for an oblique or distorted camera, where the image of the circle is not a
  /// circle and the centre of its image is not the image of its centre. The result does not
  /// depend on plane_z (planes parallel to the table map onto each other by a homothety).
  std::optional<camera::CameraModel> camera;
  double plane_z = 0;  ///< m
  /// The variance of the times a frame's image averages about its time stamp, in frame
  /// intervals squared (the intervals between the frames given to track()): exposure^2 / 12 for
  /// an exposure of that many intervals, plus (1/4)^2 for an interlaced frame's two fields. The
  /// image shows the disk's mean position over those times, which on a curved or accelerating
  /// path lies acceleration x variance / 2 off its position at the stamp: the tracker takes that
  /// off with the acceleration of its last three centres, and adds how much that acceleration
  /// changed since the frame before to sigma. 0 (an instantaneous global shutter): nothing.
  double image_time_variance_frames2 = 0;
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
  /// A frame passed without an image for track() (unreadable, a repeat of the one before,
  /// dropped): the prediction steps over it, and the acceleration the time-stamp correction
  /// needs is measured afresh from the next three centres (three evenly spaced ones).
  void skip();
  const TrackerConfig& config() const { return config_; }

 private:
  TrackResult locate(const cv::Mat& frame, const cv::Rect& roi, cv::Point2d guess, double radius,
                     TrackState state);
  TrackResult reacquire(const cv::Mat& frame);
  TrackResult at_time_stamp(TrackResult r) const;
  TrackerConfig config_;
  bool have_track_ = false, have_acceleration_ = false;
  int history_ = 0;
  /// The last centre as the image shows it (before at_time_stamp), and its differences.
  cv::Point2d last_{0, 0}, velocity_{0, 0}, acceleration_{0, 0}, acceleration_change_{0, 0};
  double radius_ = 0;
};

/// TrackerConfig::image_time_variance_frames2 of a camera whose frames are given to the tracker
/// `frame_interval_s` apart: exposure^2 / 12 of a box exposure, plus the two fields' +-1/4 of a
/// camera frame about the time stamp when `interlaced` (`camera_frame_interval_s` = 1/fps), in
/// those intervals squared.
double image_time_variance_frames2(double exposure_s, double frame_interval_s, bool interlaced,
                                   double camera_frame_interval_s);

/// Building blocks, public for tests and benchmarks.

/// The frame as a single-channel CV_32F image in DN (BGR is averaged; no copy for CV_32FC1).
/// The grey conversion runs in the frame's own depth (an 8-bit frame is made grey as 8-bit,
/// then the one channel is converted to float). Pass a window (`frame(roi)`) to convert only it.
cv::Mat to_gray_f32(const cv::Mat& frame);
/// The grey the edge fit reads: CV_8UC1 for an 8-bit frame (no float copy), else CV_32FC1.
cv::Mat to_gray_for_edge(const cv::Mat& frame);
/// The frame as a single-channel CV_8U image (grey in the frame's own depth, then saturated).
cv::Mat to_gray_u8(const cv::Mat& frame);

/// Whole-frame search for the disk's face: a bright, near-circular blob, found on a grey copy of
/// the frame four times smaller (two times when the expected edge radius is under 24 px, or when
/// nothing was found at four), made in one pass over the frame's own pixels. `frame`: any frame
/// `Tracker::track` accepts. Returns the blob's centre in the frame's pixels and the edge radius
/// estimated from its area, or state kLost.
TrackResult acquire(const cv::Mat& frame, double expected_edge_radius_px = 0);

/// One refinement from a centre guess and edge radius (px) with the chosen method. The edge fit
/// reads CV_8UC1 or CV_32FC1 (to_gray_for_edge); the others CV_32FC1.
/// `offset`: the full frame's pixel coordinates of gray_f32's (0, 0) when it is a region of
/// interest (the camera-aware fit maps full-frame pixels); guess and result are in gray_f32's.
TrackResult refine_edge(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                        const TrackerConfig& config, cv::Point2d offset = {0, 0});
TrackResult refine_moments(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                           const TrackerConfig& config);
/// cv::HoughCircles in a window around the guess (whole frame if edge_radius <= 0 is unknown).
TrackResult refine_hough(const cv::Mat& gray_f32, cv::Point2d guess, double edge_radius,
                         const TrackerConfig& config);
/// The contour peer (TrackMethod::kContour) on a grey 8-bit image: the round outline nearest
/// to the prediction, or without one the roundest large one; an expected edge radius > 0 keeps
/// outlines within 25 % of it. Centre in gray_u8's pixels.
TrackResult fit_contour(const cv::Mat& gray_u8, std::optional<cv::Point2d> prediction,
                        double expected_edge_radius_px);

}  // namespace flatland::vision
