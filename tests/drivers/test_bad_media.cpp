// Damaged and unusual image and video input: truncated PNG and JPEG, zero-length files, a corrupt
// or truncated AVI, and images of another bit depth or channel count. `flatland track` and
// `flatland calibrate` (run as the real binary) and drivers::RecordedCamera must skip what they
// cannot use with a warning naming the file, or reject it with one error line (exit 2, nothing
// written); never crash, and never half-decode a truncated file as if it were image content.
#include "cli_support.hpp"
#include "flatland/drivers/recorded.hpp"
#include "flatland/vision/image_file.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland_test::lines_of;
using flatland_test::read_text;
using flatland_test::write_text;

constexpr int kWidth = 64, kHeight = 48;

/// A bright disk on a dark table: what the tracker looks for, small enough to be quick.
cv::Mat disk_image(int shift = 0) {
  cv::Mat m(kHeight, kWidth, CV_8UC3, cv::Scalar::all(60));
  cv::circle(m, {30 + shift, 24}, 10, cv::Scalar::all(230), cv::FILLED, cv::LINE_AA);
  return m;
}

/// A chessboard of 10 x 7 squares (9 x 6 inner corners) with a white margin, seen straight on.
cv::Mat chessboard_image() {
  const int sq = 24, margin = 30;
  cv::Mat m(7 * sq + 2 * margin, 10 * sq + 2 * margin, CV_8UC1, cv::Scalar(255));
  for (int r = 0; r < 7; ++r)
    for (int c = 0; c < 10; ++c)
      if ((r + c) % 2 == 0)
        cv::rectangle(m, cv::Rect(margin + c * sq, margin + r * sq, sq, sq), cv::Scalar(0),
                      cv::FILLED);
  return m;
}

void truncate_to_half(const fs::path& p) { fs::resize_file(p, fs::file_size(p) / 2); }

/// Every stderr line is flatland's own: no libpng/libjpeg/FFmpeg/GStreamer chatter.
void expect_only_flatland_lines(const std::string& err) {
  for (const std::string& line : lines_of(err))
    EXPECT_EQ(line.rfind("flatland: ", 0), 0u) << "foreign stderr line: " << line;
}

class BadMedia : public flatland_test::CliTestBase {
 protected:
  void SetUp() override {
    CliTestBase::SetUp();
    write_text(dir_ / "camera.yaml",
               "image_width: 64\nimage_height: 48\ncamera_name: bad-media\n"
               "camera_matrix: {rows: 3, cols: 3, data: [80, 0, 31.5, 0, 80, 23.5, 0, 0, 1]}\n"
               "distortion_model: plumb_bob\n"
               "distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n");
  }

  /// An MJPG AVI of `n` disk frames: every frame is a JPEG of its own, so one can be damaged
  /// without touching the others. Empty path when this OpenCV cannot write it.
  fs::path make_mjpg(const std::string& name, int n) const {
    const fs::path video = dir_ / name;
    cv::VideoWriter w(video.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'),
                      30.0, cv::Size(kWidth, kHeight), true);
    if (!w.isOpened()) return {};
    for (int k = 0; k < n; ++k) w.write(disk_image(k % 5));
    return video;
  }

  nlohmann::json track_json(const std::string& input, flatland_test::Result& r) const {
    // --force: a test may track several inputs in turn into the same out.csv.
    r = run("track " + input + " --camera camera.yaml --out out.csv --force --json");
    if (r.code != 0) return {};
    return nlohmann::json::parse(r.out);
  }
};

