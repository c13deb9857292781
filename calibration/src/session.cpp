// Calibration sessions (see session.hpp): the CSV files of a session.
#include "flatland/calibration/session.hpp"
#include "flatland/sim/format.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <optional>
#include <random>
#include <sstream>
#include <stdexcept>

namespace flatland::calibration {

namespace fs = std::filesystem;

camera::PlacedBoard TablePlacement::placed(const camera::Board& board) const {
  camera::PlacedBoard p;
  p.board = board;
  p.position = {x, y, z};
  p.rotation = {0.0, 0.0, yaw};
  return p;
}

// ---------------------------------------------------------------------------------------------
// CSV files

namespace {

// A session's CSV names a few dozen images; anything far larger is not one.
constexpr std::size_t kMaxCsvBytes = 1 << 20;
constexpr std::size_t kMaxCsvRows = 10000;

std::vector<std::string> split_fields(const std::string& line) {
  std::vector<std::string> out;
  std::string field;
  std::istringstream is(line);
  while (std::getline(is, field, ',')) {
    const auto first = field.find_first_not_of(" \t\r");
    const auto last = field.find_last_not_of(" \t\r");
    out.push_back(first == std::string::npos ? "" : field.substr(first, last - first + 1));
  }
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

struct CsvTable {
  std::map<std::string, std::size_t> column;  // name -> index
  std::vector<std::vector<std::string>> rows;
  std::vector<int> line_numbers;
};

[[noreturn]] void fail(const std::string& where, const std::string& reason) {
  throw std::invalid_argument(where + ": " + reason);
}

// Reads at most one byte past the limit, so that a device or a huge file costs no more.
CsvTable read_csv(const std::string& path, const std::vector<std::string>& required,
                  const std::vector<std::string>& optional, const std::string& what) {
  std::ifstream in(path, std::ios::binary);
  if (!in.is_open() || fs::is_directory(path)) fail(path, "cannot read " + what);
  std::string text(kMaxCsvBytes + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxCsvBytes) fail(path, "larger than 1 MiB; " + what + " is a line per image");
  if (text.find('\0') != std::string::npos) fail(path, "not a text file (" + what + ")");

  CsvTable t;
  std::istringstream is(text);
  std::string line;
  int line_no = 0;
  bool header = true;
  std::string expected;
  for (const std::string& r : required) expected += (expected.empty() ? "" : ",") + r;
  for (const std::string& o : optional) expected += "[," + o + "]";
  while (std::getline(is, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos || line[0] == '#') continue;
    const std::vector<std::string> fields = split_fields(line);
    const std::string where = path + ":" + std::to_string(line_no);
    if (header) {
      for (std::size_t i = 0; i < fields.size(); ++i) {
        const std::string& name = fields[i];
        if (std::find(required.begin(), required.end(), name) == required.end() &&
            std::find(optional.begin(), optional.end(), name) == optional.end())
          fail(where, "unknown column '" + name + "' (the header is " + expected + ")");
        if (!t.column.emplace(name, i).second) fail(where, "column '" + name + "' twice");
      }
      for (const std::string& r : required)
        if (!t.column.count(r))
          fail(where, "missing column '" + r + "' (the header is " + expected + ")");
      header = false;
      continue;
    }
    if (fields.size() != t.column.size())
      fail(where, std::to_string(fields.size()) + " fields, the header has " +
                      std::to_string(t.column.size()));
    if (t.rows.size() == kMaxCsvRows)
      fail(where, "more than " + std::to_string(kMaxCsvRows) + " rows");
    t.rows.push_back(fields);
    t.line_numbers.push_back(line_no);
  }
  if (header) fail(path, "empty (expected the header " + expected + ", then a row per image)");
  if (t.rows.empty()) fail(path, "no rows after the header (" + expected + ")");
  return t;
}

double number_field(const CsvTable& t, std::size_t row, const std::string& name,
                    const std::string& path) {
  const std::string& s = t.rows[row][t.column.at(name)];
  double v = 0;
  const char* first = s.data() + (!s.empty() && s[0] == '+' ? 1 : 0);
  const auto [end, ec] = std::from_chars(first, s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size() || first == end || !std::isfinite(v))
    fail(path + ":" + std::to_string(t.line_numbers[row]),
         name + ": expected a finite number, got '" + s + "'");
  return v;
}

std::string image_field(const CsvTable& t, std::size_t row, const std::string& path) {
  const std::string& s = t.rows[row][t.column.at("image")];
  if (s.empty()) fail(path + ":" + std::to_string(t.line_numbers[row]), "image: empty");
  const fs::path p(s);
  return p.is_absolute() ? s : (fs::path(path).parent_path() / p).lexically_normal().string();
}

}  // namespace

std::vector<TablePlacement> read_table_csv(const std::string& path) {
  const CsvTable t = read_csv(path, {"image", "x", "y", "yaw"}, {"z"}, "a table.csv");
  std::vector<TablePlacement> out;
  for (std::size_t i = 0; i < t.rows.size(); ++i) {
    TablePlacement p;
    p.image = image_field(t, i, path);
    p.x = number_field(t, i, "x", path);
    p.y = number_field(t, i, "y", path);
    p.yaw = number_field(t, i, "yaw", path);
    if (t.column.count("z")) p.z = number_field(t, i, "z", path);
    out.push_back(p);
  }
  return out;
}

std::vector<JointImage> read_joint_csv(const std::string& path) {
  const CsvTable t = read_csv(path, {"image", "encoder"}, {}, "a joint.csv");
  std::vector<JointImage> out;
  for (std::size_t i = 0; i < t.rows.size(); ++i)
    out.push_back({image_field(t, i, path), number_field(t, i, "encoder", path)});
  return out;
}

std::string table_csv(const std::vector<TablePlacement>& rows) {
  std::string s = "image,x,y,z,yaw\n";
  for (const TablePlacement& p : rows)
    s += p.image + "," + sim::format_significant(p.x, 10) + "," + sim::format_significant(p.y, 10) +
         "," + sim::format_significant(p.z, 10) + "," + sim::format_significant(p.yaw, 10) + "\n";
  return s;
}

std::string joint_csv(const std::vector<JointImage>& rows) {
  std::string s = "image,encoder\n";
  for (const JointImage& j : rows)
    s += j.image + "," + sim::format_significant(j.encoder, 10) + "\n";
  return s;
}

}  // namespace flatland::calibration
