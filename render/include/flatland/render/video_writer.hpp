// MP4 output through OpenCV's FFmpeg backend, with the one codec fallback every video of flatland
// uses (rendered runs, experiment videos).
#pragma once

#include <opencv2/videoio.hpp>

#include <string>

namespace flatland::render {

/// Open `writer` on `path` (an .mp4) for BGR frames of `size` at `fps`: H.264 (avc1) when this
/// FFmpeg can encode it, else MPEG-4 part 2 (mp4v), saying so on stderr. Returns the codec
/// ("avc1" or "mp4v"). When neither can be encoded, throws std::runtime_error
/// `what` + "neither H.264 (avc1) nor MPEG-4 part 2 (mp4v) can be encoded ..." + `hint`.
std::string open_mp4(cv::VideoWriter& writer, const std::string& path, double fps, cv::Size size,
                     const std::string& what, const std::string& hint = "");

}  // namespace flatland::render