TEST_F(BadMedia, TrackSkipsDamagedImagesAndReadsOtherDepthsAndChannelCounts) {
  fs::create_directories(dir_ / "f");
  // The disk moves from frame to frame: identical frames would be flagged as repeated.
  const cv::Mat img = disk_image();
  cv::imwrite((dir_ / "f/00-good.png").string(), img);
  cv::imwrite((dir_ / "f/01-truncated.png").string(), img);
  truncate_to_half(dir_ / "f/01-truncated.png");
  cv::imwrite((dir_ / "f/02-truncated.jpg").string(), img);
  truncate_to_half(dir_ / "f/02-truncated.jpg");
  write_text(dir_ / "f/03-empty.png", "");
  cv::Mat deep;
  disk_image(1).convertTo(deep, CV_16UC3, 257.0);
  cv::imwrite((dir_ / "f/04-16bit.png").string(), deep);
  cv::Mat grey, rgba;
  cv::cvtColor(disk_image(2), grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(disk_image(3), rgba, cv::COLOR_BGR2BGRA);
  cv::imwrite((dir_ / "f/05-grey.png").string(), grey);
  cv::imwrite((dir_ / "f/06-rgba.png").string(), rgba);
  cv::imwrite((dir_ / "f/07-good.jpg").string(), disk_image(4));
  write_text(dir_ / "f/08-garbage.png", std::string("\x89PNG\r\n\x1a\n", 8) + "garbage");
  write_text(dir_ / "f/09-text.tif", "not a tiff");
  fs::create_directory(dir_ / "f/10-dir.png");

  flatland_test::Result r;
  const nlohmann::json j = track_json("--images 'f/*'", r);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(j["frames"], 5);
  EXPECT_EQ(j["found"], 5) << "16-bit, grey and RGBA frames are tracked like the 8-bit ones";
  EXPECT_EQ(j["skipped"], 6);
  for (const auto& [file, why] :
       std::vector<std::pair<std::string, std::string>>{{"f/01-truncated.png", "truncated PNG"},
                                                        {"f/02-truncated.jpg", "truncated JPEG"},
                                                        {"f/03-empty.png", "zero-length file"},
                                                        {"f/08-garbage.png", "truncated PNG"},
                                                        {"f/09-text.tif", "cannot decode"},
                                                        {"f/10-dir.png", "not a regular file"}})
    EXPECT_NE(r.err.find("flatland: warning: skipping unreadable image " + file + " (" + why),
              std::string::npos)
        << file << ": " << r.err;
  expect_only_flatland_lines(r.err);
  // Every file has its row; the unreadable ones say so and carry no measurement.
  std::vector<int> measured, unreadable;
  const auto rows = lines_of(read_text(dir_ / "out.csv"));
  ASSERT_EQ(rows.size(), 12u);
  for (std::size_t i = 1; i < rows.size(); ++i)
    (rows[i].find(",unreadable,") != std::string::npos ? unreadable : measured)
        .push_back(std::stoi(rows[i]));
  EXPECT_EQ(measured, (std::vector<int>{0, 4, 5, 6, 7}));
  EXPECT_EQ(unreadable, (std::vector<int>{1, 2, 3, 8, 9, 10}));
}

TEST_F(BadMedia, TrackWithNoUsableImageExitsTwoAndWritesNothing) {
  fs::create_directories(dir_ / "f");
  cv::imwrite((dir_ / "f/a.png").string(), disk_image());
  truncate_to_half(dir_ / "f/a.png");
  write_text(dir_ / "f/b.jpg", "");
  const flatland_test::Result r = run("track --images 'f/*' --camera camera.yaml --out out.csv");
  EXPECT_EQ(r.code, 2) << r.err;
  const auto lines = lines_of(r.err);
  ASSERT_EQ(lines.size(), 3u) << r.err;  // two warnings, one error
  EXPECT_EQ(lines.back(), "flatland: error: --images: f/*: no readable frame");
  EXPECT_FALSE(fs::exists(dir_ / "out.csv"));
}

TEST_F(BadMedia, TrackRejectsUnreadableVideosWithOneLine) {
  const fs::path good = make_mjpg("good.avi", 10);
  if (good.empty()) GTEST_SKIP() << "this OpenCV cannot write MJPG";
  const std::string data = read_text(good);
  write_text(dir_ / "empty.avi", "");
  std::string junk(4096, '\0');
  for (std::size_t i = 0; i < junk.size(); ++i) junk[i] = static_cast<char>((i * 7919) % 251);
  write_text(dir_ / "junk.avi", junk);
  write_text(dir_ / "header-only.avi", data.substr(0, 300));
  fs::create_directory(dir_ / "dir.avi");
  for (const auto& [file, why] : std::vector<std::pair<std::string, std::string>>{
           {"empty.avi", "--video: empty.avi: zero-length file"},
           {"junk.avi", "--video: cannot open junk.avi as a video"},
           {"header-only.avi", "header-only.avi"},
           {"dir.avi", "--video: no such file: dir.avi"},
           {"missing.avi", "--video: no such file: missing.avi"}}) {
    SCOPED_TRACE(file);
    const flatland_test::Result r =
        run("track --video " + file + " --camera camera.yaml --out out.csv");
    EXPECT_EQ(r.code, 2) << r.err;
    ASSERT_EQ(lines_of(r.err).size(), 1u) << r.err;
    EXPECT_EQ(r.err.rfind("flatland: error: ", 0), 0u) << r.err;
    EXPECT_NE(r.err.find(why), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir_ / "out.csv"));
  }
}

