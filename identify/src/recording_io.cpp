// Recordings from files: a bounded CSV reader and the readers of each recording format
// (docs/IDENTIFY.md, "Recordings").
#include "flatland/identify/recording_io.hpp"

#include "flatland/sim/format.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <utility>

namespace flatland::identify {

namespace fs = std::filesystem;

namespace {

/// identify needs at least this many samples and joint entries per recording (check_recording).
constexpr std::size_t kMinRows = 4;

std::string at_line(const std::string& path, int line) {
  return path + ":" + std::to_string(line) + ": ";
}

std::string size_text(std::size_t bytes) {
  return bytes >= (std::size_t{1} << 20) ? std::to_string(bytes >> 20) + " MiB"
                                         : std::to_string(bytes) + " bytes";
}

/// Lines of a file, each bounded, the whole bounded, so that a device, a binary file or a huge
/// file is refused without being read into memory.
class LineReader {
 public:
  LineReader(const std::string& path, const FileLimits& limits) : path_(path), limits_(limits) {
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (ec || !fs::exists(status)) throw std::invalid_argument(path + ": no such file");
    if (!fs::is_regular_file(status)) throw std::invalid_argument(path + ": not a regular file");
    const auto size = fs::file_size(path, ec);
    if (!ec && size > limits.max_bytes)
      throw std::invalid_argument(path + ": larger than " + size_text(limits.max_bytes));
    in_.open(path, std::ios::binary);
    if (!in_) throw std::invalid_argument(path + ": cannot read");
  }
  /// The next line without its end ('\n', and a '\r' before it); false at the end of the file.
  bool next(std::string& line) {
    line.clear();
    int c = 0;
    while ((c = in_.get()) != EOF && c != '\n') {
      if (line.size() >= limits_.max_line)
        throw std::invalid_argument(at_line(path_, number_ + 1) + "a line longer than " +
                                    std::to_string(limits_.max_line) + " bytes");
      line += static_cast<char>(c);
    }
    if (c == EOF && line.empty()) {
      if (in_.bad()) throw std::invalid_argument(path_ + ": read error");
      return false;
    }
    bytes_ += line.size() + 1;
    if (bytes_ > limits_.max_bytes)  // a file that grew while it was read
      throw std::invalid_argument(path_ + ": larger than " + size_text(limits_.max_bytes));
    ++number_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  }
  int number() const { return number_; }

 private:
  std::string path_;
  FileLimits limits_;
  std::ifstream in_;
  std::size_t bytes_ = 0;
  int number_ = 0;
};

std::string trim(std::string_view s) {
  const auto first = s.find_first_not_of(" \t");
  if (first == std::string_view::npos) return {};
  const auto last = s.find_last_not_of(" \t");
  return std::string(s.substr(first, last - first + 1));
}

std::vector<std::string> split_fields(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    fields.push_back(trim(std::string_view(line).substr(
        start, comma == std::string::npos ? std::string::npos : comma - start)));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return fields;
}

/// "t[s]" -> "t".
std::string column_name(const std::string& header_field) {
  return trim(header_field.substr(0, header_field.find('[')));
}

/// The whole cell as a number; nullopt if it is not one.
std::optional<double> parse_number(const std::string& cell) {
  std::string_view s = cell;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  double value = 0;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), value);
  if (s.empty() || ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return value;
}

bool blank_or_comment(const std::string& line) {
  const std::string t = trim(line);
  return t.empty() || t.front() == '#';
}

std::string quote(const std::string& s) {
  return "'" + (s.size() > 40 ? s.substr(0, 40) + "..." : s) + "'";
}

/// Linear interpolation of the joint log at t; nullopt outside it.
std::optional<double> joint_angle(const JointLog& log, double t) {
  if (log.t.empty() || t < log.t.front() || t > log.t.back()) return std::nullopt;
  const auto it = std::upper_bound(log.t.begin(), log.t.end(), t);
  if (it == log.t.end()) return log.theta.back();
  const auto i = static_cast<std::size_t>(it - log.t.begin()) - 1;
  const double w = (t - log.t[i]) / (log.t[i + 1] - log.t[i]);
  return log.theta[i] + w * (log.theta[i + 1] - log.theta[i]);
}

/// "PATH:LINE: t ... is not after ..." unless t increases strictly.
void require_increasing_time(const std::string& path, int line, const std::string& name,
                             double previous, double t) {
  if (!(t > previous))
    throw std::invalid_argument(at_line(path, line) + name + " " + sim::format_number(t) +
                                " is not after the previous row's " + sim::format_number(previous) +
                                " (times must increase strictly)");
}

void require_rows(const std::string& path, std::size_t rows, const std::string& what) {
  if (rows < kMinRows)
    throw std::invalid_argument(path + ": " + std::to_string(rows) + " " + what +
                                ", identify needs at least " + std::to_string(kMinRows));
}

}  // namespace

