// The recording readers (identify/recording_io.hpp): each format read back exactly, and each kind
// of bad input refused with one line naming file:line.
#include "flatland/drivers/tick_log_csv.hpp"
#include "flatland/identify/recording_io.hpp"

#include <gtest/gtest.h>

#include <unistd.h>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;
using namespace flatland::identify;

/// A fresh directory for one test, removed at its end.
class RecordingFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("flatland-recording-io-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    fs::create_directories(p.parent_path());
    std::ofstream(p, std::ios::binary) << text;
    return p.string();
  }
  /// The message of the std::invalid_argument `f` throws ("" if it throws none).
  template <class F>
  static std::string error_of(F&& f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find('\n'), std::string::npos) << "one line: " << m;
      return m;
    }
    return "";
  }
  fs::path dir_;
};

constexpr const char* kPlain =
    "t[s],theta[rad],s_h,sigma\n"
    "0,0.1,-1,0.01\n"
    "# a comment line\n"
    "0.5,0.2,-0.9,0.02\n"
    "\n"
    "1.0,0.3,-0.8,0.01\n"
    "1.5,0.4,-0.7,0.03\n";

TEST_F(RecordingFiles, PlainCsvIsReadExactly) {
  const std::string p = write("plain.csv", kPlain);
  ReadSummary summary;
  const Recording r = read_plain_recording(p, std::nullopt, &summary);
  EXPECT_EQ(r.t, (std::vector<double>{0, 0.5, 1.0, 1.5}));
  EXPECT_EQ(r.s_h, (std::vector<double>{-1, -0.9, -0.8, -0.7}));
  EXPECT_EQ(r.sigma, (std::vector<double>{0.01, 0.02, 0.01, 0.03}));
  EXPECT_EQ(r.joint_t, r.t);
  EXPECT_EQ(r.joint_theta, (std::vector<double>{0.1, 0.2, 0.3, 0.4}));
  EXPECT_EQ(summary.samples, 4);
}

TEST_F(RecordingFiles, PlainCsvWithoutSigmaNeedsOne) {
  const std::string p = write("plain.csv",
                              "t,theta,s_h\n0,0,-1\n0.1,0.01,-0.99\n0.2,0.02,-0.98\n"
                              "0.3,0.03,-0.97\n");
  EXPECT_NE(error_of([&] { read_plain_recording(p); }).find("no sigma column and no sigma given"),
            std::string::npos);
  const Recording r = read_plain_recording(p, 0.004);
  EXPECT_EQ(r.sigma, std::vector<double>(4, 0.004));
  EXPECT_NE(error_of([&] { read_plain_recording(p, -1.0); }).find("sigma: must be"),
            std::string::npos);
}

TEST_F(RecordingFiles, PlainCsvBadInputNamesFileAndLine) {
  struct Case {
    std::string text, expected;
  };
  const std::string ok = "0,0,-1,0.01\n0.1,0,-1,0.01\n0.2,0,-1,0.01\n";
  const std::vector<Case> cases = {
      {"t,theta,s_h,sigma\n0,0,-1,0.01\n0.1,abc,-1,0.01\n0.2,0,-1,0.01\n0.3,0,-1,0.01\n",
       ":3: theta: not a number: 'abc'"},
      {"t,theta,s_h,sigma\n" + ok + "0.15,0,-1,0.01\n",
       ":5: t 0.15 is not after the previous row's 0.2"},
      {"t,theta,s_h,sigma\n" + ok + "0.2,0,-1,0.01\n", ":5: t 0.2 is not after"},
      {"t,theta,sigma\n" + ok, ":1: missing column s_h"},
      {"t,theta,s_h,sigma\n" + ok + "0.3,nan,-1,0.01\n", ":5: theta: not finite: 'nan'"},
      {"t,theta,s_h,sigma\n" + ok, "3 data rows, identify needs at least 4"},
      {ok + "0.3,0,-1,0.01\n", ":1: the first line must be a header naming the columns"},
      {"t,theta,s_h,sigma\n" + ok + "0.3,0,-1\n", ":5: expected 4 fields as in the header, got 3"},
      {"t,theta,s_h,sigma\n" + ok + "0.3,0,-1,0\n", ":5: sigma must be > 0"},
      {"t,theta,t,s_h\n" + ok, ":1: column t appears twice"},
      {"", ": empty (no header line)"},
  };
  for (const Case& c : cases) {
    const std::string p = write("bad.csv", c.text);
    const std::string m = error_of([&] { read_plain_recording(p); });
    EXPECT_NE(m.find(p), std::string::npos) << m;
    EXPECT_NE(m.find(c.expected), std::string::npos) << "expected '" << c.expected << "' in " << m;
  }
}

