// MP4 output through libavformat/libavcodec (video_writer.hpp).
#include "flatland/render/video_writer.hpp"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/log.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <stdexcept>

namespace flatland::render {

namespace {

std::string av_error(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, text, sizeof text);
  return text;
}

}  // namespace

struct Mp4Writer::Impl {
  std::string path;
  AVFormatContext* format = nullptr;
  AVStream* stream = nullptr;
  AVCodecContext* encoder = nullptr;
  SwsContext* scaler = nullptr;
  AVFrame* yuv = nullptr;
  AVPacket* packet = nullptr;
  cv::Size size;
  long frames = 0, keys = 0;
  bool header_written = false;

  ~Impl() { close(); }

  void close() {
    if (format && format->pb) avio_closep(&format->pb);
    avformat_free_context(format);
    format = nullptr;
    stream = nullptr;
    avcodec_free_context(&encoder);
    sws_freeContext(scaler);
    scaler = nullptr;
    av_frame_free(&yuv);
    av_packet_free(&packet);
    header_written = false;
  }

  [[noreturn]] void fail(const std::string& what) {
    const std::string message = path + ": " + what;
    close();
    throw std::runtime_error(message);
  }

  /// Send a frame (nullptr: flush) and write the packets that come out.
  void encode(const AVFrame* frame) {
    if (const int e = avcodec_send_frame(encoder, frame); e < 0)
      fail("cannot encode a frame (" + av_error(e) + ")");
    for (;;) {
      const int r = avcodec_receive_packet(encoder, packet);
      if (r == AVERROR(EAGAIN) || r == AVERROR_EOF) return;
      if (r < 0) fail("cannot encode a frame (" + av_error(r) + ")");
      keys += (packet->flags & AV_PKT_FLAG_KEY) != 0;
      av_packet_rescale_ts(packet, encoder->time_base, stream->time_base);
      packet->stream_index = stream->index;
      if (const int w = av_interleaved_write_frame(format, packet); w < 0)
        fail("cannot write the video (" + av_error(w) + ")");
    }
  }

  /// An encoder for `codec` set up for this file, or nullptr if it cannot be opened.
  AVCodecContext* open_encoder(const AVCodec* codec, double fps) {
    AVCodecContext* c = avcodec_alloc_context3(codec);
    if (!c) return nullptr;
    c->width = size.width;
    c->height = size.height;
    c->pix_fmt = AV_PIX_FMT_YUV420P;
    c->framerate = av_d2q(fps, 100000);
    c->time_base = av_inv_q(c->framerate);
    c->gop_size = std::max(1, static_cast<int>(std::lround(fps * kKeyFrameInterval)));
    if (format->oformat->flags & AVFMT_GLOBALHEADER) c->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
    if (codec->id == AV_CODEC_ID_H264) {
      // OpenCV's writer's choice (CRF 23, x264's default preset), so that the rendered videos
      // look as they did; only the key frames are new.
      av_opt_set(c->priv_data, "crf", "23", 0);
    } else {
      c->bit_rate = static_cast<int64_t>(std::min(fps * size.area(), 1e9));  // OpenCV's, too
    }
    if (avcodec_open2(c, codec, nullptr) < 0) avcodec_free_context(&c);
    return c;
  }
};

Mp4Writer::Mp4Writer() : impl_(std::make_unique<Impl>()) {}
Mp4Writer::~Mp4Writer() = default;

bool Mp4Writer::isOpened() const { return impl_->header_written; }
long Mp4Writer::frames() const { return impl_->frames; }
long Mp4Writer::key_frames() const { return impl_->keys; }

