// Video frames with their integrity (see video_reader.hpp).
#include "flatland/vision/video_reader.hpp"

extern "C" {
#include <libavutil/log.h>
}

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <stdexcept>

namespace flatland::vision {

const char* to_string(FrameIntegrity integrity) {
  switch (integrity) {
    case FrameIntegrity::kIntact:
      return "intact";
    case FrameIntegrity::kRepeated:
      return "repeated";
    case FrameIntegrity::kDamaged:
      return "damaged";
    case FrameIntegrity::kUnreadable:
      return "unreadable";
  }
  return "?";
}

bool RepeatCheck::repeated(const cv::Mat& image, double timestamp_s) {
  bool same = false;
  if (!previous_.empty() && previous_.size() == image.size() && previous_.type() == image.type()) {
    cv::Mat diff;
    cv::absdiff(image, previous_, diff);
    const cv::Scalar m = cv::mean(diff);
    double mean = 0;
    for (int c = 0; c < image.channels(); ++c) mean += m[c] / image.channels();
    same = mean < kMaxMeanDifference;
  }
  const bool stale = std::isfinite(timestamp_s) && std::isfinite(previous_time_) &&
                     !(timestamp_s > previous_time_);
  previous_ = image.clone();
  if (std::isfinite(timestamp_s)) previous_time_ = timestamp_s;
  return same || stale;
}

namespace {

// FFmpeg's log, counted: every message at AV_LOG_ERROR or worse is a decoding error. It is
// forwarded to FFmpeg's own printer only at the level the user asked for with
// OPENCV_FFMPEG_LOGLEVEL (flatland keeps FFmpeg quiet otherwise: its lines break the one-line
// error contract and say less than flatland's per-frame flags).
std::atomic<long> g_decoder_errors{0};
int g_forward_level = AV_LOG_QUIET;

void count_errors(void* avcl, int level, const char* fmt, va_list args) {
  if (level <= AV_LOG_ERROR) g_decoder_errors.fetch_add(1, std::memory_order_relaxed);
  if (level <= g_forward_level) av_log_default_callback(avcl, level, fmt, args);
}

void install_counter() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (const char* level = std::getenv("OPENCV_FFMPEG_LOGLEVEL"))
      g_forward_level = std::atoi(level);
    // OpenCV installs its own callback when this is set (at its first open), which the counter
    // then replaces; set, it also keeps OpenCV from printing.
    ::setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", 0);
  });
}

}  // namespace

VideoReader::VideoReader(const std::string& path) {
  install_counter();
  // FFmpeg only: CAP_ANY would also try GStreamer, the image-sequence and the built-in MJPEG
  // readers, which print multi-line errors of their own for a file they cannot read.
  try {
    video_.open(path, cv::CAP_FFMPEG);
  } catch (const cv::Exception&) {
    video_.release();
  }
  if (!video_.isOpened()) throw std::invalid_argument("cannot open " + path + " as a video");
  total_ = std::max(0L, static_cast<long>(video_.get(cv::CAP_PROP_FRAME_COUNT)));
  fps_ = video_.get(cv::CAP_PROP_FPS);
  // The key frames, from the packets: OpenCV's raw mode reads them undecoded.
  cv::VideoCapture packets;
  try {
    packets.open(path, cv::CAP_FFMPEG, {cv::CAP_PROP_FORMAT, -1});
    cv::Mat packet;
    while (packets.isOpened() && packets.read(packet) &&
           key_.size() < static_cast<std::size_t>(total_))
      key_.push_back(packets.get(cv::CAP_PROP_LRF_HAS_KEY_FRAME) != 0);
  } catch (const cv::Exception&) {
    // Without key frames a damage lasts to the end of the video: safe, if pessimistic.
  }
  intra_only_ = !key_.empty() && key_frames() == static_cast<long>(key_.size());
  // After both opens: OpenCV installs its own log callback when it opens a capture.
  av_log_set_callback(count_errors);
  errors_seen_ = g_decoder_errors.load();
}

long VideoReader::key_frames() const {
  long n = 0;
  for (bool k : key_) n += k;
  return n;
}

bool VideoReader::read(Frame& frame) {
  frame = Frame{};
  bool got = false;
  try {
    got = video_.read(frame.image);
  } catch (const cv::Exception&) {
    got = false;
  }
  // Counted since the last read, not since this one began: FFmpeg's decoder threads work (and
  // log) between reads too.
  const long errors = g_decoder_errors.load();
  frame.decoder_errors = errors - errors_seen_;
  errors_seen_ = errors;
  const long i = index_;
  if (!got || frame.image.empty()) {
    // FFmpeg reads on past a damaged frame, so within the announced frame count a failed read
    // stands for one frame instead of silently dropping the rest of the video.
    if (i >= total_) return false;
    ++index_;
    frame.image.release();
    frame.integrity = FrameIntegrity::kUnreadable;
    frame.timestamp_s = std::nan("");
    last_error_ = i;
    damaged_ = true;
    return true;
  }
  ++index_;
  const double ms = video_.get(cv::CAP_PROP_POS_MSEC);
  // OpenCV 4.6 reports 0 for the frames it drains from the decoder at the end of a stream: an
  // unknown time, not a step back.
  frame.timestamp_s = std::isfinite(ms) && (ms > 0 || i == 0) ? ms / 1000 : std::nan("");
  if (frame.decoder_errors > 0) {
    last_error_ = i;
    damaged_ = true;
  } else if (damaged_ && intra_only_) {
    damaged_ = false;  // every frame a key frame (MJPEG): a damage ends with its frame
  } else if (damaged_ && i < static_cast<long>(key_.size()) && key_[static_cast<std::size_t>(i)] &&
             i >= last_error_ + kDamageMargin) {
    damaged_ = false;  // a key frame far enough after the damage: decoded afresh
  }
  const bool repeated = repeat_.repeated(frame.image, frame.timestamp_s);
  frame.integrity = damaged_   ? FrameIntegrity::kDamaged
                    : repeated ? FrameIntegrity::kRepeated
                               : FrameIntegrity::kIntact;
  return true;
}

}  // namespace flatland::vision
