// Video frames with their integrity (see video_reader.hpp), decoded with FFmpeg's libraries.
#include "flatland/vision/video_reader.hpp"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libavutil/log.h>
#include <libswscale/swscale.h>
}

#include <algorithm>
#include <cstdlib>
#include <deque>
#include <limits>
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

// FFmpeg's log, counted per thread: every message at AV_LOG_ERROR or worse is a decoding error
// of the reader decoding on that thread (decoding is single-threaded, so a reader's errors are
// logged on the thread that calls read()). A message is forwarded to FFmpeg's own printer only at
// the level the user asked for with OPENCV_FFMPEG_LOGLEVEL (the variable OpenCV's own FFmpeg
// backend reads): flatland keeps FFmpeg quiet otherwise, since its lines break the one-line error
// contract and say less than flatland's per-frame flags.
thread_local long t_decoder_errors = 0;
int g_forward_level = AV_LOG_QUIET;

void count_errors(void* avcl, int level, const char* fmt, va_list args) {
  if (level <= AV_LOG_ERROR) ++t_decoder_errors;
  if (level <= g_forward_level) av_log_default_callback(avcl, level, fmt, args);
}

void install_counter() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (const char* level = std::getenv("OPENCV_FFMPEG_LOGLEVEL"))
      g_forward_level = std::atoi(level);
    // Keeps OpenCV's own FFmpeg backend quiet too, where a program also opens videos with it.
    ::setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", 0);
  });
  // Every time: OpenCV's video backend installs a callback of its own when it opens a file.
  av_log_set_callback(count_errors);
}

std::string av_error(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, text, sizeof text);
  return text;
}

struct FormatCloser {
  void operator()(AVFormatContext* f) const { avformat_close_input(&f); }
};
using FormatPtr = std::unique_ptr<AVFormatContext, FormatCloser>;

FormatPtr open_format(const std::string& path) {
  AVFormatContext* raw = nullptr;
  const int err = avformat_open_input(&raw, path.c_str(), nullptr, nullptr);
  if (err < 0)
    throw std::invalid_argument("cannot open " + path + " as a video (" + av_error(err) + ")");
  FormatPtr fmt(raw);
  if (const int e = avformat_find_stream_info(fmt.get(), nullptr); e < 0)
    throw std::invalid_argument("cannot open " + path + " as a video (" + av_error(e) + ")");
  return fmt;
}

