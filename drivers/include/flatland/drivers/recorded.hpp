// Recorded drivers: write what the closed loop saw (frames, joint readings, commands) to a
// recording directory, and play it back as a Camera and a Joint so that a run can be replayed
// bit for bit. The format is described in docs/RECORDING.md.
#pragma once

#include "flatland/drivers/interfaces.hpp"
#include "flatland/files/output_set.hpp"

#include "flatland/vision/video_reader.hpp"

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace flatland::drivers {

/// What recording.json says about the run besides the counts.
struct RecordingMetadata {
  double rate_hz = 1000;  ///< the loop's tick rate
  std::string camera;     ///< Camera::describe() of the camera recorded
  std::string joint;      ///< Joint::describe() of the joint recorded
  std::string scene;      ///< the scene file the run used
};

/// Writes a recording directory. Everything goes into a staging sibling directory
/// (".DIR.tmp-<pid>", files::OutputSet) that finish() renames to DIR, so DIR either holds a
/// complete recording or does not exist: destroying the Recorder without finish() (an exception in
/// the loop) removes the staging directory, and so does an interrupt handler that calls
/// files::abandon_outputs. A killed process can leave a ".DIR.tmp-*" directory behind, never a
/// half-written DIR.
class Recorder {
 public:
  /// std::invalid_argument if `dir` exists and is not an empty directory (nothing is written
  /// then) or if metadata.rate_hz is not positive; std::runtime_error if the temporary directory
  /// cannot be created. Missing parent directories are created (and removed again, if empty,
  /// when the recording is abandoned).
  Recorder(std::filesystem::path dir, RecordingMetadata metadata);
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;
  ~Recorder();

  /// Write the frame as frames/NNNNNN.png (lossless) and its row of frames.csv. The PNG is
  /// encoded on a background thread (a few ms per frame would stall a 1 kHz loop); the image is
  /// copied first, and an encoding failure is reported by a later call. The index must
  /// increase from frame to frame, t_capture increase and t_arrival not decrease, with
  /// t_arrival >= t_capture (std::logic_error otherwise: the reader would reject the recording).
  void add_frame(const CameraFrame& frame);
  /// One loop tick: the reading the loop got (at reading.t, which must increase) and the
  /// acceleration it commanded.
  void add_tick(const control::JointReading& reading, double theta_ddot_cmd);
  /// Write recording.json and rename the temporary directory to DIR. std::runtime_error (naming
  /// the file) on an I/O failure, here or in add_frame/add_tick; the recording is then abandoned
  /// (its temporary directory removed) and further calls throw std::logic_error.
  void finish();

  const std::filesystem::path& directory() const { return dir_; }
  long frames() const { return frames_; }
  long ticks() const { return ticks_; }

 private:
  struct FrameWriter;  // encodes PNGs on a background thread (recorded.cpp)

  void require_open(const char* what) const;
  void check_stream(const std::ofstream& f, const std::string& name);
  void abandon() noexcept;

  std::filesystem::path dir_;
  std::optional<files::OutputSet> outputs_;  // the staging of DIR; empty once finished
  std::filesystem::path tmp_;                // where DIR is built, empty once finished
  RecordingMetadata meta_;
  std::unique_ptr<FrameWriter> writer_;
  std::ofstream frames_csv_, joint_csv_;
  long frames_ = 0, ticks_ = 0;
  long last_index_ = 0;
  double last_capture_ = 0, last_arrival_ = 0, last_tick_t_ = 0;
  bool finished_ = false;
};

/// One row of frames.csv (or of a video's timestamps file, whose `file` is empty).
struct FrameRecord {
  long index = 0;
  double t_capture = 0;
  double t_arrival = 0;
  std::filesystem::path file;  ///< resolved image path; empty for a video
};

/// Plays back frames: either a recording directory (DIR/frames.csv and the images it lists) or a
/// video file with its timestamps in FILE.timestamps.csv beside it ("run.avi.timestamps.csv";
/// "run.timestamps.csv" is taken if only that exists; columns index,t_capture,t_arrival; one row
/// per video frame, in order). Everything that can be checked before the run (a video's reader
/// decodes it once through) is checked by the constructor, which throws a one-line
/// std::invalid_argument naming the file and the reason. A video is read through
/// vision::VideoReader, as `flatland track` reads it: its damaged, repeated and unreadable frames
/// are handed out flagged (CameraFrame::integrity), in their place, and the loop measures none of
/// them. An image of a recording directory that fails to decode is handed out as unreadable. A
/// warning on stderr names the first flagged frames.
class RecordedCamera : public Camera {
 public:
  explicit RecordedCamera(const std::filesystem::path& path);

  /// The next recorded frame with t_arrival <= now (in recorded order), nullopt if the next one
  /// has not arrived yet or the recording is exhausted.
  std::optional<CameraFrame> poll(double now) override;
  /// "video:<path>" with the path as given.
  std::string describe() const override;

  /// Every frame of the recording, in order (with its timestamps).
  const std::vector<FrameRecord>& records() const { return records_; }
  /// Frames handed out so far, and of them the ones flagged (not intact: no measurement).
  long delivered() const { return delivered_; }
  long flagged() const { return flagged_; }
  /// True once every frame has been handed out.
  bool exhausted() const { return next_ >= records_.size(); }

 private:
  void warn_flagged(const CameraFrame& frame);

  std::filesystem::path path_;
  bool is_video_ = false;
  std::vector<FrameRecord> records_;
  std::size_t next_ = 0;
  std::optional<vision::VideoReader> video_;
  long delivered_ = 0, flagged_ = 0;
};

/// Plays back a recording's joint log (DIR/joint.csv, or the CSV file itself): read(t) returns
/// the reading of the next logged tick, whose t must equal the loop's t exactly, and command()
/// compares the loop's command with the logged one, bit for bit. The constructor throws
/// std::invalid_argument naming the file and the reason for a bad log; read() and command()
/// throw std::runtime_error naming the tick when the loop and the log disagree on time.
class LogJoint : public Joint {
 public:
  explicit LogJoint(const std::filesystem::path& path);

  control::JointReading read(double t) override;
  /// Compare with the logged command of the tick last read (which must be at time t).
  void command(double t, double theta_ddot) override;
  /// "log:<path>" with the path as given.
  std::string describe() const override;
  /// The logged command of the tick last read (NaN before the first read).
  double recorded_command() const override;

  /// Logged ticks, ticks read so far and commands given so far.
  long ticks() const { return static_cast<long>(log_.size()); }
  long ticks_read() const { return static_cast<long>(next_); }
  long commands() const { return commands_; }
  /// Commands that are not bit-identical to the logged ones, the first such tick (-1: none) and
  /// the largest |given - logged| (0 when all agree; NaN if either side was NaN).
  long mismatches() const { return mismatches_; }
  long first_mismatch_tick() const { return first_mismatch_tick_; }
  double max_command_difference() const { return max_difference_; }

 private:
  struct Tick {
    long tick = 0;
    control::JointReading reading;
    double theta_ddot_cmd = 0;
  };
  std::filesystem::path path_;
  std::vector<Tick> log_;
  std::size_t next_ = 0;
  long commands_ = 0, mismatches_ = 0, first_mismatch_tick_ = -1;
  double max_difference_ = 0;
};

}  // namespace flatland::drivers