void ReadSummary::skip(const std::string& why) {
  for (auto& [reason, count] : skipped)
    if (reason == why) {
      ++count;
      return;
    }
  skipped.emplace_back(why, 1);
}

std::size_t CsvTable::index(const std::string& name) const {
  for (std::size_t i = 0; i < columns.size(); ++i)
    if (columns[i].name == name) return i;
  throw std::logic_error("CsvTable: no column " + name + " was requested");
}

CsvTable read_csv_table(const std::string& path, const std::vector<ColumnRequest>& columns,
                        std::size_t min_rows, const FileLimits& limits) {
  LineReader reader(path, limits);
  CsvTable table;
  table.path = path;
  table.columns = columns;
  table.present.assign(columns.size(), false);
  table.values.resize(columns.size());
  table.text.resize(columns.size());
  std::string line;
  // The header: the first line that is not blank or a comment.
  bool have_header = false;
  while (reader.next(line))
    if (!blank_or_comment(line)) {
      have_header = true;
      break;
    }
  if (!have_header) throw std::invalid_argument(path + ": empty (no header line)");
  const int header_line = reader.number();
  const std::vector<std::string> header = split_fields(line);
  if (parse_number(header.front()))
    throw std::invalid_argument(at_line(path, header_line) +
                                "the first line must be a header naming the columns, got numbers");
  std::vector<std::string> names;
  for (const std::string& field : header) {
    const std::string name = column_name(field);
    if (name.empty())
      throw std::invalid_argument(at_line(path, header_line) +
                                  "an empty column name in the header");
    if (std::find(names.begin(), names.end(), name) != names.end())
      throw std::invalid_argument(at_line(path, header_line) + "column " + name +
                                  " appears twice in the header");
    names.push_back(name);
  }
  std::vector<int> field_of(columns.size(), -1);
  for (std::size_t c = 0; c < columns.size(); ++c) {
    const auto it = std::find(names.begin(), names.end(), columns[c].name);
    if (it != names.end()) {
      field_of[c] = static_cast<int>(it - names.begin());
      table.present[c] = true;
    } else if (columns[c].required) {
      throw std::invalid_argument(at_line(path, header_line) + "missing column " + columns[c].name);
    }
  }
  while (reader.next(line)) {
    if (blank_or_comment(line)) continue;
    const int n = reader.number();
    if (table.rows() >= limits.max_rows)
      throw std::invalid_argument(at_line(path, n) + "more than " +
                                  std::to_string(limits.max_rows) + " rows");
    const std::vector<std::string> fields = split_fields(line);
    if (fields.size() != header.size())
      throw std::invalid_argument(at_line(path, n) + "expected " + std::to_string(header.size()) +
                                  " fields as in the header, got " + std::to_string(fields.size()));
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (field_of[c] < 0) continue;
      const std::string& cell = fields[static_cast<std::size_t>(field_of[c])];
      if (columns[c].text) {
        table.text[c].push_back(cell);
        continue;
      }
      if (cell.empty() && columns[c].empty_is_nan) {
        table.values[c].push_back(NAN);
        continue;
      }
      const std::optional<double> v = parse_number(cell);
      if (!v)
        throw std::invalid_argument(at_line(path, n) + columns[c].name +
                                    ": not a number: " + quote(cell));
      if (!std::isfinite(*v))
        throw std::invalid_argument(at_line(path, n) + columns[c].name +
                                    ": not finite: " + quote(cell));
      table.values[c].push_back(*v);
    }
    table.line.push_back(n);
  }
  if (table.rows() < min_rows)
    throw std::invalid_argument(path + ": " + std::to_string(table.rows()) +
                                " data rows, at least " + std::to_string(min_rows) + " needed");
  return table;
}