int video_stream(AVFormatContext* fmt, const std::string& path) {
  const int s = av_find_best_stream(fmt, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
  if (s < 0) throw std::invalid_argument("cannot open " + path + " as a video (no video stream)");
  return s;
}

// One decoding pass over a video's stream on the calling thread: packets go in in decode
// order, frames come out in presentation order.
class Decoding {
 public:
  explicit Decoding(const std::string& path) : format_(open_format(path)) {
    stream_ = video_stream(format_.get(), path);
    const AVStream* st = format_->streams[stream_];
    const AVCodec* codec = avcodec_find_decoder(st->codecpar->codec_id);
    if (!codec)
      throw std::invalid_argument("cannot open " + path + " as a video (no decoder for its codec)");
    decoder_ = avcodec_alloc_context3(codec);
    packet_ = av_packet_alloc();
    frame_ = av_frame_alloc();
    if (!decoder_ || !packet_ || !frame_ ||
        avcodec_parameters_to_context(decoder_, st->codecpar) < 0)
      throw std::runtime_error("cannot set up a decoder for " + path);
    decoder_->thread_count = 1;  // errors belong to the packet being decoded (see the header)
    decoder_->pkt_timebase = st->time_base;
    if (const int e = avcodec_open2(decoder_, codec, nullptr); e < 0)
      throw std::invalid_argument("cannot open " + path + " as a video (" + av_error(e) + ")");
  }
  Decoding(const Decoding&) = delete;
  Decoding& operator=(const Decoding&) = delete;

  const AVStream& stream() const { return *format_->streams[stream_]; }

  /// The next decoded frame (valid until the next call), or nullptr when the decoder needs a
  /// packet first (or has nothing more: then finished()).
  const AVFrame* receive() {
    av_frame_unref(frame_);
    const int r = avcodec_receive_frame(decoder_, frame_);
    if (r == AVERROR_EOF) finished_ = true;
    if (r == 0) return frame_;
    if (r != AVERROR(EAGAIN) && r != AVERROR_EOF) ++t_decoder_errors;  // an error, no frame
    return nullptr;
  }

  struct Sent {
    int64_t pts = AV_NOPTS_VALUE;
    bool key = false;
  };
  /// Send the stream's next packet to the decoder (after the last, the flush); false when there
  /// is nothing left to send. Call receive() until it returns nullptr before each send.
  bool send(Sent& sent) {
    if (flushed_) return false;
    for (;;) {
      if (av_read_frame(format_.get(), packet_) < 0) {
        avcodec_send_packet(decoder_, nullptr);  // flush: the decoder hands out what it holds
        flushed_ = true;
        return true;
      }
      if (packet_->stream_index != stream_) {
        av_packet_unref(packet_);
        continue;
      }
      sent.pts = packet_->pts;
      sent.key = (packet_->flags & AV_PKT_FLAG_KEY) != 0;
      const int r = avcodec_send_packet(decoder_, packet_);
      if (r < 0 && r != AVERROR(EAGAIN)) ++t_decoder_errors;  // rejected: a damaged packet
      av_packet_unref(packet_);
      ++sent_;
      return true;
    }
  }
  bool flushed() const { return flushed_; }
  bool finished() const { return finished_; }

 private:
  FormatPtr format_;
  int stream_ = -1;
  // Freed also when the constructor throws after allocating them (a member, not the body).
  struct Owned {
    AVCodecContext* decoder = nullptr;
    AVPacket* packet = nullptr;
    AVFrame* frame = nullptr;
    ~Owned() {
      av_frame_free(&frame);
      av_packet_free(&packet);
      avcodec_free_context(&decoder);
    }
  } own_;
  AVCodecContext*& decoder_ = own_.decoder;
  AVPacket*& packet_ = own_.packet;
  AVFrame*& frame_ = own_.frame;
  long sent_ = 0;
  bool flushed_ = false, finished_ = false;
};

bool concealed(const AVFrame* f) {
  return f->decode_error_flags != 0 || (f->flags & AV_FRAME_FLAG_CORRUPT) != 0;
}

}  // namespace

struct VideoReader::Impl {
  std::unique_ptr<Decoding> decoding;
  SwsContext* scaler = nullptr;
  AVRational time_base{0, 1};
  int64_t start_pts = AV_NOPTS_VALUE;
  double fps = 0;
  long keys = 0;
  long total = 0;
  /// Every packet's presentation time, sorted: a decoded frame's place in the video. Empty when
  /// some packet has none (frames are then numbered in the order they come out).
  std::vector<int64_t> display_pts;
  /// Per frame (presentation order): reached by damage, as the scan of the whole stream found.
  std::vector<bool> damaged;

  struct Decoded {
    long index = 0;
    cv::Mat image;
    bool concealed = false;  ///< the decoder flagged this frame as patched or corrupt
    double timestamp_s = std::nan("");
  };
  std::deque<Decoded> pending;  ///< decoded, not handed out yet (presentation order)
  long next_index = 0;          ///< the frame read() hands out next
  long next_sequential = 0;     ///< numbering when display_pts is empty
  RepeatCheck repeat;

  ~Impl() { sws_freeContext(scaler); }

  long index_of(int64_t pts, long& sequential) const {
    if (display_pts.empty() || pts == AV_NOPTS_VALUE) return sequential++;
    const auto it = std::lower_bound(display_pts.begin(), display_pts.end(), pts);
    if (it == display_pts.end() || *it != pts) return sequential++;
    const long i = static_cast<long>(it - display_pts.begin());
    sequential = i + 1;
    return i;
  }

  void scan(const std::string& path);

  cv::Mat to_bgr(const AVFrame* f) {
    scaler = sws_getCachedContext(scaler, f->width, f->height,
                                  static_cast<AVPixelFormat>(f->format), f->width, f->height,
                                  AV_PIX_FMT_BGR24, SWS_BICUBIC, nullptr, nullptr, nullptr);
    if (!scaler) return {};
    cv::Mat bgr(f->height, f->width, CV_8UC3);
    uint8_t* dst[4] = {bgr.data, nullptr, nullptr, nullptr};
    int dst_stride[4] = {static_cast<int>(bgr.step[0]), 0, 0, 0};
    sws_scale(scaler, f->data, f->linesize, 0, f->height, dst, dst_stride);
    return bgr;
  }

