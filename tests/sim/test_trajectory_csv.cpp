// The trajectory CSV: its header names every column once, and each row reads back as exactly the
// sample's values (shortest round-trip numbers).
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spec.hpp"
#include "flatland/sim/trajectory_csv.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace {

using namespace flatland::sim;

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> out;
  std::stringstream ss(line);
  for (std::string f; std::getline(ss, f, ',');) out.push_back(f);
  return out;
}

TEST(TrajectoryCsv, NumbersReadBackExactly) {
  for (double v : {0.0, -0.0, 1.0 / 3.0, 1e-300, -2.5e17, 0.1, 6.02214076e23,
                   std::numeric_limits<double>::denorm_min(), std::numeric_limits<double>::max()})
    EXPECT_EQ(std::strtod(format_number(v).c_str(), nullptr), v) << format_number(v);
  EXPECT_EQ(format_number(0.1), "0.1");  // shortest: not 0.10000000000000001
  EXPECT_EQ(format_number(std::nan("")), "nan");
  EXPECT_EQ(format_number(-std::numeric_limits<double>::infinity()), "-inf");
}

TEST(TrajectoryCsv, RowsAreTheSamplesColumnByColumn) {
  Sample a;
  a.t = 0.25;
  a.theta = 1.0 / 7.0;
  a.s_h = -0.999;
  a.object_position = {0.01, -0.02};
  a.fn_ratio = 0.17644029803589859;
  a.mode = ContactMode::kSliding;
  a.gap = 1e-12;
  Sample b = a;
  b.t = 0.5;
  b.force_tangential = -3.5;
  const std::string csv = samples_csv({a, b});
  std::stringstream ss(csv);
  std::string header, row1, row2, extra;
  std::getline(ss, header);
  std::getline(ss, row1);
  std::getline(ss, row2);
  EXPECT_FALSE(std::getline(ss, extra));
  const auto names = split(header);
  EXPECT_EQ(names, sample_columns());
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
  const auto r1 = split(row1), r2 = split(row2);
  ASSERT_EQ(r1.size(), names.size());
  ASSERT_EQ(r2.size(), names.size());
  auto at = [&](const std::vector<std::string>& row, const std::string& name) {
    return row[static_cast<std::size_t>(sample_column(name) - 1)];
  };
  EXPECT_EQ(std::strtod(at(r1, "t").c_str(), nullptr), 0.25);
  EXPECT_EQ(std::strtod(at(r1, "theta").c_str(), nullptr), 1.0 / 7.0);
  EXPECT_EQ(std::strtod(at(r1, "s_h").c_str(), nullptr), -0.999);
  EXPECT_EQ(std::strtod(at(r1, "y").c_str(), nullptr), -0.02);
  EXPECT_EQ(std::strtod(at(r1, "fn_ratio").c_str(), nullptr), 0.17644029803589859);
  EXPECT_EQ(std::strtod(at(r1, "gap").c_str(), nullptr), 1e-12);
  EXPECT_EQ(at(r1, "mode"), to_string(ContactMode::kSliding));
  EXPECT_EQ(std::strtod(at(r2, "f_t").c_str(), nullptr), -3.5);
  EXPECT_THROW(sample_column("no_such_column"), std::logic_error);
}

}  // namespace