std::vector<std::string> read_csv_header(const std::string& path, const FileLimits& limits) {
  LineReader reader(path, limits);
  std::string line;
  while (reader.next(line)) {
    if (blank_or_comment(line)) continue;
    std::vector<std::string> names;
    for (const std::string& field : split_fields(line)) names.push_back(column_name(field));
    return names;
  }
  throw std::invalid_argument(path + ": empty (no header line)");
}

JointLog read_joint_log(const std::string& path, const FileLimits& limits) {
  LineReader reader(path, limits);
  JointLog log;
  std::string line;
  bool first = true;
  while (reader.next(line)) {
    if (blank_or_comment(line)) continue;
    const int n = reader.number();
    const std::vector<std::string> fields = split_fields(line);
    const std::optional<double> t = fields.size() == 2 ? parse_number(fields[0]) : std::nullopt;
    const std::optional<double> theta = fields.size() == 2 ? parse_number(fields[1]) : std::nullopt;
    const bool was_first = std::exchange(first, false);
    if (!t || !theta) {
      if (was_first && fields.size() == 2) continue;  // the header
      throw std::invalid_argument(at_line(path, n) + "expected two numbers t,theta, got " +
                                  quote(line));
    }
    if (!std::isfinite(*t) || !std::isfinite(*theta))
      throw std::invalid_argument(at_line(path, n) + "not finite: " + quote(line));
    if (!log.t.empty()) require_increasing_time(path, n, "t", log.t.back(), *t);
    if (log.t.size() >= limits.max_rows)
      throw std::invalid_argument(at_line(path, n) + "more than " +
                                  std::to_string(limits.max_rows) + " rows");
    log.t.push_back(*t);
    log.theta.push_back(*theta);
  }
  require_rows(path, log.t.size(), "rows t,theta");
  return log;
}

JointLog thin_joint_log(const JointLog& log, double spacing) {
  if (!(spacing >= 0) || !std::isfinite(spacing))
    throw std::invalid_argument("joint_spacing: must be >= 0 and finite, got " +
                                sim::format_number(spacing));
  if (log.t.size() < 3) return log;
  // A tick's time is a sum of increments: 20 ticks of 1 ms may add up to a hair under 20 ms.
  const double at_least = spacing * (1 - 1e-9);
  JointLog out;
  for (std::size_t i = 0; i + 1 < log.t.size(); ++i)
    if (out.t.empty() || log.t[i] - out.t.back() >= at_least) {
      out.t.push_back(log.t[i]);
      out.theta.push_back(log.theta[i]);
    }
  // The last reading closes the span; the one kept before it goes if it is closer than spacing.
  if (out.t.size() > 1 && log.t.back() - out.t.back() < at_least) {
    out.t.pop_back();
    out.theta.pop_back();
  }
  out.t.push_back(log.t.back());
  out.theta.push_back(log.theta.back());
  return out;
}

Recording read_plain_recording(const std::string& path, std::optional<double> sigma,
                               ReadSummary* summary, const FileLimits& limits) {
  if (sigma && !(std::isfinite(*sigma) && *sigma > 0))
    throw std::invalid_argument("sigma: must be a finite number > 0, got " +
                                sim::format_number(*sigma));
  const CsvTable table = read_csv_table(
      path, {{"t"}, {"theta"}, {"s_h"}, {.name = "sigma", .required = false}}, 0, limits);
  if (!table.has("sigma") && !sigma)
    throw std::invalid_argument(path + ": no sigma column and no sigma given (s_h's standard " +
                                "deviation weights the fit; it is not guessed)");
  Recording r;
  r.name = path;
  const auto &t = table.column("t"), &theta = table.column("theta"), &s = table.column("s_h");
  for (std::size_t i = 0; i < table.rows(); ++i) {
    if (i > 0) require_increasing_time(path, table.line[i], "t", t[i - 1], t[i]);
    const double sd = table.has("sigma") ? table.column("sigma")[i] : *sigma;
    if (!(sd > 0))
      throw std::invalid_argument(at_line(path, table.line[i]) + "sigma must be > 0, got " +
                                  sim::format_number(sd));
    r.t.push_back(t[i]);
    r.s_h.push_back(s[i]);
    r.sigma.push_back(sd);
  }
  require_rows(path, r.t.size(), "data rows");
  r.joint_t = r.t;
  r.joint_theta = theta;
  if (summary) summary->rows = summary->samples = static_cast<long>(r.t.size());
  check_recording(r);
  return r;
}

