// flatland identify: the world's parameters (friction, restitution, losses, tilt, offsets) fitted
// to recordings of the disk on the hand, written as a scene file (docs/IDENTIFY.md).
#include "common.hpp"

#include "flatland/camera/camera_file.hpp"
#include "flatland/identify/fitted_scene.hpp"
#include "flatland/identify/identify.hpp"
#include "flatland/identify/recording_io.hpp"
#include "flatland/model/compile.hpp"
#include "flatland/model/model.hpp"
#include "flatland/vision/mapping.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

namespace flatland::app {

namespace {

struct IdentifyCliOptions {
  std::string scene;
  std::vector<std::string> recordings;
  std::string unknowns, out, validate, camera, format = "auto";
  std::vector<std::string> encoders;
  double segment = 1.0;
  double sigma = 0;
  int max_iterations = identify::IdentifyOptions{}.max_iterations;
  int threads = 0;
  bool json = false, force = false, no_plot = false;
  CLI::Option* sigma_opt = nullptr;
  std::string command_line;  // for the fitted scene's comment
};

/// The recording formats identify reads (docs/IDENTIFY.md, "Recordings").
enum class Format { kPlain, kExperiment, kTrack, kPixels };

const char* to_string(Format f) {
  switch (f) {
    case Format::kPlain:
      return "plain";
    case Format::kExperiment:
      return "experiment";
    case Format::kTrack:
      return "track";
    case Format::kPixels:
      return "pixels";
  }
  return "?";
}

/// --format auto: a directory or a log.csv is an experiment's; else the header says.
Format detect_format(const std::string& path, const std::string& option) {
  const fs::path p(path);
  if (fs::is_directory(p) || p.filename() == "log.csv") return Format::kExperiment;
  if (!fs::exists(p)) throw UsageError(option + ": no such file: " + path);
  std::set<std::string> h;
  try {
    for (const std::string& name : identify::read_csv_header(path)) h.insert(name);
  } catch (const std::invalid_argument& e) {
    throw UsageError(option + ": " + e.what());
  }
  if (h.count("u") && h.count("v") && h.count("state")) return Format::kTrack;
  if (h.count("u") && h.count("v") && h.count("theta")) return Format::kPixels;
  if (h.count("t") && h.count("theta") && h.count("s_h")) return Format::kPlain;
  throw UsageError(option + ": " + path +
                   ": cannot tell the recording's format from its header (plain: t,theta,s_h"
                   "[,sigma]; pixels: t,u,v,theta,sigma_px; track.csv; an experiment's "
                   "directory); give --format");
}

Format parse_format(const std::string& name, const std::string& path, const std::string& option) {
  if (name == "auto") return detect_format(path, option);
  if (name == "plain") return Format::kPlain;
  if (name == "experiment") return Format::kExperiment;
  if (name == "track") return Format::kTrack;
  if (name == "pixels") return Format::kPixels;
  throw UsageError("--format: unknown format '" + name +
                   "' (auto, plain, experiment, track, pixels)");
}

/// Everything the pixel formats need to map a centre to s_h: the camera file and the scene's
/// hand and disk.
struct PixelContext {
  camera::CameraFile camfile;
  vision::HandMapping mapping;
  double encoder_offset = 0;
};

/// One recording as read, with what its reader left out.
struct LoadedRecording {
  std::string path;
  Format format = Format::kPlain;
  identify::Recording recording;
  identify::ReadSummary summary;
};

/// Every input checked and every recording read before any fitting: bad input is one line.
class RecordingLoader {
 public:
  RecordingLoader(const IdentifyCliOptions& o, const Scene& scene) : o_(o), scene_(scene) {}

  LoadedRecording load(const std::string& path, const std::string& option) {
    LoadedRecording r;
    r.path = path;
    r.format = parse_format(o_.format, path, option);
    try {
      switch (r.format) {
        case Format::kPlain:
          r.recording = identify::read_plain_recording(
              path, o_.sigma_opt->count() ? std::optional<double>(o_.sigma) : std::nullopt,
              &r.summary);
          break;
        case Format::kExperiment:
          r.recording = identify::read_experiment_recording(path, &r.summary);
          break;
        case Format::kTrack:
        case Format::kPixels:
          r.recording = from_pixels(path, r.format, r.summary);
          break;
      }
    } catch (const std::invalid_argument& e) {
      throw UsageError(option + ": " + e.what());
    }
    return r;
  }

