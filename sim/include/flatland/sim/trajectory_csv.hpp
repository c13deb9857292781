// The trajectory CSV: one row per sim::Sample, one column per field (SI units; the contact mode
// as a word), numbers in their shortest round-trip form. What `flatland simulate/solve --out`
// write, and what a library user writes the same way.
#pragma once

#include "flatland/sim/format.hpp"
#include "flatland/sim/simulate.hpp"

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace flatland::sim {

/// Columns of a trajectory CSV, in order (one per Sample field).
const std::vector<std::string>& sample_columns();
/// 1-based column of `name` in sample_columns() (for gnuplot `using`); std::logic_error if none.
int sample_column(const std::string& name);
/// The columns that are numbers: every one but `mode` (the contact mode, a word).
inline constexpr std::size_t kSampleNumbers = 25;
/// A sample's numbers in sample_columns() order, `mode` left out.
std::array<double, kSampleNumbers> sample_numbers(const Sample& s);
/// The whole CSV: the header and one row per sample.
std::string samples_csv(const std::vector<Sample>& samples);

}  // namespace flatland::sim
