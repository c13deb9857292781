// Video in and out: render::Mp4Writer writes what it is given with a key frame every second, and
// vision::VideoReader reads it back frame for frame (the same pixels as OpenCV's decoder), with
// the stream's times, every frame in its place, and refusals for what is not a video. The
// integrity flags on damaged files are tested end to end in tests/cli/test_track_integrity.cpp.
#include "cli_support.hpp"
#include "flatland/render/video_writer.hpp"
#include "flatland/vision/video_reader.hpp"

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;
using flatland::render::Mp4Writer;
using flatland::vision::FrameIntegrity;
using flatland::vision::VideoReader;

class VideoIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("flatland_video_io_" +
            std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A moving bright disk on a shaded table: every frame differs from the one before.
  static cv::Mat frame(int i) {
    cv::Mat m(120, 160, CV_8UC3);
    for (int y = 0; y < m.rows; ++y)
      for (int x = 0; x < m.cols; ++x) m.at<cv::Vec3b>(y, x) = cv::Vec3b::all(40 + (x + y) / 8);
    cv::circle(m, {30 + i, 60}, 15, cv::Scalar(230, 220, 210), cv::FILLED, cv::LINE_AA);
    return m;
  }

  fs::path write(int frames, double fps) {
    const fs::path p = dir_ / "clip.mp4";
    Mp4Writer w;
    const std::string codec = flatland::render::open_mp4(w, p.string(), fps, {160, 120}, "");
    EXPECT_TRUE(codec == "avc1" || codec == "mp4v") << codec;
    for (int i = 0; i < frames; ++i) w.write(frame(i));
    EXPECT_EQ(w.frames(), frames);
    w.release();
    return p;
  }

  fs::path dir_;
};

}  // namespace

TEST_F(VideoIo, WritesAKeyFrameEverySecondAndReadsBackEveryFrameInPlace) {
  const int n = 95;
  const fs::path p = write(n, 30.0);
  VideoReader reader(p.string());
  EXPECT_EQ(reader.frame_count(), n);
  EXPECT_NEAR(reader.fps(), 30.0, 1e-9);
  // Frames 0, 30, 60, 90 (x264 may add one at a scene cut; this clip has none).
  EXPECT_EQ(reader.key_frames(), static_cast<long>(std::ceil(n / 30.0)));

  // The reference: OpenCV's decoder, a separate code path over the same libavcodec.
  cv::VideoCapture cap(p.string(), cv::CAP_FFMPEG);
  ASSERT_TRUE(cap.isOpened());
  long i = 0;
  for (VideoReader::Frame f; reader.read(f); ++i) {
    cv::Mat ref;
    ASSERT_TRUE(cap.read(ref)) << i;
    ASSERT_EQ(f.image.size(), ref.size());
    EXPECT_EQ(f.integrity, FrameIntegrity::kIntact) << i;
    EXPECT_EQ(f.decoder_errors, 0) << i;
    EXPECT_NEAR(f.timestamp_s, i / 30.0, 1e-6) << i;
    // The same decoded picture; the YUV -> BGR conversion may differ by rounding.
    EXPECT_LE(cv::norm(f.image, ref, cv::NORM_INF), 2.0) << i;
    // And what was written, within the codec's loss.
    cv::Mat diff;
    cv::absdiff(f.image, frame(static_cast<int>(i)), diff);
    // The YUV round trip of both writers (OpenCV's too) turns grey g into about (g-4, g-1,
    // g-3) BGR: a mean difference of 3-4 DN on this clip.
    EXPECT_LT(cv::mean(diff)[0], 6.0) << i;
  }
  EXPECT_EQ(i, n);
}

TEST_F(VideoIo, AFileCutShortReadsItsMissingFramesAsUnreadable) {
  // AVI announces its frame count in its header, before the frames: cut, the rest is missing.
  const fs::path p = dir_ / "clip.avi";
  {
    cv::VideoWriter w(p.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30.0,
                      {160, 120}, true);
    if (!w.isOpened()) GTEST_SKIP() << "this OpenCV cannot write MJPG";
    for (int i = 0; i < 10; ++i) w.write(frame(i));
  }
  const std::string data = flatland_test::read_text(p);
  flatland_test::write_text(p, data.substr(0, data.size() * 3 / 4));
  VideoReader reader(p.string());
  EXPECT_EQ(reader.frame_count(), 10);
  int intact = 0, unreadable = 0, n = 0;
  bool unreadable_seen = false;
  for (VideoReader::Frame f; reader.read(f); ++n) {
    if (f.integrity == FrameIntegrity::kUnreadable) {
      ++unreadable;
      unreadable_seen = true;
      EXPECT_TRUE(f.image.empty());
    } else {
      EXPECT_FALSE(unreadable_seen) << "frame " << n << " after a missing one";
      intact += f.integrity == FrameIntegrity::kIntact;
    }
  }
  EXPECT_EQ(n, 10);
  EXPECT_GE(intact, 5);
  EXPECT_GE(unreadable, 1);
}

TEST_F(VideoIo, RefusesWhatIsNotAVideoAndFramesOfAnotherSize) {
  flatland_test::write_text(dir_ / "text.mp4", "not a video at all\n");
  try {
    VideoReader reader((dir_ / "text.mp4").string());
    FAIL() << "a text file was opened as a video";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("cannot open " + (dir_ / "text.mp4").string() + " as a video"),
              std::string::npos)
        << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
  EXPECT_THROW(VideoReader((dir_ / "missing.mp4").string()), std::invalid_argument);

  Mp4Writer w;
  flatland::render::open_mp4(w, (dir_ / "out.mp4").string(), 30.0, {160, 120}, "");
  EXPECT_THROW(w.write(cv::Mat(100, 100, CV_8UC3, cv::Scalar::all(0))), std::invalid_argument);
  w.write(frame(0));
  w.release();
  EXPECT_FALSE(w.isOpened());
  EXPECT_THROW(flatland::render::open_mp4(w, (dir_ / "no" / "such" / "dir.mp4").string(), 30.0,
                                          {160, 120}, "--video: "),
               std::runtime_error);
}