  /// Every --encoder was used by a track recording.
  void check_encoders_used() const {
    if (next_encoder_ < o_.encoders.size())
      throw UsageError("--encoder: " + std::to_string(o_.encoders.size()) + " given but only " +
                       std::to_string(next_encoder_) + " track.csv recordings take one (in order)");
  }

 private:
  identify::Recording from_pixels(const std::string& path, Format format,
                                  identify::ReadSummary& summary) {
    if (format == Format::kTrack && next_encoder_ >= o_.encoders.size())
      throw UsageError("--encoder: a track.csv recording (" + path +
                       ") needs the joint's encoder log; give one --encoder per track.csv, in "
                       "order");
    const PixelContext& ctx = pixel_context();
    std::optional<identify::JointLog> joint;
    identify::PixelTrack track;
    if (format == Format::kTrack) {
      const std::string& encoder = o_.encoders[next_encoder_++];
      try {
        joint = identify::thin_joint_log(identify::read_joint_log(encoder));
      } catch (const std::invalid_argument& e) {
        throw UsageError(std::string("--encoder: ") + e.what());
      }
      track = identify::read_track_csv(path, &summary);
    } else {
      track = identify::read_pixel_csv(path, &summary);
    }
    const vision::HandMapping& mapping = ctx.mapping;
    const identify::ContactMapper mapper =
        [&mapping](double u, double v, double sigma_px, double theta,
                   double previous) -> std::optional<identify::ContactSample> {
      const auto c = vision::follow_contact(mapping, {u, v}, theta, previous);
      if (!c) return std::nullopt;
      return identify::ContactSample{
          c->s_h, vision::contact_sigma(mapping, {u, v}, sigma_px, theta, c->s_h)};
    };
    return identify::pixels_to_recording(track, joint, mapper, ctx.encoder_offset, &summary);
  }

  const PixelContext& pixel_context() {
    if (pixels_) return *pixels_;
    if (o_.camera.empty())
      throw UsageError(
          "--camera: required for a recording of pixel centres (the camera file's "
          "table pose maps them to s_h)");
    PixelContext ctx;
    ctx.camfile = camera::read_camera_file(o_.camera);
    if (!ctx.camfile.has_table_pose)
      throw UsageError("--camera: " + o_.camera +
                       " has no table pose (needed to map pixels to the table for s_h)");
    if (scene_.sim.object.kind != sim::ObjectSpec::Kind::kDisk)
      throw UsageError(scene_.origin +
                       ": object: pixel centres are mapped for a disk (object.type: disk)");
    ctx.mapping =
        model::hand_mapping(*model::compile(scene_), ctx.camfile.camera,
                            ctx.camfile.joint ? ctx.camfile.joint->axis_table : cv::Point2d(0, 0));
    ctx.encoder_offset = ctx.camfile.joint ? ctx.camfile.joint->encoder_offset : 0.0;
    pixels_ = std::move(ctx);
    return *pixels_;
  }