std::string Mp4Writer::open(const std::string& path, double fps, cv::Size size,
                            const std::string& what, const std::string& hint) {
  Impl& m = *impl_;
  m.close();
  m.path = path;
  m.size = size;
  m.frames = m.keys = 0;
  if (!(fps > 0) || !std::isfinite(fps) || size.width <= 0 || size.height <= 0)
    throw std::runtime_error(what + "frames of " + std::to_string(size.width) + "x" +
                             std::to_string(size.height) + " px at " + std::to_string(fps) +
                             " fps cannot be encoded");
  // x264 reports its settings at AV_LOG_INFO on every open: flatland keeps FFmpeg to errors.
  if (av_log_get_level() > AV_LOG_ERROR) av_log_set_level(AV_LOG_ERROR);
  if (avformat_alloc_output_context2(&m.format, nullptr, "mp4", path.c_str()) < 0 || !m.format)
    throw std::runtime_error(what + "cannot set up an MP4 file");
  std::string fourcc;
  const bool odd = size.width % 2 != 0 || size.height % 2 != 0;
  for (const auto& [name, tag] : {std::pair{"libx264", "avc1"}, std::pair{"mpeg4", "mp4v"}}) {
    if (const AVCodec* codec = avcodec_find_encoder_by_name(name))
      m.encoder = m.open_encoder(codec, fps);
    if (m.encoder) {
      fourcc = tag;
      break;
    }
    if (fourcc.empty() && std::string(name) == "libx264")
      std::cerr << "flatland: cannot open an H.264 (libx264) encoder for " << size.width << "x"
                << size.height << " frames" << (odd ? " (it needs an even width and height)" : "")
                << "; falling back to MPEG-4 part 2 (mp4v)\n";
  }
  if (!m.encoder) {
    m.close();
    throw std::runtime_error(
        what + "neither H.264 (libx264) nor MPEG-4 part 2 can be encoded by this FFmpeg" +
        (odd ? " at " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                   " px (both need an even width and height)"
             : std::string(" (Debian: libavcodec59 with libx264)")) +
        hint);
  }
  m.stream = avformat_new_stream(m.format, nullptr);
  m.packet = av_packet_alloc();
  m.yuv = av_frame_alloc();
  if (!m.stream || !m.packet || !m.yuv) m.fail("out of memory");
  avcodec_parameters_from_context(m.stream->codecpar, m.encoder);
  m.stream->time_base = m.encoder->time_base;
  m.stream->avg_frame_rate = m.encoder->framerate;
  m.yuv->format = AV_PIX_FMT_YUV420P;
  m.yuv->width = size.width;
  m.yuv->height = size.height;
  if (av_frame_get_buffer(m.yuv, 0) < 0) m.fail("out of memory");
  if (const int e = avio_open(&m.format->pb, path.c_str(), AVIO_FLAG_WRITE); e < 0) {
    m.close();
    throw std::runtime_error(what + "cannot create " + path + " (" + av_error(e) + ")");
  }
  if (const int e = avformat_write_header(m.format, nullptr); e < 0)
    m.fail("cannot write the MP4 header (" + av_error(e) + ")");
  m.header_written = true;
  return fourcc;
}

void Mp4Writer::write(const cv::Mat& image) {
  Impl& m = *impl_;
  if (!m.header_written) throw std::logic_error("Mp4Writer::write on a writer that is not open");
  if (image.size() != m.size || image.depth() != CV_8U ||
      (image.channels() != 3 && image.channels() != 1))
    throw std::invalid_argument(m.path + ": a frame of " + std::to_string(image.cols) + "x" +
                                std::to_string(image.rows) + " px (8-bit BGR or grey " +
                                std::to_string(m.size.width) + "x" + std::to_string(m.size.height) +
                                " expected)");
  cv::Mat bgr = image;
  if (image.channels() == 1) cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  if (!bgr.isContinuous()) bgr = bgr.clone();
  m.scaler = sws_getCachedContext(m.scaler, m.size.width, m.size.height, AV_PIX_FMT_BGR24,
                                  m.size.width, m.size.height, AV_PIX_FMT_YUV420P, SWS_BICUBIC,
                                  nullptr, nullptr, nullptr);
  if (!m.scaler || av_frame_make_writable(m.yuv) < 0) m.fail("cannot convert a frame");
  const uint8_t* src[4] = {bgr.data, nullptr, nullptr, nullptr};
  const int src_stride[4] = {static_cast<int>(bgr.step[0]), 0, 0, 0};
  sws_scale(m.scaler, src, src_stride, 0, m.size.height, m.yuv->data, m.yuv->linesize);
  m.yuv->pts = m.frames++;
  m.encode(m.yuv);
}

void Mp4Writer::release() {
  Impl& m = *impl_;
  if (!m.header_written) return;
  m.encode(nullptr);
  if (const int e = av_write_trailer(m.format); e < 0)
    m.fail("cannot finish the MP4 file (" + av_error(e) + ")");
  if (const int e = avio_closep(&m.format->pb); e < 0)
    m.fail("cannot close the MP4 file (" + av_error(e) + ")");
  m.close();
}

std::string open_mp4(Mp4Writer& writer, const std::string& path, double fps, cv::Size size,
                     const std::string& what, const std::string& hint) {
  return writer.open(path, fps, size, what, hint);
}

}  // namespace flatland::render