TEST_F(RecordingFiles, FilesAreBoundedInSizeLinesAndRows) {
  const std::string p = write("plain.csv", kPlain);
  FileLimits tiny;
  tiny.max_bytes = 40;
  EXPECT_NE(error_of([&] { read_plain_recording(p, {}, nullptr, tiny); }).find("larger than"),
            std::string::npos);
  FileLimits short_lines;
  short_lines.max_line = 10;
  EXPECT_NE(error_of([&] {
              read_plain_recording(p, {}, nullptr, short_lines);
            }).find(":1: a line longer than 10 bytes"),
            std::string::npos);
  FileLimits few_rows;
  few_rows.max_rows = 3;
  EXPECT_NE(error_of([&] {
              read_plain_recording(p, {}, nullptr, few_rows);
            }).find(":7: more than 3 rows"),
            std::string::npos);
  EXPECT_NE(error_of([&] {
              read_plain_recording((dir_ / "none.csv").string());
            }).find("none.csv: no such file"),
            std::string::npos);
  EXPECT_NE(error_of([&] { read_plain_recording(dir_.string()); }).find("not a regular file"),
            std::string::npos);
}

TEST(JointLogThinning, KeepsReadingsAtLeastTheSpacingApartAndBothEnds) {
  JointLog log;
  for (int i = 0; i <= 1000; ++i) {  // 1 s at 1 ms, times as a 1 kHz loop accumulates them
    log.t.push_back(0.001 * i);
    log.theta.push_back(std::sin(0.001 * i));
  }
  const JointLog thin = thin_joint_log(log, 0.02);
  EXPECT_EQ(thin.t.front(), 0.0);
  EXPECT_EQ(thin.t.back(), 1.0);
  for (std::size_t k = 1; k < thin.t.size(); ++k) {
    EXPECT_GE(thin.t[k] - thin.t[k - 1], 0.02 - 1e-12) << k;
    EXPECT_LT(thin.t[k] - thin.t[k - 1], 0.04) << k;
  }
  for (std::size_t k = 0; k < thin.t.size(); ++k) EXPECT_EQ(thin.theta[k], std::sin(thin.t[k]));
  EXPECT_EQ(thin_joint_log(log, 0.0).t, log.t);
  EXPECT_THROW(thin_joint_log(log, -1.0), std::invalid_argument);
}

TEST_F(RecordingFiles, JointLogTakesAnOptionalHeader) {
  const std::string with = write("enc.csv", "t,theta\n0,0\n0.001,1e-6\n0.002,4e-6\n0.003,9e-6\n");
  const JointLog a = read_joint_log(with);
  EXPECT_EQ(a.t, (std::vector<double>{0, 0.001, 0.002, 0.003}));
  EXPECT_EQ(a.theta, (std::vector<double>{0, 1e-6, 4e-6, 9e-6}));
  const std::string without = write("enc2.csv", "0,0\n0.001,1e-6\n0.002,4e-6\n0.003,9e-6\n");
  EXPECT_EQ(read_joint_log(without).t, a.t);
  const std::string bad = write("enc3.csv", "0,0\n0.001,1e-6\n0.001,4e-6\n0.003,9e-6\n");
  EXPECT_NE(error_of([&] { read_joint_log(bad); }).find("enc3.csv:3: t 0.001 is not after"),
            std::string::npos);
  const std::string text = write("enc4.csv", "t,theta\n0,0\nx,1\n");
  EXPECT_NE(error_of([&] { read_joint_log(text); }).find("enc4.csv:3: expected two numbers"),
            std::string::npos);
}

