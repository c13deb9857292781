// Recorded and live drivers: the Recorder's directory format round-trips frames and joint ticks
// exactly, the players reject bad input with one-line errors naming the file, and the live
// drivers fail cleanly on a machine without a camera.
#include "cli_support.hpp"
#include "flatland/drivers/live.hpp"
#include "flatland/drivers/recorded.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace {

namespace fs = std::filesystem;
using flatland::control::JointReading;
using flatland::drivers::CameraFrame;
using flatland::drivers::LiveCamera;
using flatland::drivers::LogJoint;
using flatland::drivers::RecordedCamera;
using flatland::drivers::Recorder;
using flatland::drivers::RecordingMetadata;
using flatland::drivers::SteadyClock;
using flatland_test::read_text;
using flatland_test::write_text;

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

/// A reproducible noisy image: every pixel value matters for the lossless round trip.
cv::Mat noise_image(int seed, int type, int width = 40, int height = 30) {
  cv::Mat m(height, width, type);
  cv::RNG rng(static_cast<std::uint64_t>(seed) + 1);
  rng.fill(m, cv::RNG::UNIFORM, 0, 256);
  return m;
}

/// Times that do not survive "%g"-style printing: the format must round-trip every bit.
double awkward_time(int k) { return k / 30.0 + 1.0 / 3.0 * 1e-7 + std::nextafter(0.0, 1.0); }

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

/// The one-line std::invalid_argument that `f` must throw; the message is returned for more
/// checks.
std::string invalid_argument_of(const std::function<void()>& f) {
  std::string msg = "(no exception)";
  try {
    f();
  } catch (const std::invalid_argument& e) {
    msg = e.what();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected std::invalid_argument, got another exception: " << e.what();
    return e.what();
  }
  EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  return msg;
}

class RecordedDrivers : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    dir_ = fs::temp_directory_path() / ("flatland_drivers_test_" + std::to_string(::getpid()) +
                                        "_" + std::to_string(counter++));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::vector<std::string> entries(const fs::path& d) const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(d)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }

  /// A finished recording of `n` frames (colour and grey alternating) arriving every 1/30 s and
  /// 3 ms after capture, and `ticks` joint ticks at 1 kHz.
  fs::path make_recording(const std::string& name, int n, int ticks = 0) {
    const fs::path rec = dir_ / name;
    Recorder r(rec, {1000, "synthetic", "synthetic", "scene.yaml"});
    for (int k = 0; k < n; ++k) r.add_frame(frame(k));
    for (int i = 0; i < ticks; ++i) r.add_tick(reading(i), command(i));
    r.finish();
    return rec;
  }

  static CameraFrame frame(int k) {
    CameraFrame f;
    f.index = 2 * k;  // gaps: dropped frames are part of the format
    f.t_capture = awkward_time(k);
    f.t_arrival = f.t_capture + 0.003;
    f.image = noise_image(k, k % 2 ? CV_8UC1 : CV_8UC3);
    return f;
  }
  static JointReading reading(int i) {
    JointReading j;
    j.t = i * 1e-3;
    j.theta = std::sin(0.1 * i) / 3;
    j.theta_dot = std::cos(0.1 * i) * M_PI;
    return j;
  }
  static double command(int i) { return i == 2 ? -0.0 : std::exp(0.01 * i) / 7; }

  fs::path dir_;
};

// ---------------------------------------------------------------------------------------------
// Recorder -> RecordedCamera

