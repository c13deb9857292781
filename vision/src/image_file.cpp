// Damaged image files (image_file.hpp).
#include "flatland/vision/image_file.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <fstream>
#include <string_view>
#include <system_error>

namespace flatland::vision {

namespace fs = std::filesystem;

namespace {

std::uint32_t big_endian32(const unsigned char* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

}  // namespace

std::string image_file_problem(const fs::path& p) {
  std::error_code ec;
  const auto st = fs::status(p, ec);
  if (!fs::exists(st)) return "missing image file";
  if (!fs::is_regular_file(st)) return "not a regular file";
  const auto size = fs::file_size(p, ec);
  if (ec) return "cannot read the file size (" + ec.message() + ")";
  if (size == 0) return "zero-length file";
  std::ifstream f(p, std::ios::binary);
  if (!f) return "unreadable image file";
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".png") {
    static constexpr unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    unsigned char sig[8];
    if (!f.read(reinterpret_cast<char*>(sig), 8) || !std::equal(sig, sig + 8, kSignature))
      return "not a PNG file (bad signature)";
    std::uintmax_t pos = 8;
    for (;;) {
      unsigned char head[8];
      if (pos + 8 > size || !f.seekg(static_cast<std::streamoff>(pos)) ||
          !f.read(reinterpret_cast<char*>(head), 8))
        return "truncated PNG (ends before its IEND chunk)";
      const std::uintmax_t length = big_endian32(head);
      const std::uintmax_t end = pos + 8 + length + 4;  // + CRC
      if (end > size) return "truncated PNG (ends inside a chunk)";
      if (std::string_view(reinterpret_cast<const char*>(head + 4), 4) == "IEND") return "";
      pos = end;
    }
  }
  if (ext == ".jpg" || ext == ".jpeg") {
    unsigned char soi[2];
    if (!f.read(reinterpret_cast<char*>(soi), 2) || soi[0] != 0xff || soi[1] != 0xd8)
      return "not a JPEG file (bad signature)";
    // The end-of-image marker closes the file, possibly followed by a little padding.
    const std::uintmax_t tail = std::min<std::uintmax_t>(size, 64);
    std::string buf(tail, '\0');
    if (!f.seekg(static_cast<std::streamoff>(size - tail)) || !f.read(buf.data(), tail))
      return "unreadable image file";
    if (buf.find("\xff\xd9") == std::string::npos) return "truncated JPEG (no end-of-image marker)";
  }
  return "";
}

cv::Mat read_image_file(const fs::path& path, int flags, std::string& why) {
  why = image_file_problem(path);
  if (!why.empty()) return {};
  cv::Mat image;
  try {
    image = cv::imread(path.string(), flags);
  } catch (const cv::Exception&) {
    image.release();  // OpenCV throws for some malformed headers instead of returning nothing
  }
  if (image.empty()) why = "cannot decode the image (corrupt or not an image format OpenCV reads)";
  return image;
}

}  // namespace flatland::vision