/// An experiment's log as the closed loop writes it (drivers' own writers): the reader must
/// take the joint's readings from log.csv and the measured frames from frames.csv.
TEST_F(RecordingFiles, ExperimentLogAsTheLoopWritesIt) {
  using flatland::drivers::FrameLog;
  using flatland::drivers::TickLog;
  std::vector<TickLog> ticks;
  for (int i = 0; i < 200; ++i) {
    TickLog r;
    r.t = -0.05 + 0.001 * i;
    r.theta = 0.3 * r.t * r.t;
    r.mode = "dip";
    ticks.push_back(r);
  }
  std::vector<FrameLog> frames;
  for (int i = 0; i < 7; ++i) {
    FrameLog f;
    f.index = i;
    f.t_capture = -0.06 + 0.035 * i;  // the first before the joint log, the last after it
    f.t_arrival = f.t_received = f.t_capture + 0.004;
    f.tracked = true;
    f.measured = i != 2;  // frame 2: no measurement
    f.s_meas = -1 + 0.01 * i;
    f.sigma_s = 1e-3 * (1 + i);
    frames.push_back(f);
  }
  write("run/log.csv", flatland::drivers::tick_log_csv(ticks));
  write("run/frames.csv", flatland::drivers::frame_log_csv(frames));
  ReadSummary summary;
  const Recording r = read_experiment_recording((dir_ / "run").string(), &summary);
  // The joint's readings, every 20th (20 ms apart, kJointLogSpacing), and the last (199) in
  // place of the 180th, which is closer to it than that.
  ASSERT_EQ(r.joint_t.size(), 10u);
  for (std::size_t k = 0; k < 9; ++k) {
    EXPECT_EQ(r.joint_t[k], ticks[20 * k].t);
    EXPECT_EQ(r.joint_theta[k], ticks[20 * k].theta);
  }
  EXPECT_EQ(r.joint_t.back(), ticks.back().t);
  // Unthinned on request.
  const Recording all = read_experiment_recording((dir_ / "run").string(), nullptr, {}, 0.0);
  ASSERT_EQ(all.joint_t.size(), ticks.size());
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    EXPECT_EQ(all.joint_t[i], ticks[i].t);
    EXPECT_EQ(all.joint_theta[i], ticks[i].theta);
  }
  // Frames 1, 3, 4, 5: frame 0 precedes the log, 2 is not measured, 6 follows the log.
  ASSERT_EQ(r.t.size(), 4u);
  const int kept[] = {1, 3, 4, 5};
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(r.t[k], frames[static_cast<std::size_t>(kept[k])].t_capture);
    EXPECT_EQ(r.s_h[k], frames[static_cast<std::size_t>(kept[k])].s_meas);
    EXPECT_EQ(r.sigma[k], frames[static_cast<std::size_t>(kept[k])].sigma_s);
  }
  EXPECT_EQ(summary.rows, 7);
  ASSERT_EQ(summary.skipped.size(), 2u);
  EXPECT_EQ(summary.skipped[0], (std::pair<std::string, long>{"outside the joint log", 2}));
  EXPECT_EQ(summary.skipped[1], (std::pair<std::string, long>{"not measured", 1}));
  // The log.csv path names the same recording.
  EXPECT_EQ(read_experiment_recording((dir_ / "run" / "log.csv").string()).t, r.t);
  // A missing frames.csv is named.
  fs::remove(dir_ / "run" / "frames.csv");
  EXPECT_NE(error_of([&] {
              read_experiment_recording((dir_ / "run").string());
            }).find("frames.csv: no such file"),
            std::string::npos);
}

constexpr const char* kTrack =
    "frame,t,u,v,sigma_px,quality,state,s_h\n"
    "0,0,,,,,unreadable,\n"
    "1,0.1,300,200,0.1,0.95,found,\n"
    "2,0.2,,,,0,lost,\n"
    "3,0.3,302,201,0.2,0.3,low_quality,\n"
    "4,0.4,304,202,0.1,0.95,found,\n"
    "5,0.5,306,203,0.1,0.95,tracking,\n"
    "6,0.6,308,204,0.1,0.95,tracking,\n"
    "7,0.7,310,205,0.1,0.95,tracking,\n";