TEST_F(RecordedDrivers, RoundTripGivesIdenticalPixelsAndBitIdenticalTimes) {
  const fs::path rec = dir_ / "run";
  Recorder r(rec, {1000, "synthetic \"overhead\"", "log:C:\\run", "scenes/butterfly.yaml"});
  for (int k = 0; k < 6; ++k) r.add_frame(frame(k));
  for (int i = 0; i < 5; ++i) r.add_tick(reading(i), command(i));
  EXPECT_FALSE(fs::exists(rec)) << "the recording appears only when finished";
  r.finish();
  EXPECT_EQ(entries(dir_), std::vector<std::string>{"run"});
  EXPECT_EQ(entries(rec),
            (std::vector<std::string>{"frames", "frames.csv", "joint.csv", "recording.json"}));
  EXPECT_TRUE(fs::exists(rec / "frames" / "000010.png"));

  const auto meta = nlohmann::json::parse(read_text(rec / "recording.json"));
  EXPECT_EQ(meta["version"], 1);
  EXPECT_EQ(meta["rate_hz"], 1000.0);
  EXPECT_EQ(meta["frames"], 6);
  EXPECT_EQ(meta["ticks"], 5);
  EXPECT_EQ(meta["camera"], "synthetic \"overhead\"");
  EXPECT_EQ(meta["joint"], "log:C:\\run");
  EXPECT_EQ(meta["scene"], "scenes/butterfly.yaml");
  EXPECT_EQ(read_text(rec / "frames.csv").substr(0, 31), "index,t_capture,t_arrival,file\n");

  RecordedCamera cam(rec);
  EXPECT_EQ(cam.describe(), "video:" + rec.string());
  ASSERT_EQ(cam.records().size(), 6u);
  for (int k = 0; k < 6; ++k) {
    const auto got = cam.poll(100.0);
    ASSERT_TRUE(got) << "frame " << k;
    const CameraFrame want = frame(k);
    EXPECT_EQ(got->index, want.index);
    EXPECT_EQ(bits(got->t_capture), bits(want.t_capture)) << got->t_capture;
    EXPECT_EQ(bits(got->t_arrival), bits(want.t_arrival)) << got->t_arrival;
    ASSERT_EQ(got->image.type(), want.image.type()) << "frame " << k;
    ASSERT_EQ(got->image.size(), want.image.size());
    EXPECT_EQ(cv::norm(got->image, want.image, cv::NORM_INF), 0.0) << "frame " << k;
  }
  EXPECT_FALSE(cam.poll(100.0));
  EXPECT_TRUE(cam.exhausted());
  EXPECT_EQ(cam.delivered(), 6);
  EXPECT_EQ(cam.flagged(), 0);
  // Also named by its frames.csv.
  EXPECT_EQ(RecordedCamera(rec / "frames.csv").records().size(), 6u);
}

TEST_F(RecordedDrivers, PollHandsOutFramesOnlyOnceTheyHaveArrived) {
  const fs::path rec = dir_ / "run";
  {
    Recorder r(rec, {});
    const double arrivals[] = {0.10, 0.20, 0.20, 0.35};  // two frames may arrive at one tick
    for (int k = 0; k < 4; ++k) {
      CameraFrame f;
      f.index = k;
      f.t_capture = 0.05 + 0.03 * k;
      f.t_arrival = arrivals[k];
      f.image = noise_image(k, CV_8UC3);
      r.add_frame(f);
    }
    r.finish();
  }
  RecordedCamera cam(rec);
  EXPECT_FALSE(cam.poll(0.0));
  EXPECT_FALSE(cam.poll(0.0999));
  auto f = cam.poll(0.10);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->index, 0);
  EXPECT_FALSE(cam.poll(0.15));
  f = cam.poll(0.25);  // two waiting: oldest first
  ASSERT_TRUE(f);
  EXPECT_EQ(f->index, 1);
  f = cam.poll(0.25);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->index, 2);
  EXPECT_FALSE(cam.poll(0.3));
  EXPECT_FALSE(cam.exhausted());
  f = cam.poll(0.35);
  ASSERT_TRUE(f);
  EXPECT_EQ(f->index, 3);
  EXPECT_FALSE(cam.poll(10.0));
  EXPECT_TRUE(cam.exhausted());
}