TEST_F(BadMedia, TrackSkipsDamagedVideoFramesAndReportsATruncatedVideo) {
  const fs::path video = make_mjpg("clip.avi", 10);
  if (video.empty()) GTEST_SKIP() << "this OpenCV cannot write MJPG";
  std::string data = read_text(video);
  // Wipe the start of the fifth JPEG (after its start-of-image marker): a damaged frame 4.
  std::size_t pos = 0;
  for (int n = 0; n < 5; ++n) {
    pos = data.find(std::string("\xff\xd8\xff", 3), n == 0 ? 0 : pos + 3);
    ASSERT_NE(pos, std::string::npos);
  }
  std::string damaged = data;
  std::fill(damaged.begin() + static_cast<long>(pos) + 2,
            damaged.begin() + static_cast<long>(pos) + 200, '\0');
  write_text(dir_ / "damaged.avi", damaged);
  flatland_test::Result r;
  nlohmann::json j = track_json("--video damaged.avi", r);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(j["frames"], 9) << "the frames after the damaged one are read";
  EXPECT_EQ(j["skipped"], 1);
  EXPECT_NE(r.err.find("flatland: warning: --video: damaged.avi: frame 4 cannot be decoded"),
            std::string::npos)
      << r.err;
  auto rows = lines_of(read_text(dir_ / "out.csv"));
  ASSERT_EQ(rows.size(), 11u);
  EXPECT_EQ(rows[5].rfind("4,", 0), 0u) << rows[5];
  EXPECT_NE(rows[5].find(",unreadable,"), std::string::npos) << rows[5];
  EXPECT_EQ(rows[6].find("damaged"), std::string::npos) << "an MJPEG frame does not depend on "
                                                           "the one before: "
                                                        << rows[6];

  // Cut at three quarters (AVI's index is at the end): the frames before the cut are tracked,
  // each lost one is reported.
  write_text(dir_ / "cut.avi", data.substr(0, data.size() * 3 / 4));
  j = track_json("--video cut.avi", r);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_GE(j["frames"].get<int>(), 1);
  EXPECT_GE(j["skipped"].get<int>(), 1);
  EXPECT_EQ(j["frames"].get<int>() + j["skipped"].get<int>(), 10) << r.err;
  EXPECT_NE(r.err.find("cannot be decoded; skipped"), std::string::npos) << r.err;
}

TEST_F(BadMedia, CalibrateSkipsDamagedImagesAndReadsOtherDepthsAndChannelCounts) {
  fs::create_directories(dir_ / "imgs");
  const cv::Mat board = chessboard_image();
  cv::Mat deep, rgba;
  board.convertTo(deep, CV_16UC1, 257.0);
  cv::cvtColor(board, rgba, cv::COLOR_GRAY2BGRA);
  cv::imwrite((dir_ / "imgs/a-16bit.png").string(), deep);
  cv::imwrite((dir_ / "imgs/b-rgba.png").string(), rgba);
  cv::imwrite((dir_ / "imgs/c-truncated.png").string(), board);
  truncate_to_half(dir_ / "imgs/c-truncated.png");
  cv::imwrite((dir_ / "imgs/d-truncated.jpg").string(), board);
  truncate_to_half(dir_ / "imgs/d-truncated.jpg");
  write_text(dir_ / "imgs/e-empty.png", "");
  cv::imwrite((dir_ / "imgs/f-blank.png").string(),
              cv::Mat(board.size(), CV_8UC3, cv::Scalar::all(128)));
  const flatland_test::Result r =
      run("calibrate --images 'imgs/*' --board chessboard:9x6:0.02 --out out.yaml");
  // Both boards are found (16-bit and RGBA read as 8-bit grey), the blank image is searched,
  // the damaged files are skipped: two views are too few, which is bad input.
  EXPECT_EQ(r.code, 2) << r.err;
  for (const std::string s :
       {"flatland: warning: skipping imgs/c-truncated.png: truncated PNG",
        "flatland: warning: skipping imgs/d-truncated.jpg: truncated JPEG",
        "flatland: warning: skipping imgs/e-empty.png: zero-length file",
        "flatland: warning: board not found in imgs/f-blank.png",
        "flatland: error: fewer than 3 usable views: the board was found in 2 of 3 images"})
    EXPECT_NE(r.err.find(s), std::string::npos) << s << "\n" << r.err;
  expect_only_flatland_lines(r.err);
  EXPECT_FALSE(fs::exists(dir_ / "out.yaml"));

  // Nothing readable at all.
  fs::remove(dir_ / "imgs/a-16bit.png");
  fs::remove(dir_ / "imgs/b-rgba.png");
  fs::remove(dir_ / "imgs/f-blank.png");
  const flatland_test::Result none =
      run("calibrate --images 'imgs/*' --board chessboard:9x6:0.02 --out out.yaml");
  EXPECT_EQ(none.code, 2) << none.err;
  EXPECT_EQ(lines_of(none.err).back(),
            "flatland: error: --images: none of the 3 files is a readable image");
  EXPECT_FALSE(fs::exists(dir_ / "out.yaml"));
}