Recording read_experiment_recording(const std::string& path, ReadSummary* summary,
                                    const FileLimits& limits, double joint_spacing) {
  const fs::path given(path);
  const fs::path dir = fs::is_directory(given) ? given : given.parent_path();
  const std::string log_path = (fs::is_directory(given) ? dir / "log.csv" : given).string();
  const std::string frames_path = (dir / "frames.csv").string();
  // The joint: the readings the loop took at every tick.
  const CsvTable log = read_csv_table(log_path, {{"t"}, {"theta"}}, 0, limits);
  Recording r;
  r.name = dir.empty() ? path : dir.string();
  const auto &tick_t = log.column("t"), &tick_theta = log.column("theta");
  for (std::size_t i = 1; i < log.rows(); ++i)
    require_increasing_time(log_path, log.line[i], "t", tick_t[i - 1], tick_t[i]);
  require_rows(log_path, log.rows(), "ticks");
  const JointLog joint = thin_joint_log({tick_t, tick_theta}, joint_spacing);
  require_rows(log_path, joint.t.size(), "ticks " + sim::format_number(joint_spacing) + " s apart");
  r.joint_t = joint.t;
  r.joint_theta = joint.theta;
  // The samples: the frames that became measurements.
  const CsvTable frames = read_csv_table(frames_path,
                                         {{"t_capture"},
                                          {"measured"},
                                          {.name = "s_meas", .empty_is_nan = true},
                                          {.name = "sigma_s", .empty_is_nan = true}},
                                         0, limits);
  ReadSummary local;
  ReadSummary& sum = summary ? *summary : local;
  sum.rows = static_cast<long>(frames.rows());
  const auto &tc = frames.column("t_capture"), &measured = frames.column("measured");
  const auto &s = frames.column("s_meas"), &sd = frames.column("sigma_s");
  for (std::size_t i = 0; i < frames.rows(); ++i) {
    const int n = frames.line[i];
    if (i > 0) require_increasing_time(frames_path, n, "t_capture", tc[i - 1], tc[i]);
    if (measured[i] != 1.0) {
      if (measured[i] != 0.0)
        throw std::invalid_argument(at_line(frames_path, n) + "measured must be 0 or 1, got " +
                                    sim::format_number(measured[i]));
      sum.skip("not measured");
      continue;
    }
    if (!std::isfinite(s[i]) || !(sd[i] > 0))
      throw std::invalid_argument(at_line(frames_path, n) +
                                  "a measured frame needs s_meas and sigma_s > 0");
    if (tc[i] < r.joint_t.front() || tc[i] > r.joint_t.back()) {
      sum.skip("outside the joint log");
      continue;
    }
    r.t.push_back(tc[i]);
    r.s_h.push_back(s[i]);
    r.sigma.push_back(sd[i]);
  }
  sum.samples = static_cast<long>(r.t.size());
  require_rows(frames_path, r.t.size(), "measured frames");
  check_recording(r);
  return r;
}

namespace {

/// The rows of a pixel table with finite centre and sigma_px > 0 (else "PATH:LINE: ...").
void take_centre(const CsvTable& table, std::size_t i, PixelTrack& out) {
  const int n = table.line[i];
  const double t = table.column("t")[i], u = table.column("u")[i], v = table.column("v")[i],
               sp = table.column("sigma_px")[i];
  if (!std::isfinite(u) || !std::isfinite(v) || !std::isfinite(sp))
    throw std::invalid_argument(at_line(table.path, n) +
                                "a tracked centre needs u, v and sigma_px");
  if (!(sp > 0))
    throw std::invalid_argument(at_line(table.path, n) + "sigma_px must be > 0, got " +
                                sim::format_number(sp));
  if (!out.t.empty()) require_increasing_time(table.path, n, "t", out.t.back(), t);
  out.t.push_back(t);
  out.u.push_back(u);
  out.v.push_back(v);
  out.sigma_px.push_back(sp);
  out.line.push_back(n);
}

}  // namespace