TEST_F(RecordedDrivers, RecorderDestroyedWithoutFinishLeavesNothing) {
  const fs::path rec = dir_ / "new" / "parents" / "run";
  {
    Recorder r(rec, {});
    for (int k = 0; k < 5; ++k) r.add_frame(frame(k));
    for (int i = 0; i < 10; ++i) r.add_tick(reading(i), command(i));
    // While recording, only the staging sibling exists (files::OutputSet's).
    const auto during = entries(rec.parent_path());
    ASSERT_EQ(during.size(), 1u);
    EXPECT_EQ(during[0].rfind(".run.tmp-", 0), 0u) << during[0];
    EXPECT_TRUE(fs::exists(rec.parent_path() / during[0] / "joint.csv"));
  }
  EXPECT_TRUE(entries(dir_).empty()) << "the parents it created are removed too";

  // An exception out of the loop unwinds through the Recorder the same way.
  fs::create_directories(dir_ / "out");
  EXPECT_THROW(
      {
        Recorder r(dir_ / "out" / "run", {});
        r.add_frame(frame(0));
        throw std::runtime_error("the loop failed");
      },
      std::runtime_error);
  EXPECT_TRUE(entries(dir_ / "out").empty());

  // A Recorder whose add_frame is refused is abandoned the same way.
  {
    Recorder r(dir_ / "out" / "run", {});
    r.add_frame(frame(1));
    EXPECT_THROW(r.add_frame(frame(0)), std::logic_error);  // index and times must increase
    CameraFrame late = frame(2);
    late.t_arrival = late.t_capture - 1e-3;
    EXPECT_THROW(r.add_frame(late), std::logic_error);
    r.add_tick(reading(3), 0);
    EXPECT_THROW(r.add_tick(reading(3), 0), std::logic_error);  // t must increase
  }
  EXPECT_TRUE(entries(dir_ / "out").empty());
}

TEST_F(RecordedDrivers, RecorderWriteFailureNamesTheFileAndLeavesNothing) {
  const fs::path rec = dir_ / "run";
  Recorder r(rec, {});
  // Pull the frames directory from under the recorder: the PNG writes fail (on the writer
  // thread; the error surfaces in a later add_frame or in finish()).
  const auto during = entries(dir_);
  ASSERT_EQ(during.size(), 1u);
  fs::remove_all(dir_ / during[0] / "frames");
  const std::string msg = message_of([&] {
    for (int k = 0; k < 3; ++k) {
      r.add_frame(frame(k));
      r.add_tick(reading(k), 0);
    }
    r.finish();
  });
  EXPECT_EQ(msg, (dir_ / during[0] / "frames" / "000000.png").string() +
                     ": cannot write the frame image");
  EXPECT_FALSE(fs::exists(rec));
  EXPECT_TRUE(entries(dir_).empty());
}

TEST_F(RecordedDrivers, RecorderRefusesAnExistingDirectory) {
  const fs::path rec = dir_ / "run";
  fs::create_directories(rec);
  write_text(rec / "notes.txt", "keep me");
  const std::string msg = invalid_argument_of([&] { Recorder r(rec, {}); });
  EXPECT_NE(msg.find("--record " + rec.string() + ": already exists"), std::string::npos) << msg;
  EXPECT_EQ(entries(dir_), std::vector<std::string>{"run"}) << "no temporary directory left";
  EXPECT_EQ(entries(rec), std::vector<std::string>{"notes.txt"});

  write_text(dir_ / "file", "x");
  EXPECT_NE(invalid_argument_of([&] { Recorder r(dir_ / "file", {}); }).find("already exists"),
            std::string::npos);

  // An empty directory (made by the user beforehand) is taken.
  fs::create_directories(dir_ / "empty");
  {
    Recorder r(dir_ / "empty", {});
    r.add_frame(frame(0));
    r.finish();
    EXPECT_THROW(r.add_frame(frame(1)), std::logic_error);
  }
  EXPECT_EQ(RecordedCamera(dir_ / "empty").records().size(), 1u);

  EXPECT_NE(invalid_argument_of([&] {
              Recorder r(dir_ / "r2", {0, "", "", ""});
            }).find("rate_hz"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ / "r2"));
}

// ---------------------------------------------------------------------------------------------
// LogJoint

