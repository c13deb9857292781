// Pixel -> table plane -> hand frame -> hand contact parameter s_h: the chain that turns a tracked
// disk centre into the quantity the controller compares with its plan (docs/VISION.md).
#pragma once

#include "flatland/camera/camera_model.hpp"
#include "flatland/sim/curve.hpp"

#include <opencv2/core.hpp>

#include <memory>
#include <optional>
#include <vector>

namespace flatland::vision {

/// Normalised, undistorted image coordinates (x/z, y/z in the camera frame) of a pixel
/// (cv::undistortPoints with the camera's K and distortion).
cv::Point2d undistort_pixel(const camera::CameraModel& camera, cv::Point2d px);

/// The table-frame point on the plane z = plane_z (m) seen at pixel px: the undistorted ray
/// intersected with the plane. nullopt when the ray is parallel to the plane or meets it behind
/// the camera.
std::optional<cv::Point2d> pixel_to_table(const camera::CameraModel& camera, cv::Point2d px,
                                          double plane_z);

/// The same for many pixels at once (one cv::undistortPoints call, 30 fixed iterations: for the
/// tracker's edge points); NaN points where the ray misses the plane.
std::vector<cv::Point2d> pixels_to_table(const camera::CameraModel& camera,
                                         const std::vector<cv::Point2d>& px, double plane_z);

/// Table frame -> hand frame: the hand pivots about `axis_table` and is turned by theta (rad,
/// counter-clockwise seen from +z), so p_hand = R(-theta) (p_table - axis).
cv::Point2d table_to_hand(cv::Point2d p_table, cv::Point2d axis_table, double theta);

struct ContactEstimate {
  double s_h = 0;       ///< global hand parameter (pieces m cover [2m-1, 2m+1])
  double distance = 0;  ///< m, |q(s_h) - p|: how far the point is from the offset curve
  int piece = 0;
};

/// The hand parameter s whose offset point q(s) = c(s) + r n(s) (the centre of a disk of radius r
/// touching the hand at c(s), n the outward normal) is nearest to p_hand: a grid scan over
/// [guess - half_window, guess + half_window], then Brent's minimiser on |q(s) - p|^2 in the best
/// grid cell, each piece by its own formula. The grid's step is a 400th of a closed hand's period
/// (0.01 for the butterfly hands); on an open hand (a line) it is 1/20 of the disk's radius along
/// the curve at the guess.
ContactEstimate contact_parameter(const sim::HandCurve& hand, double disk_radius,
                                  cv::Point2d p_hand, double guess, double half_window = 1.0);

/// Everything needed to map a tracked centre to s_h.
struct HandMapping {
  camera::CameraModel camera;    ///< K, dist and the table pose R, t
  cv::Point2d axis_table{0, 0};  ///< m, joint axis in the table frame
  double plane_z = 0;            ///< m, height of the tracked point (the disk's top face)
  double disk_radius = 0;        ///< m
  /// The hand's outline (a compiled scene's model.hand); default: the paper's polynomial hand.
  sim::HandPtr hand = std::make_shared<sim::PolynomialHand>(0.18, -0.18, -0.252, 0.216);
};

/// Pixel -> s_h at hand angle theta. nullopt if the ray misses the plane.
std::optional<ContactEstimate> pixel_to_contact(const HandMapping& m, cv::Point2d px, double theta,
                                                double guess, double half_window = 1.0);

/// The contact of a tracked frame in a sequence: searched near the previous frame's s_h when
/// there is one (an eighth of the period either side: half a piece of the butterfly hands, whose
/// period is 4), else over a whole period of the closed outline about s = 0. On an open hand (a
/// line: no period, no wrap) the first search starts at the hand's point nearest to the centre
/// (HandCurve::nearest) and each search spans 3 disk radii along the curve either side.
/// `previous_s_h`: NaN for the first frame or after a lost one.
std::optional<ContactEstimate> follow_contact(const HandMapping& m, cv::Point2d px, double theta,
                                              double previous_s_h);

/// The standard deviation of the s_h measured at a tracked centre px (contact s_h, hand angle
/// theta): the tracker's 1-sigma per pixel coordinate, floored at 0.02 px (what the tracker's own
/// estimate leaves out), carried through the mapping by finite differences; floored at 1e-6, and
/// 1e-4 where a shifted centre does not map. The closed loop's measurements and identify's
/// recordings from pixels both take it.
double contact_sigma(const HandMapping& m, cv::Point2d px, double sigma_px, double theta,
                     double s_h);

}  // namespace flatland::vision
