// The trajectory CSV: one row per sim::Sample, one column per field (SI units; the contact mode
// as a word), numbers in their shortest round-trip form. What `flatland simulate/solve --out`
// write, and what a library user writes the same way.
#pragma once

#include "flatland/sim/format.hpp"
#include "flatland/sim/simulate.hpp"
#include "flatland/sim/spatial_run.hpp"

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

/// Columns of a spatial run's CSV (`flatland simulate` on a `space: 3d` scene): t; the centre
/// x, y, z; the body's orientation quaternion qw, qx, qy, qz (body -> world); its velocity and
/// angular velocity; the contact coordinates on the object (so_u, so_v) and the hand (sh_u,
/// sh_v) with their rates; the contact point in the world; the hand's force on the object
/// (world) and its normal part; the friction the rolling needs; the energy; the residuals.
const std::vector<std::string>& spatial_sample_columns();
/// 1-based column of `name` in spatial_sample_columns(); std::logic_error if none.
int spatial_sample_column(const std::string& name);
/// The whole CSV: the header and one row per sample.
std::string spatial_samples_csv(const std::vector<SpatialSample>& samples);

}  // namespace flatland::sim