TEST_F(RecordedDrivers, LogJointReplaysReadingsBitForBitAndComparesCommands) {
  const int n = 50;
  const fs::path rec = make_recording("run", 1, n);
  {
    LogJoint joint(rec);
    EXPECT_EQ(joint.describe(), "log:" + rec.string());
    EXPECT_EQ(joint.ticks(), n);
    for (int i = 0; i < n; ++i) {
      const JointReading want = reading(i);
      const JointReading got = joint.read(want.t);
      EXPECT_EQ(bits(got.t), bits(want.t));
      EXPECT_EQ(bits(got.theta), bits(want.theta)) << "tick " << i;
      EXPECT_EQ(bits(got.theta_dot), bits(want.theta_dot)) << "tick " << i;
      joint.command(want.t, command(i));
    }
    EXPECT_EQ(joint.commands(), n);
    EXPECT_EQ(joint.mismatches(), 0);
    EXPECT_EQ(joint.first_mismatch_tick(), -1);
    EXPECT_EQ(joint.max_command_difference(), 0.0);
    // Past the end.
    const std::string msg = message_of([&] { joint.read(1.0); });
    EXPECT_NE(msg.find("tick 50"), std::string::npos) << msg;
    EXPECT_NE(msg.find("past the end"), std::string::npos) << msg;
    EXPECT_THROW(joint.read(1.0), std::runtime_error);
  }
  {
    // A command one ulp off, and +0 for the logged -0: both are differences for a bit-for-bit
    // replay, although -0 == +0 numerically.
    LogJoint joint(rec / "joint.csv");
    for (int i = 0; i < n; ++i) {
      joint.read(reading(i).t);
      double a = command(i);
      if (i == 2) a = 0.0;
      if (i == 7) a = std::nextafter(a, 10.0);
      joint.command(reading(i).t, a);
    }
    EXPECT_EQ(joint.mismatches(), 2);
    EXPECT_EQ(joint.first_mismatch_tick(), 2);
    EXPECT_GT(joint.max_command_difference(), 0.0);
    EXPECT_LT(joint.max_command_difference(), 1e-15);
  }
  {
    // The loop and the log disagree on time: an error naming the tick.
    LogJoint joint(rec);
    joint.read(0.0);
    joint.read(1e-3);
    const std::string msg = message_of([&] { joint.read(2.5e-3); });
    EXPECT_NE(msg.find("tick 2"), std::string::npos) << msg;
    EXPECT_NE(msg.find("log:" + rec.string()), std::string::npos) << msg;
    EXPECT_THROW(joint.read(2.5e-3), std::runtime_error);
    EXPECT_THROW(joint.command(0.0, 0.0), std::runtime_error);  // the last tick read is at 1 ms
  }
  EXPECT_THROW(LogJoint(rec).command(0.0, 0.0), std::runtime_error);  // nothing read yet
}