// The recorded camera's frames are 8-bit (CameraFrame: 8UC1 or 8UC3) whatever the files hold.
TEST_F(BadMedia, RecordedCameraDeliversEightBitFramesFromOtherDepthsAndChannelCounts) {
  const fs::path rec = dir_ / "rec";
  fs::create_directories(rec / "frames");
  const cv::Mat img = disk_image();
  cv::Mat deep, grey, rgba;
  img.convertTo(deep, CV_16UC3, 257.0);
  cv::cvtColor(img, grey, cv::COLOR_BGR2GRAY);
  cv::cvtColor(img, rgba, cv::COLOR_BGR2BGRA);
  const std::vector<cv::Mat> images = {deep, grey, rgba};
  std::string csv = "index,t_capture,t_arrival,file\n";
  for (int k = 0; k < 3; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frames/%06d.png", k);
    cv::imwrite((rec / name).string(), images[static_cast<std::size_t>(k)]);
    csv += std::to_string(k) + "," + std::to_string(k * 0.1) + "," + std::to_string(k * 0.1) + "," +
           name + "\n";
  }
  write_text(rec / "frames.csv", csv);
  flatland::drivers::RecordedCamera cam(rec);
  const std::vector<int> types = {CV_8UC3, CV_8UC1, CV_8UC3};
  for (int k = 0; k < 3; ++k) {
    const auto f = cam.poll(1.0);
    ASSERT_TRUE(f) << k;
    EXPECT_EQ(f->image.type(), types[static_cast<std::size_t>(k)]) << k;
    EXPECT_EQ(f->image.size(), cv::Size(kWidth, kHeight));
  }
  EXPECT_EQ(cam.flagged(), 0);

  // A truncated JPEG frame is refused when the recording is opened, naming the file.
  cv::imwrite((rec / "frames/000001.jpg").string(), img);
  truncate_to_half(rec / "frames/000001.jpg");
  write_text(rec / "frames.csv", "index,t_capture,t_arrival,file\n0,0,0,frames/000001.jpg\n");
  try {
    flatland::drivers::RecordedCamera bad(rec);
    ADD_FAILURE() << "a truncated JPEG was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("000001.jpg: truncated JPEG"), std::string::npos)
        << e.what();
  }
}

TEST(ImageFile, ProblemsAreNamedWithoutDecoding) {
  const fs::path dir =
      fs::temp_directory_path() / ("flatland_image_file_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const cv::Mat img = disk_image();
  cv::imwrite((dir / "ok.png").string(), img);
  cv::imwrite((dir / "ok.jpg").string(), img);
  std::string why = "stale";
  EXPECT_FALSE(flatland::vision::read_image_file(dir / "ok.png", cv::IMREAD_COLOR, why).empty());
  EXPECT_EQ(why, "");
  EXPECT_FALSE(flatland::vision::read_image_file(dir / "ok.jpg", cv::IMREAD_COLOR, why).empty());
  EXPECT_EQ(flatland::vision::image_file_problem(dir / "none.png"), "missing image file");
  // A PNG cut exactly after a chunk still lacks its IEND.
  const std::string png = read_text(dir / "ok.png");
  write_text(dir / "cut.png", png.substr(0, png.size() - 12));
  EXPECT_EQ(flatland::vision::image_file_problem(dir / "cut.png"),
            "truncated PNG (ends before its IEND chunk)");
  write_text(dir / "cut.png", png.substr(0, png.size() - 13));
  EXPECT_EQ(flatland::vision::image_file_problem(dir / "cut.png"),
            "truncated PNG (ends inside a chunk)");
  write_text(dir / "huge-chunk.png",
             png.substr(0, 8) + std::string("\xff\xff\xff\xf0IHDR", 8) + png.substr(16));
  EXPECT_EQ(flatland::vision::image_file_problem(dir / "huge-chunk.png"),
            "truncated PNG (ends inside a chunk)");
  EXPECT_TRUE(
      flatland::vision::read_image_file(dir / "huge-chunk.png", cv::IMREAD_COLOR, why).empty());
  EXPECT_EQ(why, "truncated PNG (ends inside a chunk)");
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace
