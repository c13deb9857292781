#include "flatland/drivers/recorded.hpp"
#include "flatland/sim/format.hpp"

#include "flatland/vision/image_file.hpp"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <iostream>
#include <limits>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string_view>
#include <system_error>
#include <thread>
#include <utility>

namespace flatland::drivers {

namespace fs = std::filesystem;

namespace {

constexpr std::string_view kFramesHeader = "index,t_capture,t_arrival,file";
constexpr std::string_view kTimestampsHeader = "index,t_capture,t_arrival";
constexpr std::string_view kJointHeader = "tick,t,theta,theta_dot,theta_ddot_cmd";
// Warnings about undecodable frames stop after this many: a video cut short would otherwise
// print one line per missing frame.
constexpr long kMaxSkipWarnings = 10;

/// Shortest text that reads back as the same double (std::to_chars round-trips exactly).
std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (const char c : s) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\r':
        out += "\\r";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(c));
          out += buf;
        } else {
          out += c;
        }
    }
  }
  return out + "\"";
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

/// A whole CSV file with a fixed header, read row by row; every error is a one-line
/// std::invalid_argument "FILE: line N: reason".
class CsvReader {
 public:
  CsvReader(fs::path path, std::string_view header) : path_(std::move(path)) {
    std::error_code ec;
    const auto st = fs::status(path_, ec);
    if (!fs::exists(st)) fail_file("missing");
    if (!fs::is_regular_file(st)) fail_file("not a regular file");
    std::ifstream f(path_, std::ios::binary);
    if (!f) fail_file("cannot open for reading");
    std::stringstream ss;
    ss << f.rdbuf();
    if (f.bad()) fail_file("read error");
    content_ = ss.str();
    if (content_.empty()) fail_file("zero-length file");
    if (!next_line()) fail_file("zero-length file");
    if (trim(line_) != header)
      fail("bad header '" + std::string(trim(line_)) + "' (expected '" + std::string(header) +
           "')");
    columns_ = static_cast<std::size_t>(std::count(header.begin(), header.end(), ',')) + 1;
  }

  /// Advance to the next data row; false at the end. Blank lines are allowed only at the end.
  bool next() {
    if (!next_line()) return false;
    if (trim(line_).empty()) {
      const int blank = line_no_;
      while (next_line())
        if (!trim(line_).empty()) {
          line_no_ = blank;
          fail("blank line");
        }
      return false;
    }
    fields_.clear();
    std::string_view rest = line_;
    for (;;) {
      const auto comma = rest.find(',');
      fields_.push_back(trim(rest.substr(0, comma)));
      if (comma == std::string_view::npos) break;
      rest.remove_prefix(comma + 1);
    }
    if (fields_.size() != columns_)
      fail("expected " + std::to_string(columns_) + " fields, got " +
           std::to_string(fields_.size()));
    return true;
  }

  long integer(std::size_t col, std::string_view name) const {
    const std::string_view s = fields_[col];
    long v = 0;
    const auto res = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || res.ec != std::errc() || res.ptr != s.data() + s.size())
      fail("non-numeric " + std::string(name) + " '" + std::string(s) + "'");
    return v;
  }

  /// A double; `finite` rejects inf and nan (times must be finite, logged values may not be).
  double real(std::size_t col, std::string_view name, bool finite) const {
    const std::string_view s = fields_[col];
    double v = 0;
    const auto res = std::from_chars(s.data(), s.data() + s.size(), v);
    if (s.empty() || res.ec != std::errc() || res.ptr != s.data() + s.size())
      fail("non-numeric " + std::string(name) + " '" + std::string(s) + "'");
    if (finite && !std::isfinite(v))
      fail(std::string(name) + " is not finite ('" + std::string(s) + "')");
    return v;
  }

  std::string_view text(std::size_t col) const { return fields_[col]; }
  int line() const { return line_no_; }
  const fs::path& path() const { return path_; }

  [[noreturn]] void fail(const std::string& reason) const {
    throw std::invalid_argument(path_.string() + ": line " + std::to_string(line_no_) + ": " +
                                reason);
  }

 private:
  [[noreturn]] void fail_file(const std::string& reason) const {
    throw std::invalid_argument(path_.string() + ": " + reason);
  }

  bool next_line() {
    if (pos_ >= content_.size()) return false;
    const auto nl = content_.find('\n', pos_);
    const auto end = nl == std::string::npos ? content_.size() : nl;
    line_ = std::string_view(content_).substr(pos_, end - pos_);
    pos_ = nl == std::string::npos ? content_.size() : nl + 1;
    ++line_no_;
    return true;
  }

  fs::path path_;
  std::string content_;
  std::size_t pos_ = 0;
  int line_no_ = 0;
  std::string_view line_;
  std::size_t columns_ = 0;
  std::vector<std::string_view> fields_;
};

/// Read the index and the two times of a frames.csv or timestamps row and check them against
/// the previous row.
FrameRecord read_frame_row(const CsvReader& csv, const FrameRecord* previous) {
  FrameRecord r;
  r.index = csv.integer(0, "index");
  r.t_capture = csv.real(1, "t_capture", true);
  r.t_arrival = csv.real(2, "t_arrival", true);
  if (r.index < 0) csv.fail("negative index " + std::to_string(r.index));
  if (r.t_arrival < r.t_capture)
    csv.fail("t_arrival " + sim::format_number(r.t_arrival) + " < t_capture " +
             sim::format_number(r.t_capture));
  if (previous) {
    if (r.index <= previous->index)
      csv.fail("non-monotonic index " + std::to_string(r.index) + " after " +
               std::to_string(previous->index));
    if (r.t_capture <= previous->t_capture)
      csv.fail("non-monotonic t_capture " + sim::format_number(r.t_capture) + " after " +
               sim::format_number(previous->t_capture));
    if (r.t_arrival < previous->t_arrival)
      csv.fail("non-monotonic t_arrival " + sim::format_number(r.t_arrival) + " after " +
               sim::format_number(previous->t_arrival));
  }
  return r;
}

/// Structural checks shared with flatland track and calibrate (vision/image_file.hpp).
using vision::image_file_problem;

cv::Mat read_image(const fs::path& p) {
  try {
    // ANYCOLOR keeps grey images grey and drops an alpha channel (CameraFrame: 8UC1 or 8UC3).
    return cv::imread(p.string(), cv::IMREAD_ANYCOLOR);
  } catch (const cv::Exception&) {
    return {};
  }
}

bool same_double(double a, double b) {
  if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b);
  return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Recorder

struct Recorder::FrameWriter {
  struct Job {
    fs::path file;
    cv::Mat image;
  };
  // Bounded so that a disk slower than the camera slows the loop down instead of filling memory.
  static constexpr std::size_t kCapacity = 64;

  FrameWriter() : thread([this] { run(); }) {}
  ~FrameWriter() { stop(true); }

  void push(Job job) {
    std::unique_lock lock(mutex);
    space.wait(lock, [&] { return queue.size() < kCapacity; });
    queue.push_back(std::move(job));
    work.notify_one();
  }

  /// Write what is queued (or, with `discard`, drop it) and end the thread; the first error.
  std::string stop(bool discard) {
    {
      std::lock_guard lock(mutex);
      if (discard) queue.clear();
      stopping = true;
      work.notify_one();
    }
    if (thread.joinable()) thread.join();
    std::lock_guard lock(mutex);
    return error;
  }

  std::string first_error() {
    std::lock_guard lock(mutex);
    return error;
  }

  void run() {
    std::unique_lock lock(mutex);
    for (;;) {
      work.wait(lock, [&] { return stopping || !queue.empty(); });
      if (queue.empty()) return;
      Job job = std::move(queue.front());
      queue.pop_front();
      space.notify_one();
      if (!error.empty()) continue;  // the recording is lost already; drain the queue
      lock.unlock();
      std::string failure;
      try {
        if (!cv::imwrite(job.file.string(), job.image)) failure = "cannot write the frame image";
      } catch (const cv::Exception& e) {
        failure = "cannot write the frame image (" + e.err + ")";
      }
      lock.lock();
      if (!failure.empty() && error.empty()) error = job.file.string() + ": " + failure;
    }
  }

  std::mutex mutex;
  std::condition_variable work, space;
  std::deque<Job> queue;
  bool stopping = false;
  std::string error;
  std::thread thread;  // last: started once the members it uses exist
};

Recorder::Recorder(fs::path dir, RecordingMetadata metadata)
    : dir_(std::move(dir)), meta_(std::move(metadata)) {
  if (dir_.empty()) throw std::invalid_argument("--record: empty directory name");
  // "run/" names the directory run: it is staged as the sibling ".run.tmp-<pid>".
  if (!dir_.has_filename()) dir_ = dir_.parent_path();
  if (!std::isfinite(meta_.rate_hz) || !(meta_.rate_hz > 0))
    throw std::invalid_argument("--record " + dir_.string() + ": rate_hz must be positive, got " +
                                sim::format_number(meta_.rate_hz));
  std::error_code ec;
  const auto st = fs::symlink_status(dir_, ec);
  if (fs::exists(st) && !(fs::is_directory(st) && fs::is_empty(dir_, ec) && !ec))
    throw std::invalid_argument("--record " + dir_.string() +
                                ": already exists (a recording is never overwritten)");

  try {
    // Staged beside DIR and moved into place by finish() (files::OutputSet: missing parents are
    // created and removed again if the recording is abandoned).
    outputs_.emplace();
    tmp_ = outputs_->begin_directory(dir_);
    if (!fs::create_directory(tmp_ / "frames", ec))
      throw std::runtime_error((tmp_ / "frames").string() + ": cannot create directory (" +
                               ec.message() + ")");
    frames_csv_.open(tmp_ / "frames.csv", std::ios::binary);
    frames_csv_ << kFramesHeader << '\n';
    check_stream(frames_csv_, "frames.csv");
    joint_csv_.open(tmp_ / "joint.csv", std::ios::binary);
    joint_csv_ << kJointHeader << '\n';
    check_stream(joint_csv_, "joint.csv");
    writer_ = std::make_unique<FrameWriter>();
  } catch (...) {
    abandon();
    throw;
  }
}

Recorder::~Recorder() {
  if (!finished_) abandon();
}

void Recorder::abandon() noexcept {
  writer_.reset();  // discards queued frames and joins the thread
  frames_csv_.close();
  joint_csv_.close();
  outputs_.reset();  // removes the staging directory and the parents it created
  tmp_.clear();
}

void Recorder::require_open(const char* what) const {
  if (finished_) throw std::logic_error(std::string("Recorder::") + what + " after finish()");
  if (tmp_.empty())
    throw std::logic_error(std::string("Recorder::") + what + " on an abandoned recording");
}

void Recorder::check_stream(const std::ofstream& f, const std::string& name) {
  if (f) return;
  const std::string msg = (tmp_ / name).string() + ": write error";
  abandon();  // the recording is lost: later calls fail fast instead of writing more of it
  throw std::runtime_error(msg);
}

void Recorder::add_frame(const CameraFrame& frame) {
  require_open("add_frame");
  if (const std::string e = writer_->first_error(); !e.empty()) {
    abandon();
    throw std::runtime_error(e);
  }
  const std::string which = "Recorder: frame " + std::to_string(frame.index) + ": ";
  if (frame.image.empty()) throw std::logic_error(which + "no image");
  if (frame.index < 0) throw std::logic_error(which + "negative index");
  if (!std::isfinite(frame.t_capture) || !std::isfinite(frame.t_arrival))
    throw std::logic_error(which + "times must be finite");
  if (frame.t_arrival < frame.t_capture) throw std::logic_error(which + "t_arrival < t_capture");
  if (frames_ > 0 && (frame.index <= last_index_ || frame.t_capture <= last_capture_ ||
                      frame.t_arrival < last_arrival_))
    throw std::logic_error(which + "index and times must increase (previous frame " +
                           std::to_string(last_index_) + ")");
  char name[32];
  std::snprintf(name, sizeof name, "frames/%06ld.png", frame.index);
  // A deep copy: the camera may reuse its buffer for the next frame while the writer encodes.
  writer_->push({tmp_ / name, frame.image.clone()});
  frames_csv_ << frame.index << ',' << sim::format_number(frame.t_capture) << ','
              << sim::format_number(frame.t_arrival) << ',' << name << '\n';
  check_stream(frames_csv_, "frames.csv");
  ++frames_;
  last_index_ = frame.index;
  last_capture_ = frame.t_capture;
  last_arrival_ = frame.t_arrival;
}

void Recorder::add_tick(const control::JointReading& reading, double theta_ddot_cmd) {
  require_open("add_tick");
  if (!std::isfinite(reading.t) || (ticks_ > 0 && !(reading.t > last_tick_t_)))
    throw std::logic_error("Recorder: tick " + std::to_string(ticks_) + ": t " +
                           sim::format_number(reading.t) + " must be finite and increase");
  joint_csv_ << ticks_ << ',' << sim::format_number(reading.t) << ','
             << sim::format_number(reading.theta) << ',' << sim::format_number(reading.theta_dot)
             << ',' << sim::format_number(theta_ddot_cmd) << '\n';
  check_stream(joint_csv_, "joint.csv");
  ++ticks_;
  last_tick_t_ = reading.t;
}

void Recorder::finish() {
  require_open("finish");
  try {
    if (const std::string e = writer_->stop(false); !e.empty()) throw std::runtime_error(e);
    frames_csv_.close();
    check_stream(frames_csv_, "frames.csv");
    joint_csv_.close();
    check_stream(joint_csv_, "joint.csv");

    std::ofstream json(tmp_ / "recording.json", std::ios::binary);
    json << "{\n  \"version\": 1,\n  \"rate_hz\": " << sim::format_number(meta_.rate_hz)
         << ",\n  \"frames\": " << frames_ << ",\n  \"ticks\": " << ticks_
         << ",\n  \"camera\": " << json_string(meta_.camera)
         << ",\n  \"joint\": " << json_string(meta_.joint)
         << ",\n  \"scene\": " << json_string(meta_.scene) << "\n}\n";
    json.close();
    check_stream(json, "recording.json");

    // Replaces an empty directory at DIR; refuses one that something was put in since the
    // constructor looked.
    outputs_->commit();
  } catch (...) {
    abandon();
    throw;
  }
  tmp_.clear();
  outputs_.reset();
  finished_ = true;
}

// ---------------------------------------------------------------------------------------------
// RecordedCamera

RecordedCamera::RecordedCamera(const fs::path& path) : path_(path) {
  std::error_code ec;
  const auto st = fs::status(path_, ec);
  if (!fs::exists(st)) throw std::invalid_argument(path_.string() + ": no such file or directory");

  // A recording is named by its directory or by its frames.csv.
  const bool is_csv = path_.filename() == "frames.csv" && fs::is_regular_file(st);
  if (fs::is_directory(st) || is_csv) {
    const fs::path dir = is_csv ? path_.parent_path() : path_;
    CsvReader csv(dir / "frames.csv", kFramesHeader);
    while (csv.next()) {
      FrameRecord r = read_frame_row(csv, records_.empty() ? nullptr : &records_.back());
      const std::string_view file = csv.text(3);
      if (file.empty()) csv.fail("empty file name");
      r.file = dir / fs::path(std::string(file));
      if (const std::string problem = image_file_problem(r.file); !problem.empty())
        throw std::invalid_argument(r.file.string() + ": " + problem + " (" + csv.path().string() +
                                    " line " + std::to_string(csv.line()) + ")");
      records_.push_back(std::move(r));
    }
    // The structural check above does not decode; decoding one frame catches a file OpenCV
    // cannot read at all (an unsupported format) before the run starts.
    if (!records_.empty() && read_image(records_.front().file).empty())
      throw std::invalid_argument(records_.front().file.string() + ": cannot decode the image");
    return;
  }

  is_video_ = true;
  if (!fs::is_regular_file(st)) throw std::invalid_argument(path_.string() + ": not a file");
  const auto size = fs::file_size(path_, ec);
  if (ec) throw std::invalid_argument(path_.string() + ": unreadable (" + ec.message() + ")");
  if (size == 0) throw std::invalid_argument(path_.string() + ": zero-length file");
  // run.avi.timestamps.csv, or run.timestamps.csv (named after the stem) if only that exists.
  fs::path stamps = path_.string() + ".timestamps.csv";
  if (fs::path alt = fs::path(path_).replace_extension(".timestamps.csv");
      !fs::exists(stamps, ec) && fs::exists(alt, ec))
    stamps = alt;
  if (!fs::exists(stamps, ec))
    throw std::invalid_argument(stamps.string() +
                                ": missing (a video needs its frame times beside it)");
  CsvReader csv(stamps, kTimestampsHeader);
  while (csv.next())
    records_.push_back(read_frame_row(csv, records_.empty() ? nullptr : &records_.back()));

  try {
    video_.emplace(path_.string());
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument(path_.string() + ": cannot open as a video");
  }
  const long count = video_->frame_count();
  const auto expected = static_cast<long>(records_.size());
  if (count != expected)
    throw std::invalid_argument(path_.string() + ": frame count mismatch: the video has " +
                                std::to_string(count) + " frames, " + stamps.string() + " lists " +
                                std::to_string(expected));
}

std::string RecordedCamera::describe() const { return "video:" + path_.string(); }

void RecordedCamera::warn_flagged(const CameraFrame& frame) {
  ++flagged_;
  if (flagged_ <= kMaxSkipWarnings)
    std::cerr << "flatland: warning: " << describe() << ": frame " << frame.index << " is "
              << vision::to_string(frame.integrity) << "; not measured\n";
  if (flagged_ == kMaxSkipWarnings)
    std::cerr << "flatland: warning: " << describe() << ": further flagged frames not reported\n";
}