  void take_frames() {
    while (const AVFrame* f = decoding->receive()) {
      Decoded d;
      d.index = index_of(f->best_effort_timestamp, next_sequential);
      if (d.index < next_index) continue;  // out of order after damage: its place has passed
      d.image = to_bgr(f);
      d.concealed = concealed(f);
      if (f->best_effort_timestamp != AV_NOPTS_VALUE) {
        const int64_t start = start_pts == AV_NOPTS_VALUE ? 0 : start_pts;
        d.timestamp_s = static_cast<double>(f->best_effort_timestamp - start) * av_q2d(time_base);
      }
      const auto at = std::upper_bound(pending.begin(), pending.end(), d.index,
                                       [](long i, const Decoded& p) { return i < p.index; });
      pending.insert(at, std::move(d));
    }
  }

  /// Decode until a frame at or after next_index is pending, or nothing is left.
  void fill() {
    for (;;) {
      while (!pending.empty() && pending.front().index < next_index) pending.pop_front();
      if (!pending.empty() || decoding->finished()) return;
      take_frames();
      if (!pending.empty() || decoding->finished()) continue;
      Decoding::Sent sent;
      if (!decoding->send(sent)) return;  // flushed, and nothing more came out
    }
  }
};

// The first pass: decode the whole stream once and find every frame that damage reached.
// Which packet a damage starts in is not always the one the decoder complains about: a flipped
// bit can decode silently into wrong pixels and desynchronise the decoder only a few packets
// later (seen: a P frame patched without a word, its error logged at the next packet, and the B
// frame before it, which references it, already wrong). So an error condemns every frame decoded
// since the last key frame (any of them may hold the silent start), and every frame decoded
// after it until a key frame decodes cleanly.
void VideoReader::Impl::scan(const std::string& path) {
  Decoding pass(path);
  struct Packet {
    int64_t pts = AV_NOPTS_VALUE;
    bool key = false;
    long errors = 0;
  };
  std::vector<Packet> packets;  // decode order
  std::vector<int64_t> all_pts;
  std::vector<std::pair<int64_t, bool>> frames;  // pts, concealed (presentation order)
  bool have_all_pts = true;
  t_decoder_errors = 0;
  for (;;) {
    while (const AVFrame* f = pass.receive())
      frames.emplace_back(f->best_effort_timestamp, concealed(f));
    if (!packets.empty()) packets.back().errors += t_decoder_errors;
    t_decoder_errors = 0;
    if (pass.finished()) break;
    Decoding::Sent sent;
    if (!pass.send(sent)) break;
    if (pass.flushed()) continue;
    packets.push_back({sent.pts, sent.key, t_decoder_errors});
    t_decoder_errors = 0;
    if (sent.pts == AV_NOPTS_VALUE)
      have_all_pts = false;
    else
      all_pts.push_back(sent.pts);
  }
  if (!packets.empty()) packets.back().errors += t_decoder_errors;
  t_decoder_errors = 0;

  total = static_cast<long>(packets.size());
  for (const Packet& p : packets) keys += p.key;
  std::sort(all_pts.begin(), all_pts.end());
  if (have_all_pts && std::adjacent_find(all_pts.begin(), all_pts.end()) == all_pts.end())
    display_pts = std::move(all_pts);

  // Where each packet's frame stands, whether it came out and whether it came out patched.
  const long n = total;
  std::vector<bool> decoded(static_cast<std::size_t>(n), false), patched(decoded);
  long sequential = 0;
  for (const auto& [pts, bad] : frames) {
    const long i = index_of(pts, sequential);
    if (i < 0 || i >= n) continue;
    decoded[static_cast<std::size_t>(i)] = true;
    if (bad) patched[static_cast<std::size_t>(i)] = true;
  }
  auto place = [&](long d) {
    const Packet& p = packets[static_cast<std::size_t>(d)];
    if (display_pts.empty() || p.pts == AV_NOPTS_VALUE) return d;  // decode order = shown order
    return static_cast<long>(std::lower_bound(display_pts.begin(), display_pts.end(), p.pts) -
                             display_pts.begin());
  };
  damaged.assign(static_cast<std::size_t>(n), false);
  // Without presentation times a packet's place is its decode order, which differs from the
  // order frames come out by at most the decoder's reordering (16 frames in H.264): a damage then
  // marks that many frames on either side too.
  const long margin = display_pts.empty() ? 16 : 0;
  auto mark = [&](long i) {
    for (long k = std::max(0L, i - margin); k <= std::min(n - 1, i + margin); ++k)
      damaged[static_cast<std::size_t>(k)] = true;
  };
  const bool intra_only = keys == n;
  long gop_start = 0, previous_gop_start = 0;
  bool reached = false;
  // The last clean key frame that ended a damage: frames decoded after it but shown before it
  // (an open GOP's leading pictures) still reference the damaged group.
  long recovered_at = -1;
  for (long d = 0; d < n; ++d) {
    const Packet& p = packets[static_cast<std::size_t>(d)];
    const long i = place(d);
    const bool bad = p.errors > 0 || !decoded[static_cast<std::size_t>(i)] ||
                     patched[static_cast<std::size_t>(i)];
    if (p.key) {
      previous_gop_start = gop_start;
      gop_start = d;
      if (!bad && reached) {
        reached = false;
        recovered_at = i;
      }
    }
    if (bad) {
      // An error found at a key frame may belong to the group before it (the decoder notices a
      // damage a packet late): condemn that group too, unless every frame is a key frame (an
      // intra-only stream, MJPEG: no frame depends on another, so a damage ends with its frame).
      const bool late = p.key && !intra_only;
      for (long e = late ? previous_gop_start : gop_start; e <= d; ++e) mark(place(e));
      reached = true;
      recovered_at = -1;
    } else if (reached || (recovered_at >= 0 && i < recovered_at)) {
      mark(i);
    }
  }
}