TEST_F(RecordedDrivers, LogJointRejectsBadLogsNamingTheLine) {
  const fs::path log = dir_ / "joint.csv";
  struct Case {
    std::string content, expect;
  };
  const std::vector<Case> cases = {
      {"", "zero-length file"},
      {"tick,t,theta,theta_dot\n0,0,0,0\n", "bad header"},
      {"tick,t,theta,theta_dot,theta_ddot_cmd\n0,0,0,0,0\n1,0.001,x,0,0\n",
       "line 3: non-numeric theta 'x'"},
      {"tick,t,theta,theta_dot,theta_ddot_cmd\n0,0,0,0,0\n1,0,0,0,0\n", "line 3: non-monotonic t"},
      {"tick,t,theta,theta_dot,theta_ddot_cmd\n0,0,0,0,0\n0,0.001,0,0,0\n",
       "line 3: non-monotonic tick"},
      {"tick,t,theta,theta_dot,theta_ddot_cmd\n0,0,0,0\n", "line 2: expected 5 fields, got 4"},
      {"tick,t,theta,theta_dot,theta_ddot_cmd\n0,inf,0,0,0\n", "line 2: t is not finite"},
  };
  for (const auto& c : cases) {
    write_text(log, c.content);
    const std::string msg = invalid_argument_of([&] { LogJoint j(log); });
    EXPECT_NE(msg.find(log.string() + ": "), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << "expected '" << c.expect << "' in: " << msg;
  }
  EXPECT_NE(invalid_argument_of([&] { LogJoint j(dir_); }).find((dir_ / "joint.csv").string()),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Bad recordings

TEST_F(RecordedDrivers, BadRecordingsGiveOneLineErrorsNamingTheFileAndReason) {
  const std::string header = "index,t_capture,t_arrival,file\n";
  struct Case {
    std::string name;
    std::string csv;  // frames.csv; "-" for none
    std::function<void(const fs::path&)> damage;
    std::string file;  // the file the message must name (relative to the recording)
    std::string expect;
  };
  auto row = [](int k, const std::string& tc, const std::string& ta) {
    char name[32];
    std::snprintf(name, sizeof name, "frames/%06d.png", k);
    return std::to_string(k) + "," + tc + "," + ta + "," + name + "\n";
  };
  const std::string good = header + row(0, "0", "0.01") + row(1, "0.033", "0.043");
  auto nothing = [](const fs::path&) {};
  const std::vector<Case> cases = {
      {"no frames.csv", "-", nothing, "frames.csv", "missing"},
      {"empty frames.csv", "", nothing, "frames.csv", "zero-length file"},
      {"bad header", "index,t,file\n" + row(0, "0", "0"), nothing, "frames.csv",
       "bad header 'index,t,file'"},
      {"non-numeric", header + row(0, "0", "0.01") + row(1, "abc", "0.043"), nothing, "frames.csv",
       "line 3: non-numeric t_capture 'abc'"},
      {"non-numeric index", header + "x,0,0,frames/000000.png\n", nothing, "frames.csv",
       "line 2: non-numeric index 'x'"},
      {"index order", header + row(1, "0", "0.01") + row(0, "0.033", "0.043"), nothing,
       "frames.csv", "line 3: non-monotonic index"},
      {"capture order", header + row(0, "0.033", "0.04") + row(1, "0.033", "0.05"), nothing,
       "frames.csv", "line 3: non-monotonic t_capture"},
      {"arrival order", header + row(0, "0", "0.05") + row(1, "0.033", "0.04"), nothing,
       "frames.csv", "line 3: non-monotonic t_arrival"},
      {"arrival before capture", header + row(0, "0.02", "0.01"), nothing, "frames.csv",
       "line 2: t_arrival 0.01 < t_capture 0.02"},
      {"field count", header + "0,0,0\n", nothing, "frames.csv", "line 2: expected 4 fields"},
      {"blank line", header + row(0, "0", "0.01") + "\n" + row(1, "0.033", "0.043"), nothing,
       "frames.csv", "line 3: blank line"},
      {"missing image", good, [](const fs::path& d) { fs::remove(d / "frames/000001.png"); },
       "frames/000001.png", "missing image file ("},
      {"zero-length image", good,
       [](const fs::path& d) { write_text(d / "frames/000001.png", ""); }, "frames/000001.png",
       "zero-length file"},
      {"truncated PNG", good,
       [](const fs::path& d) {
         const fs::path p = d / "frames/000001.png";
         fs::resize_file(p, fs::file_size(p) - 20);
       },
       "frames/000001.png", "truncated PNG"},
      {"directory for an image", good,
       [](const fs::path& d) {
         fs::remove(d / "frames/000001.png");
         fs::create_directory(d / "frames/000001.png");
       },
       "frames/000001.png", "not a regular file"},
      {"not a PNG", good,
       [](const fs::path& d) { write_text(d / "frames/000000.png", "GIF89a..."); },
       "frames/000000.png", "not a PNG file"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path rec = dir_ / "rec";
    fs::remove_all(rec);
    fs::create_directories(rec / "frames");
    for (int k = 0; k < 2; ++k) {
      char name[32];
      std::snprintf(name, sizeof name, "frames/%06d.png", k);
      cv::imwrite((rec / name).string(), noise_image(k, CV_8UC3));
    }
    if (c.csv != "-") write_text(rec / "frames.csv", c.csv);
    c.damage(rec);
    const std::string msg = invalid_argument_of([&] { RecordedCamera cam(rec); });
    EXPECT_EQ(msg.rfind((rec / c.file).string() + ": ", 0), 0u) << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << "expected '" << c.expect << "' in: " << msg;
  }
  // The good recording the cases damage does load.
  const fs::path rec = dir_ / "rec";
  fs::remove_all(rec);
  fs::create_directories(rec / "frames");
  for (int k = 0; k < 2; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "frames/%06d.png", k);
    cv::imwrite((rec / name).string(), noise_image(k, CV_8UC3));
  }
  write_text(rec / "frames.csv", good);
  EXPECT_EQ(RecordedCamera(rec).records().size(), 2u);

  EXPECT_NE(invalid_argument_of([&] {
              RecordedCamera c(dir_ / "nothing");
            }).find((dir_ / "nothing").string() + ": no such file or directory"),
            std::string::npos);
}

TEST_F(RecordedDrivers, UnreadableImageIsBadInput) {
  if (::geteuid() == 0) GTEST_SKIP() << "root reads files whatever their permissions";
  const fs::path rec = make_recording("run", 2);
  fs::permissions(rec / "frames" / "000002.png", fs::perms::none);
  const std::string msg = invalid_argument_of([&] { RecordedCamera cam(rec); });
  EXPECT_NE(msg.find("000002.png: unreadable image file"), std::string::npos) << msg;
}

// ---------------------------------------------------------------------------------------------
// Video file + timestamps

class RecordedVideo : public RecordedDrivers {
 protected:
  /// A short lossless video (FFV1 in AVI) of `n` 64x48 noise frames, and its timestamps file.
  fs::path make_video(int n) {
    const fs::path video = dir_ / "clip.avi";
    cv::VideoWriter w(video.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('F', 'F', 'V', '1'),
                      30.0, cv::Size(64, 48), true);
    if (!w.isOpened()) return {};
    for (int k = 0; k < n; ++k) w.write(noise_image(k, CV_8UC3, 64, 48));
    w.release();
    std::string ts = "index,t_capture,t_arrival\n";
    for (int k = 0; k < n; ++k) ts += stamp_row(k);
    write_text(video.string() + ".timestamps.csv", ts);
    return video;
  }
  static std::string stamp_row(int k) {
    char buf[128];
    std::snprintf(buf, sizeof buf, "%d,%.17g,%.17g\n", k + 100, awkward_time(k),
                  awkward_time(k) + 0.004);
    return buf;
  }
};

TEST_F(RecordedVideo, PlaysEveryFrameWithItsTimestamps) {
  const fs::path video = make_video(12);
  if (video.empty()) GTEST_SKIP() << "this OpenCV cannot write FFV1";
  RecordedCamera cam(video);
  EXPECT_EQ(cam.describe(), "video:" + video.string());
  ASSERT_EQ(cam.records().size(), 12u);
  EXPECT_FALSE(cam.poll(awkward_time(0)));  // arrives 4 ms after capture
  for (int k = 0; k < 12; ++k) {
    const auto f = cam.poll(awkward_time(k) + 0.004);
    ASSERT_TRUE(f) << "frame " << k;
    EXPECT_EQ(f->index, k + 100);
    EXPECT_EQ(bits(f->t_capture), bits(awkward_time(k)));
    EXPECT_EQ(bits(f->t_arrival), bits(awkward_time(k) + 0.004));
    ASSERT_EQ(f->image.size(), cv::Size(64, 48));
    ASSERT_EQ(f->image.type(), CV_8UC3);
    // FFV1 is lossless: the frames come back in order, pixel for pixel.
    EXPECT_EQ(cv::norm(f->image, noise_image(k, CV_8UC3, 64, 48), cv::NORM_INF), 0.0)
        << "frame " << k;
  }
  EXPECT_FALSE(cam.poll(1e9));
  EXPECT_EQ(cam.delivered(), 12);
  EXPECT_EQ(cam.flagged(), 0);

  // The timestamps may also be named after the video's stem.
  fs::rename(video.string() + ".timestamps.csv", dir_ / "clip.timestamps.csv");
  EXPECT_EQ(RecordedCamera(video).records().size(), 12u);
}

TEST_F(RecordedVideo, UndecodableFrameIsHandedOutFlaggedInItsPlace) {
  // MJPG: every frame is a JPEG of its own, so one can be damaged without touching the others.
  // Flat colours survive the lossy codec well enough to tell the frames apart.
  const fs::path video = dir_ / "clip.avi";
  auto colour = [](int k) { return cv::Scalar(20.0 * k, 255 - 20.0 * k, 7.0 * k); };
  {
    cv::VideoWriter w(video.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'),
                      30.0, cv::Size(64, 48), true);
    if (!w.isOpened()) GTEST_SKIP() << "this OpenCV cannot write MJPG";
    for (int k = 0; k < 10; ++k) w.write(cv::Mat(48, 64, CV_8UC3, colour(k)));
  }
  std::string ts = "index,t_capture,t_arrival\n";
  for (int k = 0; k < 10; ++k) ts += stamp_row(k);
  write_text(video.string() + ".timestamps.csv", ts);
  // Wipe the start of the fifth JPEG (after its start-of-image marker).
  std::string data = read_text(video);
  std::size_t pos = 0;
  for (int n = 0; n < 5; ++n) {
    pos = data.find(std::string("\xff\xd8\xff", 3), n == 0 ? 0 : pos + 3);
    ASSERT_NE(pos, std::string::npos);
  }
  std::fill(data.begin() + static_cast<long>(pos) + 2, data.begin() + static_cast<long>(pos) + 200,
            '\0');
  write_text(video, data);

  RecordedCamera cam(video);
  ASSERT_EQ(cam.records().size(), 10u);
  testing::internal::CaptureStderr();
  std::vector<long> indices;
  for (int k = 0; k < 10; ++k) {
    const auto f = cam.poll(awkward_time(k) + 0.004);
    ASSERT_TRUE(f) << "frame " << k;
    indices.push_back(f->index);
    const int frame = static_cast<int>(f->index) - 100;
    if (frame == 4) {
      // The flags track uses (damaged or unreadable): the loop measures nothing from it.
      EXPECT_NE(f->integrity, flatland::vision::FrameIntegrity::kIntact);
      continue;
    }
    EXPECT_EQ(f->integrity, flatland::vision::FrameIntegrity::kIntact) << "frame " << frame;
    const cv::Scalar mean = cv::mean(f->image);
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(mean[c], colour(frame)[c], 4.0) << "frame " << frame << " channel " << c;
  }
  const std::string err = testing::internal::GetCapturedStderr();
  EXPECT_EQ(indices, (std::vector<long>{100, 101, 102, 103, 104, 105, 106, 107, 108, 109}));
  EXPECT_EQ(cam.delivered(), 10);
  EXPECT_EQ(cam.flagged(), 1);
  EXPECT_TRUE(cam.exhausted());
  EXPECT_NE(err.find("flatland: warning: video:" + video.string() + ": frame 104 is "),
            std::string::npos)
      << err;
}

TEST_F(RecordedVideo, BadVideoInputIsRejected) {
  const fs::path video = make_video(5);
  if (video.empty()) GTEST_SKIP() << "this OpenCV cannot write FFV1";
  const fs::path stamps = video.string() + ".timestamps.csv";
  const std::string good = read_text(stamps);

  // Frame count mismatch, both ways.
  write_text(stamps, "index,t_capture,t_arrival\n" + stamp_row(0) + stamp_row(1));
  std::string msg = invalid_argument_of([&] { RecordedCamera c(video); });
  EXPECT_EQ(msg.rfind(video.string() + ": frame count mismatch", 0), 0u) << msg;
  EXPECT_NE(msg.find("has 5 frames"), std::string::npos) << msg;
  EXPECT_NE(msg.find("lists 2"), std::string::npos) << msg;
  write_text(stamps, good + stamp_row(5));
  EXPECT_NE(invalid_argument_of([&] { RecordedCamera c(video); }).find("lists 6"),
            std::string::npos);

  // A bad timestamps file names itself.
  write_text(stamps, "index,t_capture,t_arrival,file\n");
  msg = invalid_argument_of([&] { RecordedCamera c(video); });
  EXPECT_EQ(msg.rfind(stamps.string() + ": line 1: bad header", 0), 0u) << msg;
  write_text(stamps, "index,t_capture,t_arrival\n0,0.5,0.5\n1,0.4,0.6\n");
  msg = invalid_argument_of([&] { RecordedCamera c(video); });
  EXPECT_EQ(msg.rfind(stamps.string() + ": line 3: non-monotonic t_capture", 0), 0u) << msg;
  write_text(stamps, "");
  msg = invalid_argument_of([&] { RecordedCamera c(video); });
  EXPECT_EQ(msg, stamps.string() + ": zero-length file");
  fs::remove(stamps);
  msg = invalid_argument_of([&] { RecordedCamera c(video); });
  EXPECT_EQ(msg.rfind(stamps.string() + ": missing", 0), 0u) << msg;

  // Zero-length and undecodable videos.
  const fs::path empty = dir_ / "empty.avi";
  write_text(empty, "");
  write_text(empty.string() + ".timestamps.csv", "index,t_capture,t_arrival\n");
  EXPECT_EQ(invalid_argument_of([&] { RecordedCamera c(empty); }),
            empty.string() + ": zero-length file");
  const fs::path junk = dir_ / "junk.avi";
  write_text(junk, std::string(4096, 'x'));
  write_text(junk.string() + ".timestamps.csv", good);
  EXPECT_EQ(invalid_argument_of([&] { RecordedCamera c(junk); }),
            junk.string() + ": cannot open as a video");
}

// ---------------------------------------------------------------------------------------------
// Live drivers and open_camera

TEST(LiveDrivers, MissingV4l2DeviceIsBadInput) {
  ASSERT_FALSE(fs::exists("/dev/video63"));
  const std::string want = "camera v4l2:63: no such device (/dev/video63 does not exist)";
  EXPECT_EQ(invalid_argument_of([] { LiveCamera c(63, std::chrono::steady_clock::now()); }), want);
  EXPECT_EQ(invalid_argument_of([] { flatland::drivers::open_camera("v4l2:63"); }), want);
}

TEST(LiveDrivers, SteadyClockCountsSecondsFromItsStartAndSleeps) {
  const SteadyClock clock;
  SteadyClock sleeper(clock.start());
  const double t0 = clock.now();
  EXPECT_GE(t0, 0.0);
  EXPECT_LT(t0, 0.5);
  sleeper.sleep_until(t0 + 0.02);
  const double t1 = clock.now();
  EXPECT_GE(t1, t0 + 0.02);
  EXPECT_LT(t1, t0 + 1.0);
  // A time already past returns at once.
  const auto before = std::chrono::steady_clock::now();
  sleeper.sleep_until(-5.0);
  EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::milliseconds(100));
  EXPECT_THROW(sleeper.sleep_until(std::numeric_limits<double>::infinity()), std::invalid_argument);
  // Started 2 s ago.
  const SteadyClock old(std::chrono::steady_clock::now() - std::chrono::seconds(2));
  EXPECT_GE(old.now(), 2.0);
  EXPECT_LT(old.now(), 3.0);
}

TEST_F(RecordedDrivers, OpenCameraAndJointParseTheirSpecifications) {
  using flatland::drivers::open_camera;
  using flatland::drivers::open_joint;
  EXPECT_EQ(open_camera("synthetic"), nullptr);
  EXPECT_EQ(open_joint("synthetic"), nullptr);

  const fs::path rec = make_recording("run", 3, 4);
  const auto cam = open_camera("video:" + rec.string());
  ASSERT_NE(cam, nullptr);
  EXPECT_EQ(cam->describe(), "video:" + rec.string());
  EXPECT_NE(dynamic_cast<RecordedCamera*>(cam.get()), nullptr);
  EXPECT_TRUE(cam->poll(10.0));
  const auto joint = open_joint("log:" + rec.string());
  ASSERT_NE(joint, nullptr);
  EXPECT_EQ(joint->describe(), "log:" + rec.string());
  EXPECT_EQ(joint->read(0.0).t, 0.0);

  for (const std::string bad :
       {"v4l2:", "v4l2:abc", "v4l2:-1", "v4l2:+1", "v4l2:1.5", "v4l2:0x1", "v4l2:99999999999"}) {
    const std::string msg = invalid_argument_of([&] { open_camera(bad); });
    EXPECT_EQ(msg.rfind("--camera: " + bad + ": the device must be a non-negative integer", 0), 0u)
        << msg;
  }
  EXPECT_EQ(invalid_argument_of([] { open_camera("video:"); }).rfind("--camera: video:", 0), 0u);
  for (const std::string bad : {"", "usb:0", "Synthetic", "video", "/dev/video0"}) {
    const std::string msg = invalid_argument_of([&] { open_camera(bad); });
    EXPECT_EQ(msg.rfind("--camera: unknown camera '" + bad + "'", 0), 0u) << msg;
    for (const char* form : {"synthetic", "video:PATH", "v4l2:N"})
      EXPECT_NE(msg.find(form), std::string::npos) << msg;
  }
  EXPECT_NE(invalid_argument_of([&] {
              open_camera("video:" + (dir_ / "none").string());
            }).find((dir_ / "none").string() + ": no such file or directory"),
            std::string::npos);
  const std::string msg = invalid_argument_of([] { open_joint("file:x"); });
  EXPECT_EQ(msg.rfind("--joint: unknown joint 'file:x'", 0), 0u) << msg;
  EXPECT_NE(msg.find("log:PATH"), std::string::npos) << msg;
  EXPECT_EQ(invalid_argument_of([] { open_joint("log:"); }).rfind("--joint: log:", 0), 0u);
}

}  // namespace