std::optional<CameraFrame> RecordedCamera::poll(double now) {
  if (next_ >= records_.size() || records_[next_].t_arrival > now) return std::nullopt;
  const FrameRecord& r = records_[next_++];
  CameraFrame frame;
  frame.index = r.index;
  frame.t_capture = r.t_capture;
  frame.t_arrival = r.t_arrival;
  if (video_) {
    vision::VideoReader::Frame v;
    if (!video_->read(v)) v.integrity = vision::FrameIntegrity::kUnreadable;
    frame.image = std::move(v.image);
    frame.integrity = v.integrity;
  } else {
    // A recording's own frames are lossless and replayed bit for bit: no repeat check (the run
    // that recorded them measured a still scene's frames too).
    frame.image = read_image(r.file);
    if (frame.image.empty()) frame.integrity = vision::FrameIntegrity::kUnreadable;
  }
  ++delivered_;
  if (frame.integrity != vision::FrameIntegrity::kIntact) warn_flagged(frame);
  return frame;
}

// ---------------------------------------------------------------------------------------------
// LogJoint

LogJoint::LogJoint(const fs::path& path) : path_(path) {
  std::error_code ec;
  if (!fs::exists(path_, ec))
    throw std::invalid_argument(path_.string() + ": no such file or directory");
  CsvReader csv(fs::is_directory(path_, ec) ? path_ / "joint.csv" : path_, kJointHeader);
  while (csv.next()) {
    Tick k;
    k.tick = csv.integer(0, "tick");
    k.reading.t = csv.real(1, "t", true);
    // Angles and the command are logged as the loop had them, non-finite values included.
    k.reading.theta = csv.real(2, "theta", false);
    k.reading.theta_dot = csv.real(3, "theta_dot", false);
    k.theta_ddot_cmd = csv.real(4, "theta_ddot_cmd", false);
    if (!log_.empty()) {
      if (k.tick <= log_.back().tick)
        csv.fail("non-monotonic tick " + std::to_string(k.tick) + " after " +
                 std::to_string(log_.back().tick));
      if (k.reading.t <= log_.back().reading.t)
        csv.fail("non-monotonic t " + sim::format_number(k.reading.t) + " after " +
                 sim::format_number(log_.back().reading.t));
    }
    log_.push_back(k);
  }
}

std::string LogJoint::describe() const { return "log:" + path_.string(); }

control::JointReading LogJoint::read(double t) {
  if (next_ >= log_.size())
    throw std::runtime_error(
        describe() + ": tick " + std::to_string(next_) + " (read at t=" + sim::format_number(t) +
        ") is past the end of the log (" + std::to_string(log_.size()) + " ticks)");
  const Tick& k = log_[next_];
  if (!(k.reading.t == t))
    throw std::runtime_error(describe() + ": tick " + std::to_string(k.tick) +
                             ": the loop reads at t=" + sim::format_number(t) +
                             ", the log has t=" + sim::format_number(k.reading.t));
  ++next_;
  return k.reading;
}

double LogJoint::recorded_command() const {
  return next_ == 0 ? std::numeric_limits<double>::quiet_NaN() : log_[next_ - 1].theta_ddot_cmd;
}

void LogJoint::command(double t, double theta_ddot) {
  if (next_ == 0)
    throw std::runtime_error(describe() + ": command at t=" + sim::format_number(t) +
                             " before any tick was read");
  const Tick& k = log_[next_ - 1];
  if (!(k.reading.t == t))
    throw std::runtime_error(describe() + ": tick " + std::to_string(k.tick) +
                             ": command at t=" + sim::format_number(t) +
                             ", the tick is at t=" + sim::format_number(k.reading.t));
  ++commands_;
  double d = 0;
  if (!same_double(theta_ddot, k.theta_ddot_cmd)) {
    ++mismatches_;
    if (first_mismatch_tick_ < 0) first_mismatch_tick_ = k.tick;
    d = std::abs(theta_ddot - k.theta_ddot_cmd);  // 0 for 0 vs -0, NaN if one side is NaN
  }
  if (std::isnan(d) || std::isnan(max_difference_))
    max_difference_ = std::numeric_limits<double>::quiet_NaN();
  else
    max_difference_ = std::max(max_difference_, d);
}

}  // namespace flatland::drivers
