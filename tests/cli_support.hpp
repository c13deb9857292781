// Shared plumbing for the end-to-end tests of the `flatland` program: each test runs the built
// binary (FLATLAND_CLI_PATH) in its own empty temporary directory.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace flatland_test {

namespace fs = std::filesystem;

inline std::string read_text(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

inline void write_text(const fs::path& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary);
  f << s;
}

/// Single-quote for the shell.
inline std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

/// Whether `name` is a program on the PATH.
inline bool have_tool(const std::string& name) {
  return std::system(("command -v " + name + " > /dev/null 2>&1").c_str()) == 0;
}

/// The cells of one CSV line (no quoted cells).
inline std::vector<std::string> cells_of(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  for (std::string cell; std::getline(ss, cell, ',');) out.push_back(cell);
  return out;
}

inline std::vector<std::string> lines_of(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  for (std::string line; std::getline(ss, line);) out.push_back(line);
  return out;
}

/// A CSV with a header (no quoted cells): each column by name, units in brackets kept in the name;
/// a cell that is not a number, or missing at the end of a row, is NaN.
inline std::map<std::string, std::vector<double>> read_columns(const fs::path& p) {
  const std::vector<std::string> lines = lines_of(read_text(p));
  std::map<std::string, std::vector<double>> out;
  if (lines.empty()) return out;
  std::vector<std::string> names;
  std::stringstream header(lines[0]);
  for (std::string cell; std::getline(header, cell, ',');) names.push_back(cell);
  for (std::size_t i = 1; i < lines.size(); ++i) {
    std::stringstream row(lines[i]);
    std::size_t k = 0;
    for (std::string cell; std::getline(row, cell, ',') && k < names.size(); ++k) {
      char* end = nullptr;
      const double v = std::strtod(cell.c_str(), &end);
      out[names[k]].push_back(end != cell.c_str() ? v : std::nan(""));
    }
    for (; k < names.size(); ++k) out[names[k]].push_back(std::nan(""));
  }
  return out;
}

struct Result {
  int code = -1;
  std::string out, err;
};

/// Every test gets its own empty working directory, removed afterwards.
class CliTestBase : public ::testing::Test {
 protected:
  void SetUp() override {
    static int counter = 0;
    dir_ = fs::temp_directory_path() /
           ("flatland_cli_test_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// Run `flatland args` in the test directory; `env` is prepended (e.g. "PATH=/nonexistent").
  Result run(const std::string& args, const std::string& env = "") const {
    const std::string cmd = "cd " + quote(dir_.string()) + " && " + env + (env.empty() ? "" : " ") +
                            quote(FLATLAND_CLI_PATH) + " " + args + " > stdout.txt 2> stderr.txt";
    const int status = std::system(cmd.c_str());
    Result r;
    r.code = status != -1 && WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = read_text(dir_ / "stdout.txt");
    r.err = read_text(dir_ / "stderr.txt");
    fs::remove(dir_ / "stdout.txt");
    fs::remove(dir_ / "stderr.txt");
    return r;
  }

  fs::path dir_;
};

}  // namespace flatland_test
