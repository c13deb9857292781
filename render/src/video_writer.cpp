#include "flatland/render/video_writer.hpp"

#include <iostream>
#include <stdexcept>

namespace flatland::render {

std::string open_mp4(cv::VideoWriter& writer, const std::string& path, double fps, cv::Size size,
                     const std::string& what, const std::string& hint) {
  for (const std::string fourcc : {"avc1", "mp4v"}) {
    writer.open(path, cv::CAP_FFMPEG,
                cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps, size,
                true);
    if (writer.isOpened()) return fourcc;
    if (fourcc == "avc1")
      std::cerr << "flatland: OpenCV's FFmpeg backend cannot encode H.264 (avc1) here; falling "
                   "back to MPEG-4 part 2 (mp4v)\n";
  }
  throw std::runtime_error(what +
                           "neither H.264 (avc1) nor MPEG-4 part 2 (mp4v) can be encoded through "
                           "OpenCV's FFmpeg backend (Debian: libavcodec59 with libx264)" +
                           hint);
}

}  // namespace flatland::render
