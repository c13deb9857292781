// Pictures of an intrinsic calibration, for a person to look at before trusting it: each view's
// detected corners with their reprojection errors as arrows, and the coverage of the image by all
// corners (a calibration is only as good as the image area its corners cover).
#pragma once

#include "flatland/calibration/intrinsics.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace flatland::calibration {

/// Corners reprojected through the result: view `i`'s object points through its pose, K and dist.
std::vector<cv::Point2f> reprojected_corners(const IntrinsicsResult& result,
                                             const std::vector<BoardView>& views, std::size_t i);

/// View `i` drawn over its image (8-bit gray or BGR): each detected corner a green circle, its
/// reprojection error an arrow from the detection to the reprojection, scaled by `arrow_scale`,
/// red where the error exceeds 3 x the view's RMS; a caption with the view's name, RMS, and the
/// arrow scale (or the reason it was rejected).
cv::Mat draw_view_residuals(const cv::Mat& image, const IntrinsicsResult& result,
                            const std::vector<BoardView>& views, std::size_t i,
                            double arrow_scale = 20);

/// Coverage of the image by the corners of the views used: an 8 x 6 grid of cells shaded by how
/// many corners fell in each (empty cells red: nothing constrains the distortion there), every
/// corner a dot coloured by its view, and a caption with the share of cells covered.
cv::Mat draw_coverage(const IntrinsicsResult& result, const std::vector<BoardView>& views);
/// The share of the 8 x 6 grid's cells holding at least one corner of a used view.
double coverage_fraction(const IntrinsicsResult& result, const std::vector<BoardView>& views);

}  // namespace flatland::calibration