TEST_F(RecordingFiles, TrackCsvKeepsTheFramesWithTheDisk) {
  const std::string p = write("track.csv", kTrack);
  ReadSummary summary;
  const PixelTrack track = read_track_csv(p, &summary);
  EXPECT_EQ(track.t, (std::vector<double>{0.1, 0.4, 0.5, 0.6, 0.7}));
  EXPECT_EQ(track.u, (std::vector<double>{300, 304, 306, 308, 310}));
  EXPECT_EQ(track.line, (std::vector<int>{3, 6, 7, 8, 9}));
  EXPECT_EQ(summary.rows, 8);
  EXPECT_EQ(summary.skipped.size(), 3u);  // unreadable, lost, low_quality: one each
  const std::string bad = write("bad.csv", std::string(kTrack) + "8,0.65,1,1,0.1,0.9,found,\n");
  EXPECT_NE(error_of([&] { read_track_csv(bad); }).find("bad.csv:10: t 0.65 is not after"),
            std::string::npos);
  const std::string no_sigma =
      write("nosigma.csv", "frame,t,u,v,sigma_px,quality,state,s_h\n0,0,300,200,,0.9,found,\n");
  EXPECT_NE(error_of([&] { read_track_csv(no_sigma); }).find(":2: a tracked centre needs u, v"),
            std::string::npos);
}

/// The mapping is the caller's: a mapper that is a closed form (s_h = (u - 300) / 100 + theta)
/// shows which angle each centre was mapped at and that the encoder offset is applied once.
TEST_F(RecordingFiles, PixelsBecomeARecordingThroughTheMapper) {
  const PixelTrack track = read_track_csv(write("track.csv", kTrack));
  JointLog joint;
  for (int i = 0; i <= 6; ++i) {  // 0 ... 0.6 s: frame 7 (0.7 s) lies outside
    joint.t.push_back(0.1 * i);
    joint.theta.push_back(0.5 * 0.1 * i);
  }
  const double offset = 0.25;
  const ContactMapper mapper = [](double u, double, double sigma_px, double theta,
                                  double) -> std::optional<ContactSample> {
    return ContactSample{(u - 300) / 100 + theta, sigma_px / 100};
  };
  ReadSummary summary;
  const Recording r = pixels_to_recording(track, joint, mapper, offset, &summary);
  ASSERT_EQ(r.t.size(), 4u);
  for (std::size_t i = 0; i < 4; ++i) {
    const double theta = 0.5 * track.t[i] + offset;
    EXPECT_NEAR(r.s_h[i], (track.u[i] - 300) / 100 + theta, 1e-15);
    EXPECT_EQ(r.sigma[i], track.sigma_px[i] / 100);
  }
  ASSERT_EQ(r.joint_theta.size(), joint.theta.size());
  for (std::size_t i = 0; i < joint.theta.size(); ++i)
    EXPECT_EQ(r.joint_theta[i], joint.theta[i] + offset);
  EXPECT_EQ(summary.skipped.back(), (std::pair<std::string, long>{"outside the joint log", 1}));
  // No angle for a track.csv without the encoder log.
  EXPECT_NE(error_of([&] {
              pixels_to_recording(track, std::nullopt, mapper);
            }).find("joint's encoder log"),
            std::string::npos);
}

TEST_F(RecordingFiles, PixelCsvCarriesItsOwnAngles) {
  const std::string p = write("px.csv",
                              "t,u,v,theta,sigma_px\n0,300,200,0,0.1\n0.1,301,200,0.1,0.1\n"
                              "0.2,302,200,0.2,0.1\n0.3,303,200,0.3,0.1\n");
  const PixelTrack track = read_pixel_csv(p);
  EXPECT_EQ(track.theta, (std::vector<double>{0, 0.1, 0.2, 0.3}));
  const ContactMapper mapper = [](double u, double, double, double theta,
                                  double) -> std::optional<ContactSample> {
    if (u == 301) return std::nullopt;  // a ray that misses
    return ContactSample{theta, 0.01};
  };
  ReadSummary summary;
  EXPECT_NE(error_of([&] {
              pixels_to_recording(track, std::nullopt, mapper, 0, &summary);
            }).find("3 centres mapped to the hand, identify needs at least 4"),
            std::string::npos);
  EXPECT_EQ(summary.skipped.front(), (std::pair<std::string, long>{"not mapped to the hand", 1}));
}

}  // namespace
