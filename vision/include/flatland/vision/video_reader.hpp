// Reading real footage frame by frame, and saying which frames can be trusted: a decoder that
// meets a damaged stream conceals the damage (it repeats or patches earlier pictures) and a
// plain reader hands those frames over as if they were fine. docs/VISION.md ("Frame integrity").
// Every consumer of a video (track, the recorded camera of the closed loop) reads through this.
#pragma once

#include <opencv2/core.hpp>

#include <cmath>
#include <memory>
#include <string>
#include <vector>

namespace flatland::vision {

/// What a frame can be trusted for.
enum class FrameIntegrity {
  kIntact,      ///< new content, decoded without error
  kRepeated,    ///< the same pixels as the frame before, or a timestamp not after its
  kDamaged,     ///< the decoder reported an error in it, or in a frame it depends on
  kUnreadable,  ///< could not be decoded at all
};
const char* to_string(FrameIntegrity integrity);

/// Flags repeated frames: the same content as the previous frame given, or a timestamp that does
/// not increase (NaN: unknown, not checked). Works for image sequences and videos alike. "The
/// same" allows for a codec: a frozen frame re-encoded by H.264 decodes with a mean absolute
/// difference of at most 0.001 DN from its neighbour (a few pixels off by 2-4 DN), while the
/// slowest real motion of the bundled scenes gives 0.06 DN and a sensor's read noise alone about
/// 1 DN per DN of noise sigma.
class RepeatCheck {
 public:
  static constexpr double kMaxMeanDifference = 0.01;  ///< DN, mean over pixels and channels

  bool repeated(const cv::Mat& image, double timestamp_s = std::nan(""));

 private:
  cv::Mat previous_;
  double previous_time_ = std::nan("");
};

/// A video decoded with FFmpeg's libraries (libavformat, libavcodec, libswscale) on the calling
/// thread, with each frame's integrity. Decoding is single-threaded on purpose: then every
/// error the decoder reports belongs to the packet being decoded, and a frame handed out before
/// that error was decoded before the damaged packet and cannot depend on it (with frame threads
/// a frame can come out while an earlier packet it references is still being decoded, so damage
/// showed up several frames before its error). A frame is damaged when the decoder reported an
/// error or concealed part of it, and so is every later frame until a key frame decoded cleanly
/// (a damaged picture is the reference of those that follow it, up to the next key frame).
class VideoReader {
 public:
  /// Throws std::invalid_argument "cannot open PATH as a video (REASON)" (one line).
  explicit VideoReader(const std::string& path);
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;
  VideoReader(VideoReader&&) noexcept;
  VideoReader& operator=(VideoReader&&) noexcept;

  struct Frame {
    cv::Mat image;  ///< BGR; empty when unreadable
    FrameIntegrity integrity = FrameIntegrity::kIntact;
    double timestamp_s = 0;   ///< the stream's presentation time (NaN if unknown)
    long decoder_errors = 0;  ///< errors the decoder logged since the previous frame was read
  };
  /// The next frame in presentation order; false after the last. Every packet of the video
  /// stream is one frame: a packet that decodes to nothing is returned in its place as
  /// kUnreadable instead of shifting the frames after it.
  bool read(Frame& frame);

  /// Frames: the video stream's packets, or the number its container announces if that is
  /// more (a file cut short).
  long frame_count() const;
  double fps() const;       ///< the stream's average frame rate (0 if unknown)
  long key_frames() const;  ///< key-frame packets

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace flatland::vision
