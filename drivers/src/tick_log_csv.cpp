#include "flatland/drivers/tick_log_csv.hpp"

#include "flatland/sim/format.hpp"

#include <cmath>
#include <limits>
#include <stdexcept>

namespace flatland::drivers {

namespace {

enum Column {
  kT,
  kTheta,
  kThetaDot,
  kCommand,
  kCommandRecorded,
  kThetaDdot,
  kThetaDdotSource,
  kStage,
  kSEst,
  kSdotEst,
  kVarS,
  kVarSdot,
  kEstimating,
  kMeasured,
  kSMeas,
  kTCapture,
  kNis,
  kThetaPlan,
  kSTrue,
  kSdotTrue,
  kThetaTrue,
  kFnRatio,
  kMuRequired,
  kNees,
  kModeTrue,
  kColumns
};

}  // namespace

const std::vector<std::string>& tick_log_columns() {
  static const std::vector<std::string> c = {"t[s]",
                                             "theta[rad]",
                                             "theta_dot[rad/s]",
                                             "command[rad/s^2]",
                                             "command_recorded[rad/s^2]",
                                             "theta_ddot[rad/s^2]",
                                             "theta_ddot_source",
                                             "stage",
                                             "s_est",
                                             "sdot_est[1/s]",
                                             "var_s",
                                             "var_sdot[1/s^2]",
                                             "estimating",
                                             "measured",
                                             "s_meas",
                                             "t_capture[s]",
                                             "nis",
                                             "theta_plan[rad]",
                                             "s_true",
                                             "sdot_true[1/s]",
                                             "theta_true[rad]",
                                             "fn_ratio",
                                             "mu_required",
                                             "nees",
                                             "mode_true"};
  static_assert(kColumns == 25);
  return c;
}

std::string tick_log_column_name(const std::string& column) {
  return column.substr(0, column.find('['));
}

int tick_log_column_index(const std::string& name) {
  const auto& c = tick_log_columns();
  for (std::size_t i = 0; i < c.size(); ++i)
    if (c[i] == name || tick_log_column_name(c[i]) == name) return static_cast<int>(i) + 1;
  throw std::logic_error("no log column " + name);
}

bool tick_log_column_is_text(int column) {
  return column == kStage || column == kModeTrue || column == kThetaDdotSource;
}

double tick_log_number(const TickLog& r, int column) {
  constexpr double nan = std::numeric_limits<double>::quiet_NaN();
  switch (column) {
    case kT:
      return r.t;
    case kTheta:
      return r.theta;
    case kThetaDot:
      return r.theta_dot;
    case kCommand:
      return r.command;
    case kCommandRecorded:
      return r.command_recorded;
    case kThetaDdot:
      return r.theta_ddot;
    case kSEst:
      return r.s_est;
    case kSdotEst:
      return r.sdot_est;
    case kVarS:
      return r.var_s;
    case kVarSdot:
      return r.var_sdot;
    case kEstimating:
      return r.estimating ? 1 : 0;
    case kMeasured:
      return r.measured ? 1 : 0;
    // s_meas, t_capture and nis mean something only at ticks that folded in a measurement.
    case kSMeas:
      return r.measured ? r.s_meas : nan;
    case kTCapture:
      return r.measured ? r.t_capture : nan;
    case kNis:
      return r.measured ? r.nis : nan;
    case kThetaPlan:
      return r.theta_plan;
    case kSTrue:
      return r.s_true;
    case kSdotTrue:
      return r.sdot_true;
    case kThetaTrue:
      return r.theta_true;
    case kFnRatio:
      return r.fn_ratio;
    case kMuRequired:
      return r.mu_required;
    case kNees:
      return r.nees;
    default:
      throw std::logic_error("log column " + std::to_string(column) + " is not a number");
  }
}

std::string tick_log_text(const TickLog& r, int column) {
  if (column == kStage) return r.mode;
  if (column == kThetaDdotSource) return control::to_string(r.theta_ddot_source);
  if (column == kModeTrue) return std::isfinite(r.s_true) ? sim::to_string(r.mode_true) : "";
  throw std::logic_error("log column " + std::to_string(column) + " is not text");
}

std::string tick_log_csv(const std::vector<TickLog>& log) {
  std::string out;
  const auto& cols = tick_log_columns();
  for (std::size_t i = 0; i < cols.size(); ++i) out += (i ? "," : "") + cols[i];
  out += '\n';
  for (const TickLog& r : log) {
    for (int c = 0; c < kColumns; ++c) {
      if (c) out += ',';
      if (tick_log_column_is_text(c))
        out += tick_log_text(r, c);
      else if (c == kEstimating || c == kMeasured)
        out += tick_log_number(r, c) != 0 ? '1' : '0';
      else
        out += sim::format_number(tick_log_number(r, c));
    }
    out += '\n';
  }
  return out;
}

std::string frame_log_csv(const std::vector<FrameLog>& frames) {
  std::string csv =
      "index,t_capture[s],t_arrival[s],t_received[s],integrity,track,u[px],v[px],sigma_px[px],"
      "quality,measured,s_meas,sigma_s\n";
  csv.reserve(csv.size() + 160 * frames.size());
  const auto num = [](double x) { return sim::format_number(x); };
  for (const FrameLog& f : frames) {
    csv += std::to_string(f.index) + "," + num(f.t_capture) + "," + num(f.t_arrival) + "," +
           num(f.t_received) + "," + vision::to_string(f.integrity) + ",";
    if (f.stale)
      csv += "stale";
    else if (f.tracked)
      csv += vision::to_string(f.track.state);
    csv += ",";
    if (f.tracked && f.track.ok())
      csv += num(f.track.center.x) + "," + num(f.track.center.y) + "," + num(f.track.sigma_px) +
             "," + num(f.track.quality) + ",";
    else
      csv += ",,,,";
    csv += f.measured ? "1," + num(f.s_meas) + "," + num(f.sigma_s) : std::string("0,,");
    csv += "\n";
  }
  return csv;
}

}  // namespace flatland::drivers