  const IdentifyCliOptions& o_;
  const Scene& scene_;
  std::optional<PixelContext> pixels_;
  std::size_t next_encoder_ = 0;
};

/// --unknowns: names of identify::parameter_names(), comma separated, none twice.
std::vector<std::string> parse_unknowns(const std::string& list) {
  const std::vector<std::string>& known = identify::parameter_names();
  std::string all;
  for (const std::string& k : known) all += (all.empty() ? "" : ", ") + k;
  std::vector<std::string> names;
  std::stringstream ss(list);
  std::string name;
  while (std::getline(ss, name, ',')) {
    name.erase(0, name.find_first_not_of(" \t"));
    name.erase(name.find_last_not_of(" \t") + 1);
    if (name.empty()) throw UsageError("--unknowns: an empty name in '" + list + "'");
    if (std::find(known.begin(), known.end(), name) == known.end())
      throw UsageError("--unknowns: unknown parameter '" + name + "' (known: " + all + ")");
    if (std::find(names.begin(), names.end(), name) != names.end())
      throw UsageError("--unknowns: '" + name + "' given twice");
    names.push_back(name);
  }
  if (names.empty()) throw UsageError("--unknowns: at least one parameter (known: " + all + ")");
  return names;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  if (!in && !in.eof()) throw std::runtime_error(path + ": cannot read");
  return os.str();
}

/// A number for JSON: null where it is NaN or infinite.
Json json_number(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }

Json report_json(const identify::IdentifyResult& r, const std::vector<LoadedRecording>& loaded) {
  Json j;
  Json params = Json::array();
  for (const identify::ParameterEstimate& p : r.parameters) {
    Json q;
    q["name"] = p.name;
    q["value"] = p.value;
    q["sigma"] = p.sigma ? Json(*p.sigma) : Json(nullptr);
    q["sigma_unscaled"] = p.sigma_unscaled ? Json(*p.sigma_unscaled) : Json(nullptr);
    q["determined"] = p.sigma.has_value();
    q["held"] = p.held;
    q["not_determined"] = p.sigma ? Json(nullptr) : Json(p.not_determined);
    q["initial"] = p.initial;
    q["step_to_minimum"] = p.step_to_minimum;
    q["bounds"] = {p.bounds.lower, p.bounds.upper};
    const auto key = identify::scene_key(p.name);
    q["scene_key"] = key ? Json(key->section + "." + key->key) : Json(nullptr);
    params.push_back(q);
  }
  j["parameters"] = params;
  Json corr = Json::array();
  for (Eigen::Index i = 0; i < r.correlation.rows(); ++i) {
    Json row = Json::array();
    for (Eigen::Index k = 0; k < r.correlation.cols(); ++k)
      row.push_back(json_number(r.correlation(i, k)));
    corr.push_back(row);
  }
  j["correlation"] = corr;
  j["chi2"] = r.chi2;
  j["degrees_of_freedom"] = r.degrees_of_freedom;
  j["chi2_per_dof"] =
      r.degrees_of_freedom > 0 ? json_number(r.chi2 / r.degrees_of_freedom) : Json(nullptr);
  j["chi2_limit"] = json_number(r.chi2_limit);
  j["sigma_scale"] = r.sigma_scale;
  j["iterations"] = r.iterations;
  j["converged"] = r.converged;
  j["step_in_sigma"] = r.step_in_sigma;
  j["chi2_decrease_expected"] = r.chi2_decrease_expected;
  j["termination_type"] = r.termination_type;
  j["termination"] = r.termination;
  j["simulations"] = r.simulations;
  j["wall_time"] = r.wall_time;
  j["simulation_time"] = r.simulation_time;
  j["warnings"] = r.warnings;
  Json recs = Json::array();
  for (const LoadedRecording& l : loaded) {
    Json q;
    q["path"] = l.path;
    q["format"] = to_string(l.format);
    q["rows"] = l.summary.rows;
    q["samples"] = static_cast<long>(l.recording.t.size());
    Json skipped = Json::object();
    for (const auto& [why, n] : l.summary.skipped) skipped[why] = n;
    q["skipped"] = skipped;
    recs.push_back(q);
  }
  j["recordings"] = recs;
  Json segs = Json::array();
  for (const identify::SegmentState& s : r.segments)
    segs.push_back({{"recording", s.recording},
                    {"t0", s.t0},
                    {"t1", s.t1},
                    {"s_h", s.s_h},
                    {"sdot_h", s.sdot_h},
                    {"sigma_s_h", s.sigma_s_h ? Json(*s.sigma_s_h) : Json(nullptr)},
                    {"sigma_sdot_h", s.sigma_sdot_h ? Json(*s.sigma_sdot_h) : Json(nullptr)}});
  j["segments"] = segs;
  return j;
}

Json validation_json(const identify::PredictionCheck& v) {
  return {{"recording", v.name},
          {"s_h0", v.s_h0},
          {"sdot_h0", v.sdot_h0},
          {"samples", v.t.size()},
          {"rms_error", v.rms_error},
          {"max_abs_error", v.max_abs_error},
          {"time_to_3_sigma", v.time_to_3_sigma ? Json(*v.time_to_3_sigma) : Json(nullptr)},
          {"stopped", v.stopped.empty() ? Json(nullptr) : Json(v.stopped)}};
}

std::string residuals_csv(const identify::IdentifyResult& r) {
  std::string s = "recording,t,measured,fitted,normalised_residual\n";
  for (std::size_t k = 0; k < r.fits.size(); ++k) {
    const identify::RecordingFit& f = r.fits[k];
    for (std::size_t i = 0; i < f.t.size(); ++i)
      s += std::to_string(k) + "," + format_number(f.t[i]) + "," + format_number(f.measured[i]) +
           "," + format_number(f.fitted[i]) + "," + format_number(f.normalised_residual[i]) + "\n";
  }
  return s;
}

std::string validation_csv(const identify::PredictionCheck& v) {
  std::string s = "t,measured,predicted,error,normalised_error\n";
  for (std::size_t i = 0; i < v.t.size(); ++i)
    s += format_number(v.t[i]) + "," + format_number(v.measured[i]) + "," +
         format_number(v.predicted[i]) + "," + format_number(v.error[i]) + "," +
         format_number(v.normalised_error[i]) + "\n";
  return s;
}

/// A value to the digit of its sigma's second significant one (0.0172 +- 0.0035); the JSON and
/// the scene file keep every digit.
std::string value_text(double value, double sigma) {
  if (!(sigma > 0) || value == 0 || !std::isfinite(value)) return format_number(value);
  const int digits = static_cast<int>(std::floor(std::log10(std::abs(value)))) -
                     static_cast<int>(std::floor(std::log10(sigma))) + 2;
  return sim::format_significant(value, std::clamp(digits, 1, 17));
}

/// The human-readable report on stdout.
std::string report_text(const identify::IdentifyResult& r, const std::vector<LoadedRecording>& in,
                        const std::optional<identify::PredictionCheck>& check,
                        const std::string& scene_path) {
  std::ostringstream os;
  long samples = 0;
  for (const LoadedRecording& l : in) samples += static_cast<long>(l.recording.t.size());
  os << "flatland identify: " << in.size() << " recording" << (in.size() == 1 ? "" : "s") << " ("
     << samples << " samples), scene " << scene_path << "\n";
  for (const LoadedRecording& l : in) {
    os << "  " << l.path << " (" << to_string(l.format) << "): " << l.recording.t.size()
       << " samples of " << l.summary.rows << " rows";
    for (const auto& [why, n] : l.summary.skipped) os << ", " << n << " " << why;
    os << "\n";
  }
  os << "  parameters (1 sigma"
     << (r.sigma_scale > 1 ? ", scaled by sqrt(chi^2/dof) = " +
                                 sim::format_significant(r.sigma_scale, 3) + "; unscaled in ()"
                           : std::string())
     << "):\n";
  std::size_t width = 0;
  for (const auto& p : r.parameters) width = std::max(width, p.name.size());
  for (const auto& p : r.parameters) {
    os << "    " << p.name << std::string(width - p.name.size() + 2, ' ');
    if (p.sigma) {
      os << value_text(p.value, *p.sigma) << " +- " << sim::format_significant(*p.sigma, 2);
      if (r.sigma_scale > 1 && p.sigma_unscaled)
        os << " (+- " << sim::format_significant(*p.sigma_unscaled, 2) << ")";
      os << "\n";
    } else
      os << "not determined: " << p.not_determined << "\n";
  }
  os << "  correlation:\n    " << std::string(width + 2, ' ');
  for (const auto& p : r.parameters)
    os << p.name.substr(0, 8) << std::string(10 - std::min<std::size_t>(8, p.name.size()), ' ');
  os << "\n";
  for (std::size_t i = 0; i < r.parameters.size(); ++i) {
    os << "    " << r.parameters[i].name
       << std::string(width - r.parameters[i].name.size() + 2, ' ');
    for (std::size_t k = 0; k < r.parameters.size(); ++k) {
      char cell[32];
      const double c = r.correlation(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(k));
      std::snprintf(cell, sizeof cell, "%-10s",
                    std::isfinite(c) ? sim::format_significant(c, 3).c_str() : "-");
      os << cell;
    }
    os << "\n";
  }
  os << "  chi^2              " << sim::format_significant(r.chi2, 6) << " for "
     << r.degrees_of_freedom << " degrees of freedom";
  if (r.degrees_of_freedom > 0)
    os << " (chi^2/dof = " << sim::format_significant(r.chi2 / r.degrees_of_freedom, 4)
       << "; 99 % of noise of the sigma given stays below "
       << sim::format_significant(r.chi2_limit, 4) << ")";
  os << "\n  fit                " << r.iterations << " iterations, " << r.simulations
     << " simulations, " << sim::format_significant(r.wall_time, 3) << " s; "
     << (r.converged ? "converged" : "NOT converged: " + r.termination_type + ": " + r.termination)
     << " (the minimum within " << sim::format_significant(r.step_in_sigma, 2) << " sigma)\n";
  for (const std::string& w : r.warnings) os << "  warning            " << w << "\n";
  if (check) {
    os << "  validation         " << check->name << ": rms error "
       << format_number(check->rms_error) << ", max " << format_number(check->max_abs_error)
       << ", beyond 3 sigma "
       << (check->time_to_3_sigma ? "after " + format_number(*check->time_to_3_sigma) + " s"
                                  : std::string("never"))
       << (check->stopped.empty() ? "" : "; stopped early: " + check->stopped) << "\n";
  }
  return os.str();
}

void write_outputs(OutputSet& outputs, const fs::path& dir, const IdentifyCliOptions& o,
                   const std::string& fitted, const identify::IdentifyResult& r,
                   const std::optional<identify::PredictionCheck>& check, Json report) {
  outputs.begin_directory(dir);
  outputs.stage(dir / "fitted.yaml", fitted);
  outputs.stage(dir / "residuals.csv", residuals_csv(r));
  if (check) outputs.stage(dir / "validation.csv", validation_csv(*check));
  if (!o.no_plot) {
    run_plot(outputs, dir,
             {"residuals.gp", "residuals.csv", "residuals.png",
              "set title 'identify: normalised residuals (fitted - measured) / sigma'\n"
              "set grid\nset xlabel 't (s)'\nset ylabel 'residual / sigma'\n"
              "set key off\n"
              "plot datafile skip 1 using 2:5:($1+1) with points pt 7 ps 0.5 lc variable, "
              "3 with lines lc 'black' dt 2, -3 with lines lc 'black' dt 2\n"});
    if (check)
      run_plot(
          outputs, dir,
          {"validation.gp", "validation.csv", "validation.png",
           "set title " + gnuplot_quote("prediction of " + check->name + " with the fitted world") +
               "\nset grid\nset xlabel 't (s)'\n"
               "set multiplot layout 2,1\nset key top left\n"
               "set ylabel 's_h'\n"
               "plot datafile skip 1 using 1:2 with points pt 7 ps 0.4 title 'measured', "
               "datafile skip 1 using 1:3 with lines lw 2 title 'predicted'\n"
               "set title ''\nset ylabel 'error / sigma'\nset key off\n"
               "plot datafile skip 1 using 1:5 with lines lw 2, 3 with lines lc 'black' dt 2, "
               "-3 with lines lc 'black' dt 2\n"
               "unset multiplot\n"});
  }
  Json files = Json::array();
  for (const std::string& p : outputs.paths()) files.push_back(p);
  files.push_back((dir / "report.json").string());
  report["outputs"] = files;
  outputs.stage(dir / "report.json", report.dump(2) + "\n");
  outputs.commit();
}

void run_identify(const IdentifyCliOptions& o) {
  // ---- every input checked before any fitting
  identify::IdentifyOptions options;
  options.unknowns = parse_unknowns(o.unknowns);
  require_positive("--segment", o.segment, "s");
  if (o.max_iterations < 1 || o.max_iterations > 10000)
    throw UsageError("--max-iterations: must be in [1, 10000], got " +
                     std::to_string(o.max_iterations));
  if (o.threads < 0 || o.threads > 1024)
    throw UsageError("--threads: must be in [0, 1024], got " + std::to_string(o.threads));
  options.threads = o.threads;
  options.segment_duration = o.segment;
  options.max_iterations = o.max_iterations;
  if (o.sigma_opt->count() && !(std::isfinite(o.sigma) && o.sigma > 0))
    throw UsageError("--sigma: must be > 0, got " + format_number(o.sigma));
  const fs::path dir = o.out;
  if (!dir.empty()) check_output_directory("--out", dir, o.force);
  const bool plots = !dir.empty() && !o.no_plot;
  if (plots) require_gnuplot();
  const Scene scene = load_scene(o.scene);
  if (scene.spatial)
    throw UsageError(o.scene + ": identify fits a planar scene (this one is space: 3d)");
  RecordingLoader loader(o, scene);
  std::vector<LoadedRecording> loaded;
  std::vector<identify::Recording> recordings;
  for (const std::string& path : o.recordings) {
    loaded.push_back(loader.load(path, "RECORDING"));
    recordings.push_back(loaded.back().recording);
  }
  std::optional<LoadedRecording> held_out;
  if (!o.validate.empty()) held_out = loader.load(o.validate, "--validate");
  loader.check_encoders_used();
  const std::string scene_text = read_text(o.scene);

  // ---- fit
  identify::IdentifyResult result;
  {
    ProgressBar bar("identify");
    options.progress = [&bar, &o](const identify::Progress& p) {
      bar.update(std::min(p.iteration, o.max_iterations), o.max_iterations);
    };
    try {
      result = identify::identify(scene.sim, recordings, options);
    } catch (const std::invalid_argument& e) {
      throw UsageError(e.what());
    }
  }
  std::optional<identify::PredictionCheck> check;
  if (held_out) {
    identify::ValidateOptions vo;
    vo.angle_offset = result.angle_offset;
    vo.time_offset = result.time_offset;
    check = identify::validate(result.world, held_out->recording, vo);
  }

  identify::FitProvenance provenance;
  provenance.scene_path = o.scene;
  provenance.command_line = o.command_line;
  for (const LoadedRecording& l : loaded)
    provenance.recordings.push_back(l.path + " (" + to_string(l.format) + ", " +
                                    std::to_string(l.recording.t.size()) + " samples)");
  const std::string fitted = identify::fitted_scene(scene_text, result, provenance);
  // The file must be a scene the other commands load: a fitted world the scene's rules refuse
  // (mu_kinetic above the scene's mu, say) is reported, not written.
  try {
    (void)parse_scene(fitted, (dir / "fitted.yaml").string());
  } catch (const SceneError& e) {
    throw std::runtime_error(std::string("the fitted world is not a valid scene: ") + e.what());
  }
  Json report = report_json(result, loaded);
  report["validation"] = check ? validation_json(*check) : Json(nullptr);
  report["scene"] = o.scene;

  OutputSet outputs(o.force);
  if (!dir.empty()) write_outputs(outputs, dir, o, fitted, result, check, report);
  if (o.json) {
    Json files = Json::array();
    for (const std::string& p : outputs.paths()) files.push_back(p);
    report["outputs"] = files;
    emit_json(report);
    return;
  }
  std::string text = report_text(result, loaded, check, o.scene);
  for (const std::string& p : outputs.paths()) text += "  wrote " + p + "\n";
  std::cout << text;
}

/// The command as given (from the parsed options, so the same run writes the same file).
std::string command_line(const IdentifyCliOptions& o) {
  std::string s = "flatland identify " + shell_quote(o.scene);
  for (const std::string& r : o.recordings) s += " " + shell_quote(r);
  s += " --unknowns " + shell_quote(o.unknowns) + " --segment " + format_number(o.segment);
  if (!o.validate.empty()) s += " --validate " + shell_quote(o.validate);
  if (!o.camera.empty()) s += " --camera " + shell_quote(o.camera);
  for (const std::string& e : o.encoders) s += " --encoder " + shell_quote(e);
  if (o.sigma_opt->count()) s += " --sigma " + format_number(o.sigma);
  if (o.format != "auto") s += " --format " + o.format;
  if (o.max_iterations != identify::IdentifyOptions{}.max_iterations)
    s += " --max-iterations " + std::to_string(o.max_iterations);
  return s;
}

}  // namespace

Command add_identify_command(CLI::App& app) {
  auto o = std::make_shared<IdentifyCliOptions>();
  CLI::App* cmd = add_command(app, "identify");
  cmd->add_option("scene", o->scene,
                  "The world to start from (a planar scene file): its hand, object, gravity and "
                  "contact; the fitted values replace its own")
      ->type_name("SCENE")
      ->required();
  cmd->add_option("recordings", o->recordings,
                  "Recordings of the disk on the hand: an experiment's output directory (or its "
                  "log.csv), a track.csv (with --encoder and --camera), a plain CSV with a header "
                  "t,theta,s_h[,sigma] (s, rad, -, -) or a pixel CSV t,u,v,theta,sigma_px (with "
                  "--camera); docs/IDENTIFY.md")
      ->type_name("RECORDING...")
      ->required();
  cmd->add_option("--unknowns", o->unknowns,
                  "Parameters to fit, comma separated: mu_static, mu_kinetic, restitution, "
                  "rolling_resistance, drag, drag_angular, tilt, angle_offset, time_offset. "
                  "Required")
      ->type_name("LIST")
      ->required();
  cmd->add_option("--segment", o->segment,
                  "Length of a shooting segment, s (> 0): each recording is cut into segments of "
                  "at most this, each with its own initial state. Default: 1")
      ->type_name("S");
  cmd->add_option("--out", o->out,
                  "Directory for fitted.yaml (the scene with the fitted values), residuals.csv "
                  "(recording, t, measured, fitted, normalised_residual) and residuals.png, "
                  "report.json and, with --validate, validation.csv and validation.png (+ the "
                  ".gp scripts). Default: no files")
      ->type_name("DIR");
  cmd->add_option("--validate", o->validate,
                  "A held-out recording (any format above) simulated from its first state with "
                  "the fitted world: its error over time")
      ->type_name("RECORDING");
  cmd->add_option("--camera", o->camera,
                  "Camera file (flatland calibrate's: table pose, joint) mapping pixel centres "
                  "to s_h; needed by track.csv and pixel recordings")
      ->type_name("FILE");
  cmd->add_option("--encoder", o->encoders,
                  "The joint's encoder log (rows t,theta; s, rad) of a track.csv recording; one "
                  "per track.csv, in the order they are given (the --validate one last)")
      ->type_name("FILE");
  o->sigma_opt = cmd->add_option("--sigma", o->sigma,
                                 "s_h's standard deviation for a plain CSV without a sigma column "
                                 "(> 0). Default: none (such a file is refused)");
  cmd->add_option("--format", o->format,
                  "Recording format: auto (a directory or log.csv: experiment; else from the "
                  "header), plain, experiment, track, pixels. Default: auto");
  cmd->add_option("--max-iterations", o->max_iterations,
                  "Ceres iterations at most per solve (1 to 10000); a fit that stops there is "
                  "reported as not converged. Default: " +
                      std::to_string(identify::IdentifyOptions{}.max_iterations));
  cmd->add_option("--threads", o->threads,
                  "Segments simulated at once (0 to 1024; 0: every core). Default: 0");
  cmd->add_flag("--no-plot", o->no_plot, "Do not draw residuals.png (and validation.png)");
  add_force_option(*cmd, o->force);
  cmd->add_flag("--json", o->json,
                "Print exactly one JSON object on stdout ({parameters, correlation, chi2, "
                "degrees_of_freedom, chi2_per_dof, chi2_limit, sigma_scale, iterations, converged, "
                "step_in_sigma, chi2_decrease_expected, termination_type, recordings, segments, "
                "validation, outputs, ...}); the same as report.json. Default: off");
  return {cmd, [o] {
            o->command_line = command_line(*o);
            run_identify(*o);
          }};
}

}  // namespace flatland::app