VideoReader::VideoReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  install_counter();
  Impl& m = *impl_;
  m.scan(path);
  m.decoding = std::make_unique<Decoding>(path);
  const AVStream& st = m.decoding->stream();
  // A container that announces more frames than it holds packets (a file cut short) has lost
  // the rest: they are read as unreadable, not silently dropped.
  m.total = std::max(m.total, static_cast<long>(std::max<int64_t>(0, st.nb_frames)));
  m.damaged.resize(static_cast<std::size_t>(m.total), true);
  m.time_base = st.time_base;
  m.start_pts = st.start_time;
  const AVRational rate = st.avg_frame_rate.num > 0 ? st.avg_frame_rate : st.r_frame_rate;
  m.fps = rate.num > 0 && rate.den > 0 ? av_q2d(rate) : 0;
  t_decoder_errors = 0;
}

VideoReader::~VideoReader() = default;
VideoReader::VideoReader(VideoReader&&) noexcept = default;
VideoReader& VideoReader::operator=(VideoReader&&) noexcept = default;

long VideoReader::frame_count() const { return impl_->total; }
double VideoReader::fps() const { return impl_->fps; }
long VideoReader::key_frames() const { return impl_->keys; }

bool VideoReader::read(Frame& frame) {
  frame = Frame{};
  Impl& m = *impl_;
  if (m.next_index >= m.total) return false;
  av_log_set_callback(count_errors);
  m.fill();
  frame.decoder_errors = t_decoder_errors;
  t_decoder_errors = 0;
  const long i = m.next_index++;
  if (m.pending.empty() || m.pending.front().index != i || m.pending.front().image.empty()) {
    // This packet decoded to nothing (or is missing): a frame of its own, so that the frames
    // after it keep their places.
    if (!m.pending.empty() && m.pending.front().index == i) m.pending.pop_front();
    frame.integrity = FrameIntegrity::kUnreadable;
    frame.timestamp_s = std::nan("");
    return true;
  }
  Impl::Decoded d = std::move(m.pending.front());
  m.pending.pop_front();
  frame.image = std::move(d.image);
  frame.timestamp_s = d.timestamp_s;
  const bool damaged = m.damaged[static_cast<std::size_t>(i)] || d.concealed;
  const bool repeated = m.repeat.repeated(frame.image, frame.timestamp_s);
  frame.integrity = damaged    ? FrameIntegrity::kDamaged
                    : repeated ? FrameIntegrity::kRepeated
                               : FrameIntegrity::kIntact;
  return true;
}

}  // namespace flatland::vision