PixelTrack read_track_csv(const std::string& path, ReadSummary* summary, const FileLimits& limits) {
  const CsvTable table = read_csv_table(path,
                                        {{"t"},
                                         {.name = "u", .empty_is_nan = true},
                                         {.name = "v", .empty_is_nan = true},
                                         {.name = "sigma_px", .empty_is_nan = true},
                                         {.name = "state", .text = true}},
                                        0, limits);
  ReadSummary local;
  ReadSummary& sum = summary ? *summary : local;
  sum.rows = static_cast<long>(table.rows());
  PixelTrack track;
  track.path = path;
  const std::vector<std::string>& state = table.text[table.index("state")];
  double previous_t = -INFINITY;
  for (std::size_t i = 0; i < table.rows(); ++i) {
    // Every row's time, measured or not, must increase: a track's frames are in order.
    require_increasing_time(path, table.line[i], "t", previous_t, table.column("t")[i]);
    previous_t = table.column("t")[i];
    if (state[i] != "found" && state[i] != "tracking") {
      sum.skip(state[i].empty() ? std::string("no state") : state[i]);
      continue;
    }
    take_centre(table, i, track);
  }
  sum.samples = static_cast<long>(track.t.size());
  require_rows(path, track.t.size(), "frames with the disk found");
  return track;
}

PixelTrack read_pixel_csv(const std::string& path, ReadSummary* summary, const FileLimits& limits) {
  const CsvTable table =
      read_csv_table(path, {{"t"}, {"u"}, {"v"}, {"theta"}, {"sigma_px"}}, 0, limits);
  PixelTrack track;
  track.path = path;
  for (std::size_t i = 0; i < table.rows(); ++i) {
    take_centre(table, i, track);
    track.theta.push_back(table.column("theta")[i]);
  }
  if (summary) summary->rows = summary->samples = static_cast<long>(track.t.size());
  require_rows(path, track.t.size(), "data rows");
  return track;
}

Recording pixels_to_recording(const PixelTrack& track, const std::optional<JointLog>& joint,
                              const ContactMapper& mapper, double encoder_offset,
                              ReadSummary* summary) {
  if (!std::isfinite(encoder_offset)) throw std::invalid_argument("encoder_offset: not finite");
  if (track.theta.empty() && !joint)
    throw std::invalid_argument(track.path +
                                ": a track's hand angles come from the joint's encoder log, "
                                "which was not given");
  ReadSummary local;
  ReadSummary& sum = summary ? *summary : local;
  Recording r;
  r.name = track.path;
  double previous = NAN;
  for (std::size_t i = 0; i < track.t.size(); ++i) {
    const std::optional<double> theta =
        track.theta.empty() ? joint_angle(*joint, track.t[i]) : track.theta[i];
    if (!theta) {
      sum.skip("outside the joint log");
      previous = NAN;
      continue;
    }
    const std::optional<ContactSample> c =
        mapper(track.u[i], track.v[i], track.sigma_px[i], *theta + encoder_offset, previous);
    if (!c || !std::isfinite(c->s_h) || !(c->sigma > 0)) {
      sum.skip("not mapped to the hand");
      previous = NAN;
      continue;
    }
    r.t.push_back(track.t[i]);
    r.s_h.push_back(c->s_h);
    r.sigma.push_back(c->sigma);
    previous = c->s_h;
  }
  sum.samples = static_cast<long>(r.t.size());
  require_rows(track.path, r.t.size(), "centres mapped to the hand");
  r.joint_t = joint ? joint->t : track.t;
  r.joint_theta = joint ? joint->theta : track.theta;
  for (double& theta : r.joint_theta) theta += encoder_offset;
  check_recording(r);
  return r;
}

}  // namespace flatland::identify
