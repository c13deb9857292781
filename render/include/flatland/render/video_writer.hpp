// MP4 output with FFmpeg's libraries, the one writer every video of flatland uses (rendered runs,
// experiment videos): H.264 when this FFmpeg can encode it, else MPEG-4 part 2, and a key frame
// every second, as a real recorder writes them. OpenCV's writer (4.6) leaves the key-frame
// interval to x264's default of 250 frames, so a rendered video had a single key frame and a
// damage anywhere cost the rest of it (docs/VISION.md, "Frame integrity").
#pragma once

#include <opencv2/core.hpp>

#include <memory>
#include <string>

namespace flatland::render {

class Mp4Writer {
 public:
  /// Seconds between key frames: a damaged frame costs at most the frames up to the next one.
  static constexpr double kKeyFrameInterval = 1.0;

  Mp4Writer();
  ~Mp4Writer();  ///< closes an open file without reporting errors (call release() to see them)
  Mp4Writer(const Mp4Writer&) = delete;
  Mp4Writer& operator=(const Mp4Writer&) = delete;

  /// Open `path` for BGR (or grey) frames of `size` at `fps`: H.264 (libx264, CRF 23, as
  /// OpenCV's writer had it) when this FFmpeg can encode it, else MPEG-4 part 2, saying so on
  /// stderr. Returns the codec as a fourcc ("avc1" or "mp4v"). Throws std::runtime_error
  /// `what` + the reason (+ `hint` when no encoder exists) when the file cannot be written.
  std::string open(const std::string& path, double fps, cv::Size size, const std::string& what,
                   const std::string& hint = "");
  bool isOpened() const;
  /// Encode one frame (CV_8UC3 BGR or CV_8UC1 of the opened size). std::runtime_error naming
  /// the file on an encoding or write error; std::invalid_argument for a frame of another size.
  void write(const cv::Mat& image);
  /// Flush the encoder, finish and close the file. std::runtime_error naming the file on failure.
  /// Does nothing if not open.
  void release();
  long frames() const;      ///< frames written
  long key_frames() const;  ///< of which key frames

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// `writer.open(...)`, for the call sites that read better as a function.
std::string open_mp4(Mp4Writer& writer, const std::string& path, double fps, cv::Size size,
                     const std::string& what, const std::string& hint = "");

}  // namespace flatland::render
