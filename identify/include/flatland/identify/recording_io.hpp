// Recordings from files (docs/IDENTIFY.md, "Recordings"): a plain CSV of t, theta and s_h, an
// experiment's log (log.csv and frames.csv), the joint's encoder log, and the tracked pixel
// centres of `flatland track` (track.csv) or of a plain pixel CSV, which become s_h through a
// caller's pixel -> s_h mapping (the camera file's calibration; identify does not link the
// camera stack). Every file is bounded in size, line length and rows; bad input is one
// std::invalid_argument line "FILE:LINE: reason" (or "FILE: reason"). SI units.
#pragma once

#include "flatland/identify/identify.hpp"

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace flatland::identify {

/// The bounds every recording file is read within.
struct FileLimits {
  std::size_t max_bytes = std::size_t{512} << 20;  ///< an hour of a 1 kHz log is ~200 MB
  std::size_t max_line = 4096;                     ///< bytes per line
  std::size_t max_rows = 8'000'000;                ///< data rows
};

/// A column a reader wants from a CSV file, by the header's name (a unit in brackets after a name
/// is ignored: "t[s]" is "t").
struct ColumnRequest {
  std::string name;
  bool required = true;       ///< absent: "PATH:1: missing column NAME"
  bool text = false;          ///< kept as text (CsvTable::text), else parsed as a finite number
  bool empty_is_nan = false;  ///< an empty cell is NaN (a frame with no measurement)
};

/// The requested columns of a CSV file: for each request, whether the header has it and, per
/// row, its value (numbers) or cell (text). Other columns are not parsed.
struct CsvTable {
  std::string path;
  std::vector<ColumnRequest> columns;
  std::vector<bool> present;
  std::vector<std::vector<double>> values;     ///< [column][row]; NaN for text columns
  std::vector<std::vector<std::string>> text;  ///< [column][row]; empty for number columns
  std::vector<int> line;                       ///< the file's line number of each row
  std::size_t rows() const { return line.size(); }
  /// Index of the request named `name` (std::logic_error if none was made).
  std::size_t index(const std::string& name) const;
  bool has(const std::string& name) const { return present[index(name)]; }
  const std::vector<double>& column(const std::string& name) const { return values[index(name)]; }
};

/// Read a CSV file whose first line is a header. Blank lines and lines starting with '#' are
/// skipped. std::invalid_argument "PATH:LINE: reason" for: a missing or unreadable file, a file
/// or line beyond `limits`, more rows than `limits`, a header with an empty or repeated name or
/// without a required column, a row with another number of fields than the header, a requested
/// number cell that is not a finite number (empty only where allowed), fewer than `min_rows`
/// rows.
CsvTable read_csv_table(const std::string& path, const std::vector<ColumnRequest>& columns,
                        std::size_t min_rows = 1, const FileLimits& limits = {});

/// The column names of a CSV file's header (its first line that is not blank or a comment; units
/// in brackets dropped), read within `limits`; std::invalid_argument "PATH: reason" if there is
/// none.
std::vector<std::string> read_csv_header(const std::string& path, const FileLimits& limits = {});

/// The joint's encoder log: rows t,theta (s, rad), strictly increasing t; a header line is
/// optional (as `flatland track --encoder` reads it).
struct JointLog {
  std::vector<double> t, theta;
};
JointLog read_joint_log(const std::string& path, const FileLimits& limits = {});

/// s: the spacing a joint log read from a file is thinned to before the fit's spline goes through
/// it. A spline through every reading of a 1 kHz log differentiates the encoder's quantisation
/// twice: q / dt^2 = 6 rad/s^2 of noise in theta'' for a 20-bit encoder (q = 6e-6 rad) at 1 ms,
/// more than the hand's own accelerations, and the simulated disk then fails (measured on a
/// synthetic experiment: the fit's runs stopped at 0.75 s at 1 ms, at 1.75 s at 10 ms, and ran
/// through at 20 ms and 33 ms with the same fitted values); at 20 ms the noise is 0.016 rad/s^2.
constexpr double kJointLogSpacing = 0.02;

/// The log's readings at least `spacing` s apart (the first always, the last always), for the
/// spline through them; the log itself when it is already that sparse.
JointLog thin_joint_log(const JointLog& log, double spacing = kJointLogSpacing);

/// What a reader kept and left out, for the command's report.
struct ReadSummary {
  long rows = 0;     ///< data rows in the file(s)
  long samples = 0;  ///< rows that became measurements
  /// Rows left out, and why ("lost", "low_quality", "not measured", "outside the joint log",
  /// "not mapped"), one count per reason in the order first met.
  std::vector<std::pair<std::string, long>> skipped;
  void skip(const std::string& why);
};

/// A plain CSV with a header naming at least t, theta and s_h (units: s, rad and the hand's
/// global parameter; a unit in brackets after a name is allowed, "t[s]") and optionally sigma
/// (s_h's standard deviation per row, > 0). Without a sigma column `sigma` gives one for every
/// row; with neither, std::invalid_argument (identify weights by the measurement's sigma and does
/// not invent one). The joint log is the file's own (t, theta). Non-monotonic time, NaN, fewer
/// than 4 rows: "PATH:LINE: reason".
Recording read_plain_recording(const std::string& path, std::optional<double> sigma = {},
                               ReadSummary* summary = nullptr, const FileLimits& limits = {});

/// An experiment's output directory (or its log.csv): the joint's log is log.csv's t and theta
/// (the readings the loop took, 1 kHz), thinned to `joint_spacing` (thin_joint_log); the samples
/// are frames.csv's measured frames (t_capture, s_meas, sigma_s) inside the joint log's span.
Recording read_experiment_recording(const std::string& path, ReadSummary* summary = nullptr,
                                    const FileLimits& limits = {},
                                    double joint_spacing = kJointLogSpacing);

/// Tracked disk centres (px) per frame, with the tracker's sigma_px and, for a plain pixel CSV,
/// the hand angle of each frame.
struct PixelTrack {
  std::string path;
  std::vector<double> t, u, v, sigma_px;
  std::vector<double> theta;  ///< empty for a track.csv (the angle comes from the encoder log)
  std::vector<int> line;
};

/// The centres of `flatland track`'s CSV (frame,t,u,v,sigma_px,quality,state,s_h): the rows
/// whose state is found or tracking (lost, low-quality and flagged frames are counted in
/// `summary` and left out).
PixelTrack read_track_csv(const std::string& path, ReadSummary* summary = nullptr,
                          const FileLimits& limits = {});
/// A plain pixel CSV with a header naming t, u, v, theta and sigma_px (s, px, px, rad, px).
PixelTrack read_pixel_csv(const std::string& path, ReadSummary* summary = nullptr,
                          const FileLimits& limits = {});

/// A measured contact: s_h and its standard deviation.
struct ContactSample {
  double s_h = 0, sigma = 0;
};
/// The caller's pixel -> s_h mapping (the camera file's pose, the joint axis and offset, the
/// scene's hand and disk): the centre (u, v) px with its sigma_px at raw joint angle theta, near
/// `previous_s_h` (NaN: search the whole outline). nullopt where the ray misses the table or no
/// contact is found.
using ContactMapper = std::function<std::optional<ContactSample>(
    double u, double v, double sigma_px, double theta, double previous_s_h)>;

/// A recording from tracked centres: each centre mapped to s_h at its frame's hand angle (the
/// track's theta column, else `joint` interpolated linearly at t; frames outside the joint log
/// are left out); the joint log is `joint` when given, else the track's (t, theta). The hand's
/// angle is the encoder's plus `encoder_offset` (the camera file's joint.encoder_offset), in
/// what the mapper is given and in the recording's joint log alike.
Recording pixels_to_recording(const PixelTrack& track, const std::optional<JointLog>& joint,
                              const ContactMapper& mapper, double encoder_offset = 0,
                              ReadSummary* summary = nullptr);

}  // namespace flatland::identify
