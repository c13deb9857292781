// Reading real footage frame by frame, and saying which frames can be trusted: a decoder that
// meets a damaged stream conceals the damage (it repeats or patches earlier pictures) and
// OpenCV hands those frames over as if they were fine. docs/VISION.md ("Frame integrity").
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <cmath>
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

/// A video read through OpenCV's FFmpeg backend, with each frame's integrity. A frame is damaged
/// when FFmpeg logs a decoding error while it is read, and so is every later frame until a key
/// frame at least `kDamageMargin` frames after the last error (a damaged picture is the reference
/// of the ones that follow it, up to the next key frame; the margin covers FFmpeg's frame-threaded
/// decoding, which logs a frame's errors up to a thread count of reads before it is returned). In
/// an intra-only stream (every frame a key frame: MJPEG, which FFmpeg 5.1 decodes without frame
/// threads) only the frames with errors are damaged.
class VideoReader {
 public:
  static constexpr long kDamageMargin = 16;

  /// Throws std::invalid_argument "cannot open PATH as a video" (one line).
  explicit VideoReader(const std::string& path);

  struct Frame {
    cv::Mat image;  ///< BGR; empty when unreadable
    FrameIntegrity integrity = FrameIntegrity::kIntact;
    double timestamp_s = 0;   ///< the stream's presentation time (NaN if unknown)
    long decoder_errors = 0;  ///< errors FFmpeg logged since the previous frame was read
  };
  /// The next frame; false after the last. Within the announced frame count a frame that cannot
  /// be decoded is returned as kUnreadable instead of ending the video.
  bool read(Frame& frame);

  long frame_count() const { return total_; }
  double fps() const { return fps_; }
  long key_frames() const;

 private:
  cv::VideoCapture video_;
  std::vector<bool> key_;  ///< per packet (decode order; the stream's key frames)
  long total_ = 0, index_ = 0;
  double fps_ = 0;
  long errors_seen_ = 0;  ///< FFmpeg's error count at the last read
  long last_error_ = -1;  ///< index of the last frame read with a decoder error
  bool damaged_ = false;
  bool intra_only_ = false;  ///< every packet a key frame: damage does not propagate
  RepeatCheck repeat_;
};

}  // namespace flatland::vision
