// Trajectory CSV (sample_columns, samples_csv).
#include "flatland/sim/trajectory_csv.hpp"

#include <charconv>
#include <cmath>
#include <stdexcept>

namespace flatland::sim {

const std::vector<std::string>& sample_columns() {
  static const std::vector<std::string> columns = {"t",
                                                   "theta",
                                                   "theta_dot",
                                                   "theta_ddot",
                                                   "s_h",
                                                   "sdot_h",
                                                   "sddot_h",
                                                   "s_o",
                                                   "sdot_o",
                                                   "x",
                                                   "y",
                                                   "object_angle",
                                                   "vx",
                                                   "vy",
                                                   "omega",
                                                   "f_n",
                                                   "f_t",
                                                   "fn_ratio",
                                                   "ft_ratio",
                                                   "mu_required",
                                                   "constraint_residual",
                                                   "redundant_residual",
                                                   "mode",
                                                   "slip_velocity",
                                                   "gap",
                                                   "rolling_couple"};
  return columns;
}

int sample_column(const std::string& name) {
  const auto& c = sample_columns();
  for (std::size_t i = 0; i < c.size(); ++i)
    if (c[i] == name) return static_cast<int>(i) + 1;
  throw std::logic_error("no sample column " + name);
}

std::array<double, kSampleNumbers> sample_numbers(const Sample& s) {
  return {s.t,
          s.theta,
          s.theta_dot,
          s.theta_ddot,
          s.s_h,
          s.sdot_h,
          s.sddot_h,
          s.s_o,
          s.sdot_o,
          s.object_position.x(),
          s.object_position.y(),
          s.object_angle,
          s.object_velocity.x(),
          s.object_velocity.y(),
          s.object_angular_velocity,
          s.force_normal,
          s.force_tangential,
          s.fn_ratio,
          s.ft_ratio,
          s.mu_required,
          s.constraint_residual,
          s.redundant_residual,
          s.slip_velocity,
          s.gap,
          s.rolling_couple};
}

std::string samples_csv(const std::vector<Sample>& samples) {
  std::string out;
  const auto& cols = sample_columns();
  for (std::size_t i = 0; i < cols.size(); ++i) out += (i ? "," : "") + cols[i];
  out += '\n';
  const std::size_t mode = sample_column("mode") - 1;
  for (const Sample& s : samples) {
    const auto v = sample_numbers(s);
    for (std::size_t i = 0, j = 0; i < cols.size(); ++i) {
      if (i) out += ',';
      out += i == mode ? to_string(s.mode) : format_number(v[j++]);
    }
    out += '\n';
  }
  return out;
}

const std::vector<std::string>& spatial_sample_columns() {
  static const std::vector<std::string> columns = {"t",
                                                   "x",
                                                   "y",
                                                   "z",
                                                   "qw",
                                                   "qx",
                                                   "qy",
                                                   "qz",
                                                   "vx",
                                                   "vy",
                                                   "vz",
                                                   "wx",
                                                   "wy",
                                                   "wz",
                                                   "so_u",
                                                   "so_v",
                                                   "sh_u",
                                                   "sh_v",
                                                   "sdot_o_u",
                                                   "sdot_o_v",
                                                   "sdot_h_u",
                                                   "sdot_h_v",
                                                   "contact_x",
                                                   "contact_y",
                                                   "contact_z",
                                                   "f_x",
                                                   "f_y",
                                                   "f_z",
                                                   "f_n",
                                                   "mu_required",
                                                   "energy",
                                                   "constraint_residual",
                                                   "redundant_residual"};
  return columns;
}

int spatial_sample_column(const std::string& name) {
  const auto& c = spatial_sample_columns();
  for (std::size_t i = 0; i < c.size(); ++i)
    if (c[i] == name) return static_cast<int>(i) + 1;
  throw std::logic_error("no spatial sample column " + name);
}

std::string spatial_samples_csv(const std::vector<SpatialSample>& samples) {
  std::string out;
  const auto& cols = spatial_sample_columns();
  for (std::size_t i = 0; i < cols.size(); ++i) out += (i ? "," : "") + cols[i];
  out += '\n';
  for (const SpatialSample& s : samples) {
    const SpatialState& q = s.state;
    const Eigen::Quaterniond o = q.orientation.normalized();
    const double v[] = {s.t,
                        q.position.x(),
                        q.position.y(),
                        q.position.z(),
                        o.w(),
                        o.x(),
                        o.y(),
                        o.z(),
                        q.velocity.x(),
                        q.velocity.y(),
                        q.velocity.z(),
                        q.angular_velocity.x(),
                        q.angular_velocity.y(),
                        q.angular_velocity.z(),
                        q.s_o.x(),
                        q.s_o.y(),
                        q.s_h.x(),
                        q.s_h.y(),
                        q.sdot_o.x(),
                        q.sdot_o.y(),
                        q.sdot_h.x(),
                        q.sdot_h.y(),
                        s.contact.x(),
                        s.contact.y(),
                        s.contact.z(),
                        s.force.x(),
                        s.force.y(),
                        s.force.z(),
                        s.force_normal,
                        s.mu_required,
                        s.energy,
                        s.constraint_residual,
                        s.redundant_residual};
    static_assert(sizeof(v) / sizeof(v[0]) == 33);
    for (std::size_t i = 0; i < cols.size(); ++i) {
      if (i) out += ',';
      out += format_number(v[i]);
    }
    out += '\n';
  }
  return out;
}

}  // namespace flatland::sim
