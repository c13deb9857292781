// Reading image files that may be damaged: a truncated PNG or JPEG is reported as such instead
// of being half-decoded (libjpeg fills the missing rows with grey and carries on, which a tracker
// or a board detector would take for image content).
#pragma once

#include <opencv2/core.hpp>

#include <filesystem>
#include <string>

namespace flatland::vision {

/// Why an image file cannot be used, or "" if it looks whole: missing, not a regular file,
/// zero-length, unreadable, or for PNG and JPEG (by extension) a bad signature or a truncated
/// file (PNG: the chunk chain up to IEND; JPEG: the end-of-image marker). Structural only: a few
/// reads per file, no decoding.
std::string image_file_problem(const std::filesystem::path& path);

/// image_file_problem, then cv::imread(path, flags) (cv::IMREAD_COLOR, _GRAYSCALE or _ANYCOLOR:
/// always 8 bits per channel, 16-bit files scaled down, alpha dropped). An empty Mat, with `why`
/// set to the reason, when the file is unusable; never throws for bad content.
cv::Mat read_image_file(const std::filesystem::path& path, int flags, std::string& why);

}  // namespace flatland::vision
