// The closed loop's 1 kHz log as a table: its columns (every TickLog field, in order, with its unit
// in brackets), each row's values, and the CSV an experiment writes (log.csv). The Python module's
// experiment log has the same columns, read through the same functions.
#pragma once

#include "flatland/drivers/experiment.hpp"

#include <string>
#include <vector>

namespace flatland::drivers {

/// "t[s]", "theta[rad]", ..., "mode_true".
const std::vector<std::string>& tick_log_columns();
/// The column's name without its unit ("theta_dot" for "theta_dot[rad/s]").
std::string tick_log_column_name(const std::string& column);
/// 1-based index of the column named `name` (with or without its unit), for gnuplot scripts;
/// std::logic_error if there is none.
int tick_log_column_index(const std::string& name);
/// Whether the column holds text (the stage, the hand acceleration's source and the true contact
/// mode) rather than numbers.
bool tick_log_column_is_text(int column);
/// A numeric column's value in row r: NaN where it means nothing (s_meas, t_capture and nis at
/// ticks that folded in no measurement; command_recorded outside a replay; the truth columns of
/// a run that is not synthetic).
/// Booleans are 0 or 1.
double tick_log_number(const TickLog& r, int column);
/// A text column's value: the stage's name, the source's name ("readings", "command"), the true
/// mode's name (empty without truth).
std::string tick_log_text(const TickLog& r, int column);
/// log.csv: a header of the columns, one row per tick; numbers in shortest round-trip form.
std::string tick_log_csv(const std::vector<TickLog>& log);

/// frames.csv: one row per frame the loop received, in order: index, t_capture[s],
/// t_arrival[s], t_received[s] (the tick that took it), integrity (intact, repeated, damaged,
/// unreadable: what the camera's reader said), track (found, tracking, lost; stale for a frame
/// captured no later than one before it; empty when flagged), u[px], v[px], sigma_px[px],
/// quality (the tracker's, where it ran), measured (0/1), s_meas, sigma_s (the measurement).
std::string frame_log_csv(const std::vector<FrameLog>& frames);

}  // namespace flatland::drivers
